//! A state machine's command port: requests of stimuli answered with what they did.
//!
//! Port `fsm.<machine>` ([`command_port`]) takes the stimuli of one command
//! (`Vec<Stimulus>`), checks them all against the program and queues them all, or refuses
//! them all at once with the reason. Once the machine has handled the last of them, the reply
//! ([`CommandReply`]) says what each did, or what went wrong.
//!
//! Three threads share the work, so the machine's own thread never waits on the network:
//!
//! | thread                  | does                                                        |
//! |-------------------------|-------------------------------------------------------------|
//! | `fsm-<m>-commands`      | receives requests, checks and queues them (or refuses them) |
//! | the machine (`fsm-<m>`) | handles each stimulus; after a command's last, hands its outcome on without blocking |
//! | `fsm-<m>-replies`       | sends each outcome to its user (which may wait for the reply stream to match) |

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, Weak};
use std::thread::JoinHandle;
use std::time::Duration;

use super::engine::{Outcome, Stimulus};
use super::task::{FsmError, Shared, enqueue};
use ndds_client::Participant;
use ndds_client::ports::{PortError, PortOwner, ReplyHandle};

use crate::sync::lock;

/// The reply of a machine's command port: what the stimuli did, or why not (refused, or an
/// action that faulted; then what did happen comes first).
pub use ndds_client::ports::CommandReply;

/// The port through which machine `machine` takes stimuli and answers with their outcome
/// (`ndds fsm send` uses it).
pub fn command_port(machine: &str) -> String {
    format!("fsm.{machine}")
}

/// How long the receiver waits for a request before checking for a stop.
const POLL: Duration = Duration::from_millis(100);

/// Outcomes waiting for the reply thread at most; past that the machine drops an outcome
/// (its user times out) rather than wait.
const REPLIES_WAITING: usize = 256;

/// An outcome on its way to the user that asked.
type Outgoing = (ReplyHandle<CommandReply>, CommandReply);

/// A command's stimuli: the outcome of each, reported once the last has been handled.
pub(super) struct Batch {
    lines: Mutex<Vec<String>>,
    faults: Mutex<Vec<String>>,
    remaining: AtomicUsize,
    reply: Mutex<Option<ReplyHandle<CommandReply>>>,
    replies: SyncSender<Outgoing>,
}

/// The command port's two threads.
pub(super) struct CommandServer {
    receiver: Option<JoinHandle<()>>,
    replier: Option<JoinHandle<()>>,
}

impl CommandServer {
    /// Owns `port` for the machine of `shared` and starts serving it.
    pub(super) fn start(
        shared: &Arc<Shared>,
        participant: &Participant,
        port: &str,
    ) -> Result<Self, PortError> {
        let owner: PortOwner<Vec<Stimulus>, CommandReply> =
            PortOwner::declare(participant, port, &shared.name)?;
        let (replies, outgoing) = std::sync::mpsc::sync_channel(REPLIES_WAITING);
        let spawn_error = |thread: String| {
            move |source| PortError::Spawn {
                port: Some(port.to_owned()),
                thread,
                source,
            }
        };
        let name = port.to_owned();
        let thread = format!("fsm-{}-replies", shared.name);
        let replier = std::thread::Builder::new()
            .name(thread.clone())
            .spawn(move || send_replies(&name, &outgoing))
            .map_err(spawn_error(thread))?;
        let weak = Arc::downgrade(shared);
        let thread = format!("fsm-{}-commands", shared.name);
        let receiver = std::thread::Builder::new()
            .name(thread.clone())
            .spawn(move || receive(&weak, &owner, &replies))
            .map_err(spawn_error(thread))?;
        Ok(Self {
            receiver: Some(receiver),
            replier: Some(replier),
        })
    }

    /// Stops taking commands: waits for the receiver, which ends within a poll once the
    /// machine's stop flag is set.
    pub(super) fn join_receiver(&mut self) {
        if let Some(thread) = self.receiver.take() {
            let _ = thread.join();
        }
    }

    /// Waits for the reply thread, which ends once every outcome on its way is sent: call it
    /// after [`join_receiver`](Self::join_receiver) and after the machine's queue was
    /// emptied (a queued command holds a way to the reply thread).
    pub(super) fn join_replier(&mut self) {
        if let Some(thread) = self.replier.take() {
            let _ = thread.join();
        }
    }
}

fn receive(
    weak: &Weak<Shared>,
    owner: &PortOwner<Vec<Stimulus>, CommandReply>,
    replies: &SyncSender<Outgoing>,
) {
    let mut failing = None;
    loop {
        match weak.upgrade() {
            Some(shared) if !shared.stop.load(Ordering::Acquire) => {}
            _ => return,
        }
        let Some((stimuli, handle)) = owner.serve_next(POLL, &mut failing) else {
            continue;
        };
        let Some(shared) = weak.upgrade() else { return };
        queue_command(&shared, stimuli, handle, replies);
    }
}

fn send_replies(port: &str, outgoing: &Receiver<Outgoing>) {
    while let Ok((handle, reply)) = outgoing.recv() {
        if let Err(err) = handle.reply(&reply) {
            tracing::debug!(port, error = %err, "command outcome not sent");
        }
    }
}

/// Queues the command's stimuli with a batch that replies once the last is handled, or
/// replies at once with the refusal. Waits while the reply thread is behind, so that requests
/// wait in the port's bounded buffer instead of piling up here.
fn queue_command(
    shared: &Shared,
    stimuli: Vec<Stimulus>,
    handle: ReplyHandle<CommandReply>,
    replies: &SyncSender<Outgoing>,
) {
    if shared.stop.load(Ordering::Acquire) {
        let refused = FsmError::Stopped(shared.name.clone()).to_string();
        let _ = replies.send((handle, Err(refused)));
        return;
    }
    if stimuli.is_empty() {
        let _ = replies.send((handle, Ok("no stimuli sent".to_owned())));
        return;
    }
    let batch = Arc::new(Batch {
        lines: Mutex::new(Vec::new()),
        faults: Mutex::new(Vec::new()),
        remaining: AtomicUsize::new(stimuli.len()),
        reply: Mutex::new(Some(handle)),
        replies: replies.clone(),
    });
    if let Err(err) = enqueue(shared, stimuli, Some(&batch)) {
        // Nothing of a refused batch was queued: its handle is still there to reply with.
        let handle = lock(&batch.reply).take();
        if let Some(handle) = handle {
            let _ = replies.send((handle, Err(err.to_string())));
        }
    }
}

/// Records what `stimulus` did in its batch; after the batch's last stimulus, hands the
/// outcome to the reply thread without waiting (a full reply queue drops it).
pub(super) fn settle(batch: &Batch, stimulus: &Stimulus, outcome: &Outcome, state: &str) {
    let sent = match &stimulus.value {
        Some(value) => format!("{}={value}", stimulus.name),
        None => stimulus.name.clone(),
    };
    lock(&batch.lines).push(describe(&sent, outcome, state));
    lock(&batch.faults).extend(outcome.faults.iter().map(|f| format!("{sent}: {f}")));
    if batch.remaining.fetch_sub(1, Ordering::AcqRel) != 1 {
        return;
    }
    let Some(handle) = lock(&batch.reply).take() else {
        return;
    };
    let lines = std::mem::take(&mut *lock(&batch.lines)).join("\n");
    let faults = std::mem::take(&mut *lock(&batch.faults));
    let reply = if faults.is_empty() {
        Ok(lines)
    } else {
        Err(format!("{lines}\nfaults:\n{}", faults.join("\n")))
    };
    if let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) =
        batch.replies.try_send((handle, reply))
    {
        tracing::debug!("command outcome dropped: the reply thread is behind or gone");
    }
}

/// One line: what a stimulus did.
fn describe(sent: &str, outcome: &Outcome, state: &str) -> String {
    if outcome.fired.is_empty() {
        let fate = if outcome.vanished {
            "no transition took it (transient: it is gone)"
        } else {
            "no transition fired"
        };
        return format!("{sent}: {fate}; state {state}");
    }
    let steps: Vec<String> = outcome
        .fired
        .iter()
        .map(|t| {
            let code = t.code.map(|c| format!(", code {c}")).unwrap_or_default();
            format!("{} -> {} ({}{code})", t.from, t.to, t.action)
        })
        .collect();
    format!("{sent}: {}", steps.join(", then "))
}

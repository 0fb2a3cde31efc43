//! [`StateMachine`]: a state program running on its own thread, fed by one event queue from
//! any thread and from the network, with actions that drive a [`Runtime`].
//!
//! On the network (when built with a participant) a machine whose main machine is `M`:
//! - takes stimuli ([`Stimulus`]) from the reliable topic `fsm/M/events`, in arrival order with
//!   the local ones;
//! - publishes its [`MachineState`] on `fsm/M/state` after every stimulus and once a second.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::command::{Batch, CommandServer, command_port, settle};
use super::def::Program;
use super::engine::{Actions, Machine, MachineState, Stimulus};
use super::verify::{FsmProblem, verify};
use super::vocabulary::{Refusal, Vocabulary};
use crate::Runtime;
use ndds_client::ports::OwnerLocation;
use ndds_client::{
    CallbackConsumer, ConsumerQos, Participant, Producer, ProducerQos, Reliability, TypeDescription,
};
use ndds_core::types::builtin;

/// Stimuli waiting in a machine's queue at most; more are refused.
pub const QUEUE_LIMIT: usize = 4096;
/// Longest stimulus name accepted (bytes).
pub const MAX_NAME_LEN: usize = 128;
/// Longest condition value accepted (bytes).
pub const MAX_VALUE_LEN: usize = 1024;

type ActionFn = Box<dyn FnMut(Option<&str>) -> Result<i32, String> + Send>;

/// Named actions with the codes each can return (what [`verify`] checks successors against).
#[derive(Default)]
pub struct ActionSet {
    actions: BTreeMap<String, (Vec<i32>, ActionFn)>,
}

impl ActionSet {
    /// No actions.
    pub fn new() -> Self {
        Self::default()
    }

    /// The runtime's actions: `switch CONFIGURATION`, `start HABITAT`, `stop HABITAT`, `reset
    /// HABITAT`, `rate HABITAT HZ` — each returns 0 when done, 1 when refused (unknown
    /// configuration or habitat, a rate out of range, a system that does not verify; the
    /// refusal is logged). A rate change reaches the habitat's modules (`timing_changed`) at
    /// its next sample boundary.
    pub fn runtime(runtime: &Runtime) -> Self {
        let mut set = Self::new();
        let rt = runtime.clone();
        set.add("switch", &[0, 1], move |arg| {
            let name = arg.ok_or("`switch` needs a configuration name")?;
            Ok(refused(rt.switch(name).map_err(|e| e.to_string())))
        });
        // Habitats are looked up, never created: a misspelt name is refused (code 1).
        let find = |rt: &Runtime, arg: Option<&str>, action: &str| {
            let name = arg.ok_or_else(|| format!("`{action}` needs a habitat name"))?;
            rt.find_habitat(name)
                .ok_or_else(|| format!("`{action} {name}`: no habitat `{name}`"))
        };
        let rt = runtime.clone();
        set.add("start", &[0, 1], move |arg| {
            let habitat = find(&rt, arg, "start");
            Ok(refused(
                habitat.and_then(|h| h.start().map_err(|e| e.to_string())),
            ))
        });
        let rt = runtime.clone();
        set.add("stop", &[0, 1], move |arg| {
            Ok(refused(find(&rt, arg, "stop").map(|h| h.stop())))
        });
        let rt = runtime.clone();
        set.add("reset", &[0, 1], move |arg| {
            Ok(refused(find(&rt, arg, "reset").map(|h| h.reset())))
        });
        let rt = runtime.clone();
        set.add("rate", &[0, 1], move |arg| {
            let (habitat, hz) = rate_argument(arg)?;
            Ok(refused(
                find(&rt, Some(habitat), "rate")
                    .and_then(|h| h.set_rate(hz).map_err(|e| e.to_string())),
            ))
        });
        set
    }

    /// Adds (or replaces) action `name`, which returns one of `codes`.
    pub fn add(
        &mut self,
        name: &str,
        codes: &[i32],
        action: impl FnMut(Option<&str>) -> Result<i32, String> + Send + 'static,
    ) -> &mut Self {
        self.actions
            .insert(name.to_owned(), (codes.to_vec(), Box::new(action)));
        self
    }

    /// Adds a sample module as action `name` (ControlShell's "CSM module executed when the
    /// transition occurs"): its `execute` runs, code 0 when it succeeds and 1 when it fails.
    pub fn add_module(&mut self, name: &str, mut module: impl crate::SampleModule) -> &mut Self {
        let mut sample = 0u64;
        self.add(name, &[0, 1], move |_| {
            let ctx = crate::SampleContext {
                period: Duration::ZERO,
                sample,
                time: Duration::ZERO,
            };
            sample += 1;
            Ok(match module.execute(&ctx) {
                Ok(()) => 0,
                Err(err) => {
                    tracing::warn!(error = %err, "state machine module action failed");
                    1
                }
            })
        })
    }

    /// The codes `name` can return, or `None` if there is no such action.
    pub fn codes(&self, name: &str) -> Option<Vec<i32>> {
        self.actions.get(name).map(|(codes, _)| codes.clone())
    }
}

/// `HABITAT HZ` of a `rate` action (an error, hence the machine's error state, when it is not
/// of that form: the file is wrong, not the moment).
pub(crate) fn rate_argument(arg: Option<&str>) -> Result<(&str, f64), String> {
    let usage = "`rate` takes a habitat and a rate in Hz: `rate servo 500`";
    let mut words = arg.ok_or(usage)?.split_whitespace();
    let (Some(habitat), Some(hz), None) = (words.next(), words.next(), words.next()) else {
        return Err(usage.to_owned());
    };
    let hz: f64 = hz
        .trim_end_matches("Hz")
        .parse()
        .map_err(|_| format!("`rate {habitat} {hz}`: `{hz}` is not a number; {usage}"))?;
    Ok((habitat, hz))
}

fn refused(result: Result<(), String>) -> i32 {
    match result {
        Ok(()) => 0,
        Err(err) => {
            tracing::warn!(error = %err, "state machine action refused");
            1
        }
    }
}

impl Actions for ActionSet {
    /// Runs the action; a panic is a failure (the machine goes to its error state) instead of
    /// the end of the machine's thread.
    fn run(&mut self, name: &str, argument: Option<&str>) -> Result<i32, String> {
        let Some((_, action)) = self.actions.get_mut(name) else {
            return Err(format!("no action `{name}`"));
        };
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| action(argument))).unwrap_or_else(
            |payload| {
                let text = payload
                    .downcast_ref::<&str>()
                    .map(|s| (*s).to_owned())
                    .or_else(|| payload.downcast_ref::<String>().cloned())
                    .unwrap_or_default();
                Err(format!("panicked: {text}"))
            },
        )
    }
}

/// Why a state machine could not start or take a stimulus.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FsmError {
    /// The program does not verify.
    #[error("state program `{machine}` does not verify:\n{}", list(.problems))]
    Verify {
        /// The main machine.
        machine: String,
        /// Every problem.
        problems: Vec<FsmProblem>,
    },
    /// The queue holds [`QUEUE_LIMIT`] stimuli already.
    #[error("state machine `{0}`: queue full ({QUEUE_LIMIT} stimuli waiting)")]
    QueueFull(String),
    /// The machine was stopped.
    #[error("state machine `{0}` is stopped")]
    Stopped(String),
    /// A stimulus the program does not take: undeclared, a value where none belongs, a
    /// condition without a value, or a near miss of a value its transitions test.
    #[error(transparent)]
    Refused(Box<Refusal>),
    /// A machine of this name already runs in the domain (it owns the machine's command port).
    #[error(
        "state machine `{machine}` already runs in this domain: {owner}; stop it, or run this \
         copy in another domain (--domain)"
    )]
    AlreadyRunning {
        /// The main machine.
        machine: String,
        /// Where the running one is.
        owner: OwnerLocation,
    },
    /// A name over [`MAX_NAME_LEN`] or a value over [`MAX_VALUE_LEN`] bytes.
    #[error(
        "state machine `{machine}`: stimulus too large (name {name_len} bytes, value {value_len} bytes; at most {MAX_NAME_LEN} and {MAX_VALUE_LEN})"
    )]
    Oversized {
        /// The main machine.
        machine: String,
        /// The name's length.
        name_len: usize,
        /// The value's length.
        value_len: usize,
    },
    /// A topic could not be declared.
    #[error("state machine `{machine}`: topic `{topic}`: {reason}")]
    Topic {
        /// The main machine.
        machine: String,
        /// The topic.
        topic: String,
        /// Why.
        reason: String,
    },
    /// The thread could not start.
    #[error("state machine `{0}`: cannot spawn its thread: {1}")]
    Spawn(String, std::io::Error),
}

impl From<Refusal> for FsmError {
    fn from(refusal: Refusal) -> Self {
        FsmError::Refused(Box::new(refusal))
    }
}

fn list(problems: &[FsmProblem]) -> String {
    problems
        .iter()
        .map(|p| format!("  - {p}"))
        .collect::<Vec<_>>()
        .join("\n")
}

pub(super) struct Shared {
    pub(super) name: String,
    vocabulary: Vocabulary,
    dropped: std::sync::atomic::AtomicU64,
    queue: Mutex<Queue>,
    ready: Condvar,
    state: Mutex<MachineState>,
    changed: Condvar,
    pub(super) stop: AtomicBool,
}

#[derive(Default)]
struct Queue {
    items: std::collections::VecDeque<Queued>,
}

/// A stimulus waiting for the machine, and who waits for its outcome.
struct Queued {
    stimulus: Stimulus,
    batch: Option<Arc<Batch>>,
}

/// A running state machine. Dropping the last handle stops it.
pub struct StateMachine {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    commands: Option<CommandServer>,
    _events: Option<CallbackConsumer>,
}

impl StateMachine {
    /// Verifies `program` against `actions` and runs it on its own thread (no network).
    pub fn start(program: Program, actions: ActionSet) -> Result<Self, FsmError> {
        Self::launch(program, actions, None)
    }

    /// The same, on the network: stimuli also come from `fsm/<main>/events` and the state is
    /// published on `fsm/<main>/state`.
    pub fn start_on(
        program: Program,
        actions: ActionSet,
        participant: &Participant,
    ) -> Result<Self, FsmError> {
        Self::launch(program, actions, Some(participant))
    }

    fn launch(
        program: Program,
        mut actions: ActionSet,
        participant: Option<&Participant>,
    ) -> Result<Self, FsmError> {
        let name = program.main.clone();
        let problems = verify(&program, &|action| actions.codes(action));
        if !problems.is_empty() {
            return Err(FsmError::Verify {
                machine: name,
                problems,
            });
        }
        let vocabulary = Vocabulary::of(&program);
        let machine = Machine::new(Arc::new(program));
        let shared = Arc::new(Shared {
            name: name.clone(),
            vocabulary,
            dropped: std::sync::atomic::AtomicU64::new(0),
            queue: Mutex::new(Queue::default()),
            ready: Condvar::new(),
            state: Mutex::new(machine.snapshot()),
            changed: Condvar::new(),
            stop: AtomicBool::new(false),
        });
        let topic_error = |topic: &str, reason: String| FsmError::Topic {
            machine: name.clone(),
            topic: topic.to_owned(),
            reason,
        };
        let (events, publisher, commands) = match participant {
            None => (None, None, None),
            Some(_)
                if name.is_empty() || name.contains('/') || name.chars().any(char::is_control) =>
            {
                return Err(topic_error(
                    &format!("fsm/{name}/events"),
                    "a machine on the network needs a name without `/` or control characters"
                        .into(),
                ));
            }
            Some(participant) => {
                let port = command_port(&name);
                if let Some(owner) = ndds_client::ports::owners_elsewhere(participant, &port)
                    .map_err(|e| topic_error(&port, e.to_string()))?
                    .into_iter()
                    .next()
                {
                    return Err(FsmError::AlreadyRunning {
                        machine: name,
                        owner,
                    });
                }
                let commands = CommandServer::start(&shared, participant, &port)
                    .map_err(|e| topic_error(&port, e.to_string()))?;
                let topic = format!("fsm/{name}/events");
                let qos = ConsumerQos {
                    reliability: Reliability::Reliable { depth: 256 },
                    depth: 256,
                    ..ConsumerQos::default()
                };
                let weak = Arc::downgrade(&shared);
                let events = participant
                    .consumer_with_type::<Stimulus>(
                        &topic,
                        TypeDescription::named::<Stimulus>(builtin::FSM_STIMULUS),
                        qos,
                    )
                    .map_err(|e| topic_error(&topic, e.to_string()))?
                    .on_sample(move |sample| {
                        if let Some(shared) = weak.upgrade()
                            && let Err(err) = enqueue(&shared, vec![sample.value], None)
                        {
                            // Logged at 1, 2, 4, 8, ... drops: a flooding peer cannot flood the log.
                            let dropped = shared.dropped.load(Ordering::Relaxed);
                            if dropped.is_power_of_two() {
                                tracing::warn!(error = %err, dropped, "stimulus from the network dropped");
                            }
                        }
                    })
                    .map_err(|e| topic_error(&topic, e.to_string()))?;
                let topic = format!("fsm/{name}/state");
                let producer = participant
                    .producer_with_type::<MachineState>(
                        &topic,
                        TypeDescription::named::<MachineState>(builtin::FSM_STATE),
                        ProducerQos::default(),
                    )
                    .map_err(|e| topic_error(&topic, e.to_string()))?;
                (Some(events), Some(producer), Some(commands))
            }
        };
        let worker = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name(format!("fsm-{name}"))
            .spawn(move || run(&worker, machine, &mut actions, publisher.as_ref()))
            .map_err(|e| FsmError::Spawn(name.clone(), e))?;
        Ok(Self {
            shared,
            thread: Some(thread),
            commands,
            _events: events,
        })
    }

    /// Queues a stimulus (from any thread); it is processed after those queued before it.
    /// A stimulus the program does not take is refused ([`FsmError::Refused`]) and never
    /// reaches the machine.
    pub fn send(&self, stimulus: Stimulus) -> Result<(), FsmError> {
        if self.shared.stop.load(Ordering::Acquire) {
            return Err(FsmError::Stopped(self.shared.name.clone()));
        }
        enqueue(&self.shared, vec![stimulus], None)
    }

    /// The stimuli the machine accepts (also published in its state).
    pub fn accepted(&self) -> Vec<super::vocabulary::Accepted> {
        self.shared.vocabulary.accepted()
    }

    /// The machine now (after the last processed stimulus).
    pub fn snapshot(&self) -> MachineState {
        let mut state = self
            .shared
            .state
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        state.dropped = self.shared.dropped.load(Ordering::Relaxed);
        state.accepts = self.shared.vocabulary.accepted();
        state
    }

    /// Waits until the innermost running machine is in `state`; false after `timeout`.
    pub fn wait_for_state(&self, state: &str, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        let mut current = self.shared.state.lock().unwrap_or_else(|p| p.into_inner());
        while current.state != state {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            current = self
                .shared
                .changed
                .wait_timeout(current, left)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
        true
    }
}

impl StateMachine {
    /// Stops the machine's thread after the stimulus it is handling (queued ones are dropped);
    /// later [`send`](Self::send)s fail with [`FsmError::Stopped`]. Dropping it does the same
    /// and waits for the thread.
    pub fn stop(&self) {
        self.shared.stop.store(true, Ordering::Release);
        let _queue = self.shared.queue.lock().unwrap_or_else(|p| p.into_inner());
        self.shared.ready.notify_all();
    }
}

impl Drop for StateMachine {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        {
            // Under the queue's lock, so the thread cannot miss the wake-up between its check
            // of `stop` and its wait.
            let _queue = self.shared.queue.lock().unwrap_or_else(|p| p.into_inner());
            self.shared.ready.notify_all();
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        let mut commands = self.commands.take();
        if let Some(commands) = &mut commands {
            commands.join_receiver();
        }
        // Queued commands will never be handled: dropping them lets the reply thread end.
        self.shared
            .queue
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .items
            .clear();
        if let Some(commands) = &mut commands {
            commands.join_replier();
        }
    }
}

/// Queues `stimuli` together, or none of them: each is checked against the program first.
pub(super) fn enqueue(
    shared: &Shared,
    stimuli: Vec<Stimulus>,
    batch: Option<&Arc<Batch>>,
) -> Result<(), FsmError> {
    let refuse = |error: FsmError| {
        shared.dropped.fetch_add(1, Ordering::Relaxed);
        Err(error)
    };
    for stimulus in &stimuli {
        let value_len = stimulus.value.as_ref().map_or(0, String::len);
        if stimulus.name.len() > MAX_NAME_LEN || value_len > MAX_VALUE_LEN {
            return refuse(FsmError::Oversized {
                machine: shared.name.clone(),
                name_len: stimulus.name.len(),
                value_len,
            });
        }
        if let Err(refusal) = shared.vocabulary.check(stimulus) {
            return refuse(FsmError::Refused(refusal));
        }
    }
    let mut queue = shared.queue.lock().unwrap_or_else(|p| p.into_inner());
    if queue.items.len() + stimuli.len() > QUEUE_LIMIT {
        drop(queue);
        return refuse(FsmError::QueueFull(shared.name.clone()));
    }
    for stimulus in stimuli {
        queue.items.push_back(Queued {
            stimulus,
            batch: batch.cloned(),
        });
    }
    shared.ready.notify_one();
    Ok(())
}

const REPUBLISH: Duration = Duration::from_secs(1);

fn run(
    shared: &Shared,
    mut machine: Machine,
    actions: &mut ActionSet,
    publisher: Option<&Producer<MachineState>>,
) {
    let publish = |state: &MachineState| {
        let mut state = state.clone();
        state.dropped = shared.dropped.load(Ordering::Relaxed);
        state.accepts = shared.vocabulary.accepted();
        if let Some(p) = publisher
            && let Err(err) = p.write(&state)
        {
            tracing::warn!(machine = %shared.name, error = %err, "state not published");
        }
    };
    publish(&machine.snapshot());
    let mut last_publish = Instant::now();
    while !shared.stop.load(Ordering::Acquire) {
        let next = {
            let mut queue = shared.queue.lock().unwrap_or_else(|p| p.into_inner());
            if queue.items.is_empty() && !shared.stop.load(Ordering::Acquire) {
                queue = shared
                    .ready
                    .wait_timeout(queue, REPUBLISH)
                    .unwrap_or_else(|p| p.into_inner())
                    .0;
            }
            queue.items.pop_front()
        };
        match next {
            Some(Queued { stimulus, batch }) => {
                let outcome = machine.handle(&stimulus, actions);
                for fired in &outcome.fired {
                    tracing::info!(machine = %shared.name, from = %fired.from, to = %fired.to,
                        condition = %fired.condition, action = %fired.action, "transition");
                }
                let state = machine.snapshot();
                if let Some(batch) = &batch {
                    settle(batch, &stimulus, &outcome, &state.state);
                }
                *shared.state.lock().unwrap_or_else(|p| p.into_inner()) = state.clone();
                shared.changed.notify_all();
                publish(&state);
                last_publish = Instant::now();
            }
            None if last_publish.elapsed() >= REPUBLISH => {
                publish(&machine.snapshot());
                last_publish = Instant::now();
            }
            None => {}
        }
    }
}

//! `ndds fsm`: drive and watch the state machines of a live system (`ndds_runtime::fsm`).
//!
//! - `ndds fsm send MACHINE STIMULUS[=VALUE]...` sends stimuli through the machine's command
//!   port (`fsm.MACHINE`) and prints what they did, or fails with the machine's reason for
//!   refusing them (none is queued then);
//! - `ndds fsm show MACHINE` prints its state from `fsm/MACHINE/state`.

use std::time::Duration;

use anyhow::Context as _;
use ndds_client::ports::{PortError, PortUser};
use ndds_client::{ConsumerQos, Participant, TypeDescription};
use ndds_runtime::fsm::{CommandReply, MachineState, Stimulus, command_port};

use crate::connect::{DaemonArgs, connect};
use crate::{outln, seconds};
use ndds_core::suggest;
use ndds_core::types::builtin;

/// Options of `ndds fsm`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    mode: Mode,
}

#[derive(Debug, clap::Subcommand)]
enum Mode {
    /// Send stimuli to a machine, in order: `Acquire`, `Object=Visible`; prints what they did,
    /// or fails with the machine's reason when it refuses them (then none is taken).
    Send {
        /// The machine (its main machine's name).
        machine: String,
        /// Stimuli: `NAME` (transient or latched) or `NAME=VALUE` (condition).
        #[arg(required = true)]
        stimuli: Vec<String>,
        /// Seconds to wait for the machine to answer with the outcome.
        #[arg(long, value_parser = seconds::parse, default_value = "5")]
        wait: Duration,
    },
    /// Print a machine's state: current state, call stack, last transition, stimulus memory.
    Show {
        /// The machine.
        machine: String,
        /// Print the state as JSON.
        #[arg(long)]
        json: bool,
        /// Seconds to wait for the state (machines republish every second).
        #[arg(long, value_parser = seconds::parse, default_value = "3")]
        wait: Duration,
    },
}

/// Runs `ndds fsm`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    match &args.mode {
        Mode::Send {
            machine,
            stimuli,
            wait,
        } => send(daemon, machine, stimuli, *wait),
        Mode::Show {
            machine,
            json,
            wait,
        } => show(daemon, machine, *json, *wait),
    }
}

fn send(
    daemon: &DaemonArgs,
    machine: &str,
    stimuli: &[String],
    wait: Duration,
) -> anyhow::Result<()> {
    let parsed: Vec<Stimulus> = stimuli.iter().map(|s| Stimulus::parse(s)).collect();
    if let Some(bad) = parsed.iter().find(|s| s.name.is_empty()) {
        anyhow::bail!("empty stimulus name in {bad:?}");
    }
    let participant = connect(daemon)?;
    let reply = command(&participant, machine, &parsed, wait)?;
    match reply {
        Ok(report) => {
            for line in report.lines() {
                outln!("{machine}: {line}")?;
            }
            Ok(())
        }
        Err(reason) => anyhow::bail!("{reason}"),
    }
}

/// Sends `stimuli` to `machine` through its command port and returns its answer: what they
/// did once the machine handled them, or why it refused them all (none is queued then).
pub fn command(
    participant: &Participant,
    machine: &str,
    stimuli: &[Stimulus],
    wait: Duration,
) -> anyhow::Result<CommandReply> {
    let port = command_port(machine);
    let user = PortUser::<Vec<Stimulus>, CommandReply>::declare(participant, &port, "ndds")?;
    match user.send(&stimuli.to_vec(), wait) {
        Ok(reply) => Ok(reply),
        Err(PortError::Timeout { owner: None, .. }) => {
            let known = machines(participant);
            let hint = suggest::did_you_mean(&suggest::suggest(machine, &known))
                .map(|s| format!("; {s}"))
                .unwrap_or_default();
            anyhow::bail!(
                "no state machine `{machine}` answered within {wait:?}{hint} ({})",
                running(&known)
            )
        }
        Err(PortError::Timeout { .. }) => anyhow::bail!(
            "state machine `{machine}` did not answer within {wait:?}: it may still be running an \
             action, or the request did not reach it (`ndds fsm show {machine}` shows its state)"
        ),
        Err(err) => Err(err.into()),
    }
}

/// `running: a, b`, or that none runs.
fn running(known: &[String]) -> String {
    if known.is_empty() {
        "no state machine runs in this domain".to_owned()
    } else {
        format!("running: {}", known.join(", "))
    }
}

/// The state machines of the domain: their command ports, from the daemon's view.
fn machines(participant: &Participant) -> Vec<String> {
    crate::systems::owned_ports(participant, "fsm.").unwrap_or_default()
}

fn show(daemon: &DaemonArgs, machine: &str, json: bool, wait: Duration) -> anyhow::Result<()> {
    let participant = connect(daemon)?;
    let topic = format!("fsm/{machine}/state");
    let consumer = participant.consumer_with_type::<MachineState>(
        &topic,
        TypeDescription::named::<MachineState>(builtin::FSM_STATE),
        ConsumerQos::default(),
    )?;
    let sample = match consumer.recv_timeout(wait) {
        Ok(sample) => sample,
        Err(err) if err.is_timeout() => {
            let known = machines(&participant);
            let hint = suggest::did_you_mean(&suggest::suggest(machine, &known))
                .map(|s| format!("; {s}"))
                .unwrap_or_default();
            anyhow::bail!(
                "no state from machine `{machine}` on {topic:?} within {wait:?}{hint} ({})",
                running(&known)
            );
        }
        Err(err) => return Err(err).context(format!("reading {topic:?}")),
    };
    let state = sample.value;
    if json {
        outln!("{}", serde_json::to_string(&state)?)?;
        return Ok(());
    }
    outln!("machine     {}", state.machine)?;
    outln!("state       {}", state.state)?;
    if state.stack.len() > 1 {
        outln!("call stack  {}", state.stack.join(" > "))?;
    }
    if let Some(t) = &state.last_transition {
        let code = t.code.map(|c| format!(" -> code {c}")).unwrap_or_default();
        outln!(
            "last        {}:{} --[{}]--> {} (action {}{code})",
            t.machine,
            t.from,
            t.condition,
            t.to,
            t.action
        )?;
    }
    let conditions: Vec<String> = state
        .conditions
        .iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect();
    outln!("conditions  {}", conditions.join(" "))?;
    outln!("latched     {}", state.latched.join(" "))?;
    let accepts: Vec<String> = state.accepts.iter().map(ToString::to_string).collect();
    outln!("accepts     {}", accepts.join(" "))?;
    outln!(
        "counts      {} transitions, {} faults, {} stimuli refused",
        state.transitions,
        state.faults,
        state.dropped
    )?;
    if !state.last_fault.is_empty() {
        outln!("last fault  {}", state.last_fault)?;
    }
    Ok(())
}

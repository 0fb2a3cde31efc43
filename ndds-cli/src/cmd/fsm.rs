//! `ndds fsm`: drive and watch the state machines of a live system (`ndds_client::fsm`).
//!
//! - `ndds fsm send MACHINE STIMULUS[=VALUE]...` queues stimuli on `fsm/MACHINE/events`
//!   (reliably, waiting until the machine acknowledged them);
//! - `ndds fsm show MACHINE` prints its state from `fsm/MACHINE/state`.

use std::time::Duration;

use anyhow::Context as _;
use ndds_client::fsm::{MachineState, Stimulus};
use ndds_client::{ConsumerQos, ProducerQos, Reliability};

use crate::connect::{DaemonArgs, connect};
use crate::seconds;

/// Options of `ndds fsm`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    mode: Mode,
}

#[derive(Debug, clap::Subcommand)]
enum Mode {
    /// Send stimuli to a machine, in order: `Acquire`, `Object=Visible`.
    Send {
        /// The machine (its main machine's name).
        machine: String,
        /// Stimuli: `NAME` (transient or latched) or `NAME=VALUE` (condition).
        #[arg(required = true)]
        stimuli: Vec<String>,
        /// Seconds to wait for the machine to appear and to acknowledge.
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
    let topic = format!("fsm/{machine}/events");
    let qos = ProducerQos {
        reliability: Reliability::Reliable { depth: 256 },
        ..ProducerQos::default()
    };
    let producer = participant.producer::<Stimulus>(&topic, qos)?;
    anyhow::ensure!(
        producer.wait_for_consumers(1, wait),
        "no state machine `{machine}` found (nothing consumes {topic:?}); `ndds topics` lists the fsm/*/events topics"
    );
    for stimulus in &parsed {
        producer.write(stimulus)?;
    }
    anyhow::ensure!(
        producer.wait_for_acknowledgments(wait),
        "state machine `{machine}` did not acknowledge within {wait:?}"
    );
    eprintln!("ndds: sent {} stimulus(es) to {machine}", parsed.len());
    Ok(())
}

fn show(daemon: &DaemonArgs, machine: &str, json: bool, wait: Duration) -> anyhow::Result<()> {
    let participant = connect(daemon)?;
    let topic = format!("fsm/{machine}/state");
    let consumer = participant.consumer::<MachineState>(&topic, ConsumerQos::default())?;
    let sample = consumer.recv_timeout(wait).with_context(|| {
        format!("no state from machine `{machine}` on {topic:?} within {wait:?}")
    })?;
    let state = sample.value;
    if json {
        println!("{}", serde_json::to_string(&state)?);
        return Ok(());
    }
    println!("machine     {}", state.machine);
    println!("state       {}", state.state);
    if state.stack.len() > 1 {
        println!("call stack  {}", state.stack.join(" > "));
    }
    if let Some(t) = &state.last_transition {
        let code = t.code.map(|c| format!(" -> code {c}")).unwrap_or_default();
        println!(
            "last        {}:{} --[{}]--> {} (action {}{code})",
            t.machine, t.from, t.condition, t.to, t.action
        );
    }
    let conditions: Vec<String> = state
        .conditions
        .iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect();
    println!("conditions  {}", conditions.join(" "));
    println!("latched     {}", state.latched.join(" "));
    println!(
        "counts      {} transitions, {} faults",
        state.transitions, state.faults
    );
    if !state.last_fault.is_empty() {
        println!("last fault  {}", state.last_fault);
    }
    Ok(())
}

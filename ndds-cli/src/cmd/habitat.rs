//! `ndds habitat NAME rate HZ | reset | start | stop`: change a habitat of a running system
//! through its command port, and say what the system did (or why it refused).

use std::time::Duration;

use ndds_runtime::{HabitatAction, RuntimeCommand};

use crate::connect::{DaemonArgs, connect};
use crate::{outln, seconds, systems};

/// Options of `ndds habitat`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The habitat.
    habitat: String,
    #[command(subcommand)]
    action: Action,
    /// The system the habitat belongs to (default: the one running, or the one of those
    /// running that has the habitat).
    #[arg(long, global = true)]
    system: Option<String>,
    /// Seconds to wait for the system's answer.
    #[arg(long, global = true, value_parser = seconds::parse, default_value = "5")]
    wait: Duration,
}

#[derive(Debug, clap::Subcommand)]
enum Action {
    /// Sample at HZ from the next sample boundary (every module's `timing_changed` runs).
    #[command(allow_negative_numbers = true)]
    Rate {
        /// Samples per second.
        hz: f64,
    },
    /// Call every module's `reset` at the next sample boundary.
    Reset,
    /// Begin sampling (the system is verified first).
    Start,
    /// Stop sampling (disable and shutdown routines run).
    Stop,
}

impl Action {
    fn command(&self) -> HabitatAction {
        match self {
            Action::Rate { hz } => HabitatAction::Rate(*hz),
            Action::Reset => HabitatAction::Reset,
            Action::Start => HabitatAction::Start,
            Action::Stop => HabitatAction::Stop,
        }
    }
}

/// Runs `ndds habitat`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let participant = connect(daemon)?;
    let link = systems::choose(
        &participant,
        args.system.as_deref(),
        Some(&args.habitat),
        args.wait,
    )?;
    let command = RuntimeCommand::habitat(&args.habitat, args.action.command());
    match link.ask(&command)? {
        Ok(done) => {
            outln!("{done}")?;
            Ok(())
        }
        Err(refused) => anyhow::bail!("{refused}"),
    }
}

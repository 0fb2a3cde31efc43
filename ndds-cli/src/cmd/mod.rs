//! The subcommands, one per file, collected in one clap enum.

mod bag;
mod echo;
mod fsm;
mod habitat;
mod hz;
mod key;
mod modules;
mod new;
mod nodes;
mod perf;
mod play;
mod ports;
mod publish;
mod record;
pub(crate) mod run;
mod security;
mod shell;
mod studio;
mod topics;

use clap::{Parser, Subcommand};

use crate::connect::DaemonArgs;

/// Inspect and drive a live ndds domain.
#[derive(Debug, Parser)]
#[command(name = "ndds", version, about)]
pub struct Cli {
    #[command(flatten)]
    daemon: DaemonArgs,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// List topics with their types, producers and consumers.
    Topics(topics::Args),
    /// List daemons (hosts) and client processes.
    Nodes(nodes::Args),
    /// Print the samples of a topic, decoded from the type carried in discovery.
    Echo(echo::Args),
    /// Publish JSON values on a topic.
    Pub(publish::Args),
    /// Measure the sample rate of a topic.
    Hz(hz::Args),
    /// Measure latency (ping/pong) and throughput (pub/sub), or the raw-UDP baseline.
    Perf(perf::Args),
    /// Send stimuli to a state machine, or show its state.
    Fsm(fsm::Args),
    /// Change a habitat of a running system: its rate, reset, start or stop.
    Habitat(habitat::Args),
    /// List ports with their owner, users, restrictions and queue.
    Ports(ports::Args),
    /// Show the module tree: each running module with its children, tasks and ports.
    Modules(modules::Args),
    /// The operator's console on a running system: look at it, set, switch, send, watch.
    Shell(shell::Args),
    /// Make a crate with a component type of your own, or a system description to start from.
    New(new::Args),
    /// Load a system description file, verify it and run it, with a live status.
    Run(run::Args),
    /// Record topics into an MCAP file (Foxglove, rosbag2 and Python's mcap read it).
    Record(record::Args),
    /// Publish recorded samples again, with their recorded types, QoS and timing.
    Play(play::Args),
    /// What a recording holds, and parts of recordings into new files.
    Bag(bag::Args),
    /// Domain key files: a new one, and the steps of a key rotation.
    Key(key::Args),
    /// Identities and the permissions document: who may publish, subscribe, own or use what.
    Security(security::Args),
    /// The network, running systems, state machines and live plots in a browser.
    Studio(studio::Args),
}

impl Cli {
    /// Whether the command says itself why an endpoint of its own is not matched (`ndds pub`
    /// refuses with the consumers' type or reliability), so the library's warning would only
    /// repeat it.
    pub fn explains_mismatches(&self) -> bool {
        matches!(self.command, Command::Pub(_))
    }
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Topics(args) => topics::run(&cli.daemon, &args),
        Command::Nodes(args) => nodes::run(&cli.daemon, &args),
        Command::Echo(args) => echo::run(&cli.daemon, &args),
        Command::Pub(args) => publish::run(&cli.daemon, &args),
        Command::Hz(args) => hz::run(&cli.daemon, &args),
        Command::Perf(args) => perf::run(&cli.daemon, &args),
        Command::Fsm(args) => fsm::run(&cli.daemon, &args),
        Command::Habitat(args) => habitat::run(&cli.daemon, &args),
        Command::Ports(args) => ports::run(&cli.daemon, &args),
        Command::Modules(args) => modules::run(&cli.daemon, &args),
        Command::Shell(args) => shell::run(&cli.daemon, &args),
        Command::New(args) => new::run(&args),
        Command::Record(args) => record::run(&cli.daemon, &args),
        Command::Play(args) => play::run(&cli.daemon, &args),
        Command::Bag(args) => bag::run(&args),
        Command::Key(args) => key::run(&args),
        Command::Security(args) => security::run(&args),
        Command::Run(args) => run::run(&cli.daemon, &args, ndds_components::library()),
        Command::Studio(args) => studio::run(&cli.daemon, &args),
    }
}

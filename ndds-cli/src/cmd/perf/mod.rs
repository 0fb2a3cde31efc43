//! `ndds perf`: latency (`ping` / `pong`) and throughput (`pub` / `sub`) of ndds, measured the
//! way Cyclone DDS's `ddsperf` measures it, and the same measurements over plain UDP sockets
//! (`--raw-udp`) as the physical baseline.
//!
//! Every loop ends by a count or a duration. Figures are printed as text, or as one JSON object
//! (`--json`) for scripts such as `scripts/bench.sh`.
//!
//! ## Layout
//! - [`sample`]: the sample type, sizes, clocks and sequence-gap counting shared by all modes;
//! - [`latency`] and [`throughput`]: what is measured and how it is reported;
//! - [`ping`], [`pong`], [`publish`], [`subscribe`]: the ndds side of each mode;
//! - [`udp`]: the same four modes over plain UDP sockets;
//! - [`runtime`]: the ControlShell runtime's overhead and jitter.

mod latency;
mod ping;
mod pong;
mod port;
mod publish;
mod runtime;
mod sample;
mod subscribe;
mod throughput;
mod udp;

use std::time::Duration;

use clap::Subcommand;
use ndds_client::{
    ConnectError, ConsumerQos, EmbeddedPolicy, Participant, ProducerQos, Reliability,
};

use crate::connect::DaemonArgs;

/// Options of `ndds perf`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    mode: Mode,
}

#[derive(Debug, Subcommand)]
enum Mode {
    /// Send pings and measure the round trip of each (start `ndds perf pong` first).
    Ping(ping::Args),
    /// Answer every ping with the same sample.
    Pong(pong::Args),
    /// Publish samples of a given size as fast as allowed, for a duration.
    Pub(publish::Args),
    /// Receive samples and report their rate, bandwidth and loss over a steady window.
    Sub(subscribe::Args),
    /// Round trips through a port (send/receive/reply, or query with --query); start one
    /// with --serve first.
    Port(port::Args),
    /// The ControlShell runtime's per-sample overhead and a timer habitat's jitter (no
    /// network, no daemon).
    Runtime(runtime::Args),
}

/// Runs `ndds perf`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    match &args.mode {
        Mode::Ping(args) => ping::run(daemon, args),
        Mode::Pong(args) => pong::run(daemon, args),
        Mode::Pub(args) => publish::run(daemon, args),
        Mode::Sub(args) => subscribe::run(daemon, args),
        Mode::Runtime(args) => runtime::run(args),
        Mode::Port(args) => port::run(daemon, args),
    }
}

/// Options every ndds mode shares.
#[derive(Clone, Debug, clap::Args)]
struct Stream {
    /// Topic prefix: ping/pong use `PREFIX/ping` and `PREFIX/pong`, pub/sub `PREFIX/data`.
    #[arg(long, default_value = "ndds/perf")]
    topic: String,
    /// Reliable stream (producer offers, consumer requests) instead of best effort.
    #[arg(long, conflicts_with = "raw_udp")]
    reliable: bool,
    /// History depth of a reliable producer (its flow-control window), and the reordering
    /// buffer of a reliable consumer.
    #[arg(long, default_value_t = 1024, requires = "reliable")]
    depth: u32,
}

impl Stream {
    fn reliability(&self) -> Reliability {
        if self.reliable {
            Reliability::Reliable { depth: self.depth }
        } else {
            Reliability::BestEffort
        }
    }

    fn mode_name(&self) -> &'static str {
        if self.reliable {
            "reliable"
        } else {
            "best-effort"
        }
    }

    fn topic(&self, leaf: &str) -> String {
        format!("{}/{leaf}", self.topic)
    }

    fn producer_qos(&self) -> ProducerQos {
        ProducerQos {
            reliability: self.reliability(),
            // A full window makes a reliable write wait; a benchmark should see that, but
            // never hang on it.
            write_timeout: Duration::from_secs(1),
            ..ProducerQos::default()
        }
    }

    fn consumer_qos(&self) -> ConsumerQos {
        ConsumerQos {
            reliability: self.reliability(),
            depth: usize::try_from(self.depth).unwrap_or(usize::MAX).max(64),
            ..ConsumerQos::default()
        }
    }
}

/// Connects to the local daemon as a control program named `ndds-perf`; never starts an
/// embedded daemon (run `ndds-daemon`, or point both sides at one daemon's socket).
fn connect(args: &DaemonArgs) -> anyhow::Result<Participant> {
    let mut builder = Participant::builder()
        .embedded(EmbeddedPolicy::Never)
        .name("ndds-perf");
    if let Some(domain) = args.domain {
        builder = builder.domain(domain);
    }
    if let Some(socket) = &args.socket {
        builder = builder.socket(socket);
    }
    builder.connect().map_err(|err| match err {
        ConnectError::NoDaemon { path, reason } => anyhow::anyhow!(
            "no ndds daemon is running at {} ({reason}); start `ndds-daemon`, or name the \
             daemon's socket with --socket or NDDS_SOCKET",
            path.display()
        ),
        other => other.into(),
    })
}

//! `ndds-test-node`: a small control program for the interop tests. It connects to the
//! daemon named by `NDDS_SOCKET`, and produces or consumes samples, reporting what happens as
//! JSON lines on stdout (`{"event": ...}`):
//!
//! - `ready` once its endpoints are declared (with its `pid`);
//! - producers: `matched` (with `--wait-consumers`), `incompatible` for each consumer of its
//!   topic that declared another type, `done`;
//! - consumers: `sample` (the value's fields, `status` `fresh` or `took_over`, the writer's
//!   guid and `strength`, reception time in µs since the Unix epoch), with `--events`
//!   `notification` (`kind`: `NoNewData`, `NeverReceived`, `ProducerLost`, `Incompatible`,
//!   `OldData`, `DeserializationError`, with the variant's fields), and `done` with the
//!   participant's data-socket counters.
//!
//! `--reliable DEPTH` makes either side reliable; `--type blob --payload BYTES` writes samples
//! of any size whose bytes a consumer checks (`len`, `intact`).
//!
//! `port own|send|waitfor` play the roles of ports (see `ports.rs`).
//!
//! Layout: `produce.rs` and `consume.rs` (one role each), `ports.rs` (port roles),
//! `samples.rs` (the sample types), `report.rs` (the JSON lines).

mod consume;
mod ports;
mod produce;
mod report;
mod samples;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use ndds_client::Participant;

use samples::{Blob, SampleType, Telemetry, TelemetryV2};

#[derive(Debug, Parser)]
struct Cli {
    /// The sample type to declare (another type on the same topic is incompatible).
    #[arg(long = "type", value_enum, default_value = "telemetry", global = true)]
    sample_type: SampleType,
    #[command(subcommand)]
    role: Role,
}

#[derive(Debug, Subcommand)]
enum Role {
    /// Write samples at a rate.
    Produce(produce::Args),
    /// Read samples and print each one.
    Consume(consume::Args),
    /// A port role: own, send or waitfor.
    Port {
        /// Which role.
        #[arg(value_enum)]
        mode: ports::Mode,
        #[command(flatten)]
        args: ports::Args,
    },
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let participant = Participant::connect().context("connect to the test daemon")?;
    if let Role::Port { mode, args } = &cli.role {
        return ports::run(&participant, *mode, args);
    }
    match (&cli.role, cli.sample_type) {
        (Role::Produce(args), SampleType::Telemetry) => {
            produce::run::<Telemetry>(&participant, args)
        }
        (Role::Produce(args), SampleType::TelemetryV2) => {
            produce::run::<TelemetryV2>(&participant, args)
        }
        (Role::Consume(args), SampleType::Telemetry) => {
            consume::run::<Telemetry>(&participant, args)
        }
        (Role::Consume(args), SampleType::TelemetryV2) => {
            consume::run::<TelemetryV2>(&participant, args)
        }
        (Role::Produce(args), SampleType::Blob) => produce::run::<Blob>(&participant, args),
        (Role::Consume(args), SampleType::Blob) => consume::run::<Blob>(&participant, args),
        (Role::Port { .. }, _) => Ok(()),
    }
}

//! `ndds perf pub`: writes samples of `--size` bytes for `--duration`, flat out or at a rate,
//! and reports what it wrote (the subscriber reports what arrived).

use std::net::SocketAddrV4;
use std::time::Duration;

use ndds_client::{Batching, ProducerQos};

use super::sample::{PerfSample, parse_size, perf_type, wall_ns};
use super::throughput::{self, Published, Rate, parse_rate};
use super::{Stream, connect, udp};
use crate::connect::DaemonArgs;
use crate::seconds;

/// Options of `ndds perf pub`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    stream: Stream,
    /// Payload bytes per sample (suffixes k and M: powers of 1024).
    #[arg(long, value_parser = parse_size, default_value = "64")]
    pub size: usize,
    /// Seconds to publish.
    #[arg(long, value_parser = seconds::parse, default_value = "5")]
    pub duration: Duration,
    /// Samples per second, or `max`.
    #[arg(long, value_parser = parse_rate, default_value = "max")]
    pub rate: Rate,
    /// Batch small samples: the longest a sample waits for others, in microseconds.
    #[arg(long, value_name = "D", conflicts_with = "raw_udp")]
    batch_us: Option<u64>,
    /// Largest batch datagram in bytes (with --batch-us).
    #[arg(
        long,
        value_name = "B",
        default_value_t = 65_000,
        requires = "batch_us"
    )]
    batch_bytes: usize,
    /// Seconds to wait for a subscriber before publishing.
    #[arg(long, value_parser = seconds::parse, default_value = "10")]
    wait: Duration,
    /// Publish over plain UDP, one datagram per sample (to `ndds perf sub --raw-udp`).
    #[arg(long, requires = "peer")]
    raw_udp: bool,
    /// Address of the raw-UDP subscriber (127.0.0.1:PORT).
    #[arg(long, requires = "raw_udp")]
    peer: Option<SocketAddrV4>,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

impl Args {
    fn batching(&self) -> Batching {
        match self.batch_us {
            Some(us) => Batching::On {
                max_delay: Duration::from_micros(us),
                max_bytes: self.batch_bytes,
            },
            None => Batching::Off,
        }
    }

    fn batching_name(&self) -> String {
        match self.batch_us {
            Some(us) => format!("{us} us/{} B", self.batch_bytes),
            None => "off".to_owned(),
        }
    }
}

/// Runs `ndds perf pub`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let (out, transport) = match args.peer {
        Some(peer) if args.raw_udp => (
            udp::publish(peer, args.size, args.rate, args.duration, args.wait)?,
            "raw-udp",
        ),
        _ => (publish_ndds(daemon, args)?, "ndds"),
    };
    let setup = throughput::Setup {
        transport,
        reliability: args.stream.mode_name(),
        size: args.size,
        batching: args.batching_name(),
    };
    throughput::report_pub(&setup, &out, args.json)
}

fn publish_ndds(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<Published> {
    let participant = connect(daemon)?;
    let qos = ProducerQos {
        batching: args.batching(),
        ..args.stream.producer_qos()
    };
    let producer = participant.producer_with_type::<PerfSample>(
        &args.stream.topic("data"),
        perf_type(),
        qos,
    )?;
    if !producer.wait_for_consumers(1, args.wait) {
        anyhow::bail!(
            "no `ndds perf sub` matched topic {} within {} s",
            args.stream.topic("data"),
            args.wait.as_secs_f64()
        );
    }
    let mut sample = PerfSample::with_size(args.size);
    let out = throughput::publish_for(
        args.duration,
        args.rate,
        |seq| {
            sample.seq = seq;
            if throughput::stamp_due(seq, args.rate) {
                sample.sent_ns = wall_ns();
            }
            producer.write(&sample)
        },
        || !producer.matched().is_empty(),
    );
    producer.flush()?;
    if args.stream.reliable {
        // Repairs of the last samples need the producer a little longer.
        std::thread::sleep(Duration::from_millis(200));
    }
    Ok(out)
}

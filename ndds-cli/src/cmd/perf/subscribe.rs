//! `ndds perf sub`: counts the samples that arrive (on a direct consumer, so counting costs no
//! thread switch) and reports rate, bandwidth and loss over a steady window: from `--warmup`
//! seconds after the first sample, for `--duration` seconds or until the publisher stops.

use std::net::SocketAddrV4;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use ndds_client::Guid;

use super::sample::Gaps;
use super::throughput::{self, Counts, Measured, Window};
use super::{Stream, connect, udp};
use crate::connect::DaemonArgs;
use crate::seconds;

/// Options of `ndds perf sub`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    stream: Stream,
    /// Seconds measured (the steady window).
    #[arg(long, value_parser = seconds::parse, default_value = "3")]
    duration: Duration,
    /// Seconds skipped after the first sample.
    #[arg(long, value_parser = seconds::parse, default_value = "0.5")]
    warmup: Duration,
    /// Seconds to wait for the first sample.
    #[arg(long, value_parser = seconds::parse, default_value = "10")]
    wait: Duration,
    /// Seconds of silence taken as the publisher's end (the window ends there).
    #[arg(long, value_parser = seconds::parse, default_value = "0.5")]
    idle: Duration,
    /// Receive plain UDP datagrams (from `ndds perf pub --raw-udp`).
    #[arg(long, requires = "bind")]
    raw_udp: bool,
    /// Address the raw-UDP subscriber listens on (127.0.0.1:PORT).
    #[arg(long, requires = "raw_udp")]
    bind: Option<SocketAddrV4>,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `ndds perf sub`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let window = Window {
        wait: args.wait,
        warmup: args.warmup,
        length: args.duration,
        idle: args.idle,
    };
    let (measured, transport) = match args.bind {
        Some(bind) if args.raw_udp => (udp::subscribe(bind, &window)?, "raw-udp"),
        _ => (subscribe_ndds(daemon, args, &window)?, "ndds"),
    };
    let setup = throughput::Setup {
        transport,
        reliability: args.stream.mode_name(),
        size: 0,
        batching: String::new(),
    };
    throughput::report_sub(&setup, &measured, args.json)
}

/// The counts, and the sequence gaps of each writer (usually one).
#[derive(Debug, Default)]
pub struct Tally {
    pub counts: Counts,
    writers: Vec<(Guid, Gaps)>,
}

impl Tally {
    /// Counts one sample of `bytes` payload bytes, number `seq` of `writer`.
    pub fn see(&mut self, writer: Guid, seq: u64, bytes: usize) {
        let index = match self.writers.iter().position(|(w, _)| *w == writer) {
            Some(index) => index,
            None => {
                self.writers.push((writer, Gaps::default()));
                self.writers.len() - 1
            }
        };
        let gaps = &mut self.writers[index].1;
        let before = *gaps;
        gaps.see(seq);
        self.counts.samples += 1;
        self.counts.bytes += bytes as u64;
        self.counts.lost += gaps.lost - before.lost;
        self.counts.late += gaps.late - before.late;
    }
}

fn subscribe_ndds(daemon: &DaemonArgs, args: &Args, window: &Window) -> anyhow::Result<Measured> {
    let participant = connect(daemon)?;
    let consumer = participant.raw_consumer(
        &args.stream.topic("data"),
        super::sample::perf_type(),
        args.stream.consumer_qos(),
    )?;
    let tally = Arc::new(Mutex::new(Tally::default()));
    let counter = Arc::clone(&tally);
    // Undecoded, read in place: the sample's fields without copying its payload.
    let direct = consumer.on_raw_sample_direct(move |sample| {
        if let Some(view) = super::sample::PerfView::read(&sample.payload) {
            let mut tally = counter.lock().unwrap_or_else(|p| p.into_inner());
            tally.see(sample.info.writer, view.seq, view.payload.len());
        }
    })?;
    let measured = throughput::measure(window, || {
        tally.lock().unwrap_or_else(|p| p.into_inner()).counts
    });
    let measured = measured
        .map_err(|err| anyhow::anyhow!("{err:#} ({})", diagnosis(&participant, direct.consumer())));
    drop(direct);
    measured
}

/// What the consumer and its participant saw, for a run that measured nothing: whether the
/// producer was matched, whether datagrams came, and what was dropped.
fn diagnosis(
    participant: &ndds_client::Participant,
    consumer: &ndds_client::RawConsumer,
) -> String {
    let c = consumer.stats();
    let p = participant.stats();
    let dropped: Vec<String> = p
        .dropped
        .iter()
        .filter(|(_, n)| *n > 0)
        .map(|(why, n)| format!("{why} {n}"))
        .collect();
    format!(
        "{} producer(s) matched; consumer: {} samples arrived, {} delivered, {} from unmatched \
         senders, {} reliable stream(s) ({} received, {} handed on, {} lost, {} requests, {} \
         acknowledgements); participant: {} datagrams received, {} sent, {} fragments refused, \
         dropped: {}",
        consumer.matched().len(),
        c.received,
        c.delivered,
        c.unmatched,
        c.reliable_streams,
        c.reliable.received,
        c.reliable.delivered,
        c.reliable.lost,
        c.reliable.nacks,
        c.reliable.acks,
        p.received,
        p.sent,
        p.fragments_refused,
        if dropped.is_empty() {
            "none".to_string()
        } else {
            dropped.join(", ")
        },
    )
}

//! `ndds perf ping`: round trips through `ndds perf pong`.
//!
//! Pings go out on `PREFIX/ping`; the pong writes each back on `PREFIX/pong`. Replies are
//! taken by a direct consumer (on the participant's I/O thread), which records the round
//! trip and writes the next ping at once: no thread switch anywhere in the loop, as in a raw
//! UDP loop that sends and receives on one thread. The main thread only watches: it resends
//! when a ping or its reply was lost, and stops the run. With `--rate`, the main thread sends
//! pings at that rate instead, and replies are only recorded.

use std::net::SocketAddrV4;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use ndds_client::Producer;

use super::latency::{self, Limit, Progress};
use super::sample::{PerfSample, PerfView, mono_ns, parse_size, perf_type};
use super::{Stream, connect, udp};
use crate::connect::DaemonArgs;
use crate::seconds;

/// Round trips without any reply after which the pong is taken for gone.
pub const STALL: u32 = 10;
/// Resend interval while waiting for the very first reply (the pong may not have matched
/// this ping's consumer yet).
pub const FIRST_RETRY: Duration = Duration::from_millis(50);

/// Options of `ndds perf ping`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    stream: Stream,
    #[command(flatten)]
    run: PingRun,
    /// Measure over plain UDP sockets, with no ndds (against `ndds perf pong --raw-udp`).
    #[arg(long, requires = "peer")]
    raw_udp: bool,
    /// Address of the raw-UDP pong (127.0.0.1:PORT).
    #[arg(long, requires = "raw_udp")]
    peer: Option<SocketAddrV4>,
}

/// What a ping run measures, with ndds or raw UDP.
#[derive(Clone, Debug, clap::Args)]
pub struct PingRun {
    /// Payload bytes per sample (suffixes k and M: powers of 1024).
    #[arg(long, value_parser = parse_size, default_value = "64")]
    pub size: usize,
    /// Round trips to measure after the warm-up [default: 1000 unless --duration is given].
    #[arg(long, conflicts_with = "duration")]
    pub count: Option<u64>,
    /// Seconds to measure after the warm-up.
    #[arg(long, value_parser = seconds::parse)]
    pub duration: Option<Duration>,
    /// Send pings at this rate (Hz) instead of each on the previous reply.
    #[arg(long, value_parser = seconds::parse_rate, value_name = "HZ")]
    pub rate: Option<Duration>,
    /// Round trips excluded at the start.
    #[arg(long, default_value_t = 100)]
    pub warmup: u64,
    /// Seconds without a reply after which a ping counts as lost.
    #[arg(long, value_parser = seconds::parse, default_value = "1")]
    pub timeout: Duration,
    /// Seconds to wait for the pong to answer at all.
    #[arg(long, value_parser = seconds::parse, default_value = "10")]
    pub wait: Duration,
    /// One JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

impl PingRun {
    pub fn limit(&self) -> Limit {
        match (self.count, self.duration) {
            (Some(count), _) => Limit::Count(count),
            (None, Some(duration)) => Limit::Duration(duration),
            (None, None) => Limit::Count(1000),
        }
    }
}

/// Runs `ndds perf ping`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let start = Instant::now();
    let (progress, transport) = match args.peer {
        Some(peer) if args.raw_udp => (udp::ping(peer, &args.run)?, "raw-udp"),
        _ => (ping_ndds(daemon, args)?, "ndds"),
    };
    let setup = latency::Setup {
        transport,
        reliability: args.stream.mode_name(),
        size: args.run.size,
        warmup: args.run.warmup,
        elapsed: start.elapsed(),
    };
    latency::report(&setup, &progress.trips.summary(), args.run.json)
}

/// What the reply callback and the main thread share.
struct Pinger {
    producer: Producer<PerfSample>,
    state: Mutex<State>,
    changed: Condvar,
    /// Each reply sends the next ping (no `--rate`).
    closed_loop: bool,
}

struct State {
    /// The next ping; its payload is allocated once.
    next: PerfSample,
    progress: Progress,
    sent: u64,
    last_sent: Instant,
    last_reply: Option<Instant>,
    finished: bool,
    error: Option<String>,
}

impl Pinger {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Writes the next ping; a failed write is kept for the main thread to report.
    fn send_next(&self, state: &mut State) {
        state.next.seq += 1;
        state.next.sent_ns = mono_ns();
        state.sent += 1;
        state.last_sent = Instant::now();
        if let Err(err) = self.producer.write(&state.next) {
            state.error.get_or_insert_with(|| err.to_string());
        }
    }

    /// A reply, on the participant's I/O thread.
    fn on_reply(&self, reply: &PerfView<'_>) {
        let arrived = mono_ns();
        let now = Instant::now();
        let mut state = self.lock();
        // A late reply to a ping already given up is not a round trip of this loop.
        if state.finished || (self.closed_loop && reply.seq != state.next.seq) {
            return;
        }
        state
            .progress
            .record(arrived.saturating_sub(reply.sent_ns), now);
        state.last_reply = Some(now);
        if state.progress.done(now) {
            state.finished = true;
            self.changed.notify_all();
        } else if self.closed_loop {
            self.send_next(&mut state);
        }
    }
}

fn ping_ndds(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<Progress> {
    let run = &args.run;
    let participant = connect(daemon)?;
    let producer = participant.producer_with_type::<PerfSample>(
        &args.stream.topic("ping"),
        perf_type(),
        args.stream.producer_qos(),
    )?;
    let consumer = participant.raw_consumer(
        &args.stream.topic("pong"),
        perf_type(),
        args.stream.consumer_qos(),
    )?;
    let matched =
        producer.wait_for_consumers(1, run.wait) && consumer.wait_for_producers(1, run.wait);
    if !matched {
        anyhow::bail!(
            "no `ndds perf pong` matched topic {} within {} s",
            args.stream.topic,
            run.wait.as_secs_f64()
        );
    }
    let pinger = Arc::new(Pinger {
        producer,
        state: Mutex::new(State {
            next: PerfSample::with_size(run.size),
            progress: Progress::new(run.warmup, run.limit()),
            sent: 0,
            last_sent: Instant::now(),
            last_reply: None,
            finished: false,
            error: None,
        }),
        changed: Condvar::new(),
        closed_loop: run.rate.is_none(),
    });
    // The callback holds no strong reference: the producer is dropped here, never on the
    // I/O thread.
    let replies = Arc::downgrade(&pinger);
    // Replies are read in place (no copy of their payload), as raw UDP reads them.
    let direct = consumer.on_raw_sample_direct(move |reply| {
        if let (Some(pinger), Some(view)) = (replies.upgrade(), PerfView::read(&reply.payload)) {
            pinger.on_reply(&view);
        }
    })?;
    let result = match run.rate {
        None => watch_closed_loop(&pinger, run),
        Some(period) => drive_open_loop(&pinger, run, period),
    };
    // The callback goes first, then the producer it writes with, then the participant.
    drop(direct);
    let mut state = pinger.lock();
    state.finished = true;
    result?;
    Ok(std::mem::replace(
        &mut state.progress,
        Progress::new(0, Limit::Count(0)),
    ))
}

/// Watches a loop driven by the replies: resends after a loss, stops at the end.
fn watch_closed_loop(pinger: &Pinger, run: &PingRun) -> anyhow::Result<()> {
    let mut state = pinger.lock();
    pinger.send_next(&mut state);
    let begun = Instant::now();
    let (mut silent, mut seen) = (0, 0);
    loop {
        let first = state.last_reply.is_none();
        let timeout = if first { FIRST_RETRY } else { run.timeout };
        state = pinger
            .changed
            .wait_timeout(state, timeout)
            .map(|(guard, _)| guard)
            .unwrap_or_else(|p| p.into_inner().0);
        if let Some(err) = state.error.take() {
            anyhow::bail!("writing a ping failed: {err}");
        }
        let now = Instant::now();
        if state.finished || state.progress.done(now) {
            return Ok(());
        }
        if state.progress.trips.replies != seen {
            (seen, silent) = (state.progress.trips.replies, 0);
        }
        if now.duration_since(state.last_sent) < timeout {
            continue;
        }
        if first {
            if now.duration_since(begun) >= run.wait {
                anyhow::bail!(
                    "the pong never answered within {} s",
                    run.wait.as_secs_f64()
                );
            }
        } else {
            state.progress.trips.lost += 1;
            silent += 1;
            if silent >= STALL {
                anyhow::bail!("the pong stopped answering ({STALL} pings lost in a row)");
            }
        }
        pinger.send_next(&mut state);
    }
}

/// Sends pings at a fixed rate from this thread; the callback records the replies.
fn drive_open_loop(pinger: &Pinger, run: &PingRun, period: Duration) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut due = start;
    loop {
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        let mut state = pinger.lock();
        let now = Instant::now();
        if let Some(err) = state.error.take() {
            anyhow::bail!("writing a ping failed: {err}");
        }
        if state.finished || !state.progress.wants_more(state.sent, now) {
            break;
        }
        let heard = state.last_reply.unwrap_or(start);
        if now.duration_since(heard) >= run.timeout * STALL && now.duration_since(start) > run.wait
        {
            anyhow::bail!("the pong stopped answering");
        }
        pinger.send_next(&mut state);
        due += period;
    }
    // The last replies get one timeout to come back.
    let grace = Instant::now() + run.timeout;
    let mut state = pinger.lock();
    while state.progress.trips.replies < state.sent && Instant::now() < grace {
        state = pinger
            .changed
            .wait_timeout(state, Duration::from_millis(10))
            .map(|(guard, _)| guard)
            .unwrap_or_else(|p| p.into_inner().0);
    }
    state.progress.trips.lost = state.sent - state.progress.trips.replies.min(state.sent);
    Ok(())
}

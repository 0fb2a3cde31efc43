//! `ndds perf pong`: writes every ping back as it came, from a direct consumer (on the
//! participant's I/O thread, no thread switch), until its ping goes away or `--duration`
//! passes.

use std::net::SocketAddrV4;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ndds_client::RawProducer;
use serde_json::json;

use super::sample::perf_type;
use super::{Stream, connect, udp};
use crate::connect::DaemonArgs;
use crate::{outln, seconds};

/// How often the main thread looks whether its ping is still there.
const CHECK: Duration = Duration::from_millis(50);

/// Options of `ndds perf pong`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    stream: Stream,
    /// Stop after this many seconds even if a ping is still running.
    #[arg(long, value_parser = seconds::parse, default_value = "600")]
    duration: Duration,
    /// Answer raw-UDP pings (`ndds perf ping --raw-udp`) instead of ndds ones.
    #[arg(long, requires = "bind")]
    raw_udp: bool,
    /// Address the raw-UDP pong listens on (127.0.0.1:PORT).
    #[arg(long, requires = "raw_udp")]
    bind: Option<SocketAddrV4>,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `ndds perf pong`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let (echoed, transport) = match args.bind {
        Some(bind) if args.raw_udp => (udp::pong(bind, args.duration)?, "raw-udp"),
        _ => (pong_ndds(daemon, args)?, "ndds"),
    };
    if args.json {
        outln!(
            "{}",
            json!({"mode": "pong", "transport": transport, "echoed": echoed.echoed,
                   "errors": echoed.errors, "first_error": echoed.first_error})
        )?;
    } else {
        outln!(
            "pong {transport}: {} samples echoed, {} write errors",
            echoed.echoed,
            echoed.errors
        )?;
    }
    Ok(())
}

/// What a pong did.
#[derive(Debug, Default)]
pub struct Echoed {
    pub echoed: u64,
    pub errors: u64,
    pub first_error: Option<String>,
}

/// What the callback uses and counts.
struct Echo {
    producer: RawProducer,
    echoed: AtomicU64,
    errors: AtomicU64,
    first_error: Mutex<Option<String>>,
}

impl Echo {
    fn answer(&self, ping: &[u8]) {
        match self.producer.write_bytes(ping) {
            Ok(()) => self.echoed.fetch_add(1, Ordering::Relaxed),
            Err(err) => {
                let mut first = self.first_error.lock().unwrap_or_else(|p| p.into_inner());
                first.get_or_insert_with(|| err.to_string());
                self.errors.fetch_add(1, Ordering::Relaxed)
            }
        };
    }
}

fn pong_ndds(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<Echoed> {
    let participant = connect(daemon)?;
    // The ping's bytes go back as they came: no decoding, no encoding.
    let producer = participant.raw_producer(
        &args.stream.topic("pong"),
        perf_type(),
        args.stream.producer_qos(),
    )?;
    let consumer = participant.raw_consumer(
        &args.stream.topic("ping"),
        perf_type(),
        args.stream.consumer_qos(),
    )?;
    let echo = Arc::new(Echo {
        producer,
        echoed: AtomicU64::new(0),
        errors: AtomicU64::new(0),
        first_error: Mutex::new(None),
    });
    // A weak reference, so the producer is dropped here and never on the I/O thread.
    let answers = Arc::downgrade(&echo);
    let direct = consumer.on_raw_sample_direct(move |ping| {
        if let Some(echo) = answers.upgrade() {
            echo.answer(&ping.payload);
        }
    })?;
    wait_for_ping_to_leave(&echo, args.duration);
    drop(direct);
    Ok(Echoed {
        echoed: echo.echoed.load(Ordering::Relaxed),
        errors: echo.errors.load(Ordering::Relaxed),
        first_error: echo.first_error.lock().ok().and_then(|e| e.clone()),
    })
}

/// Returns once a ping has come (matched, or answered) and gone again (unmatched, and no
/// ping answered since the previous look), or after `duration`.
fn wait_for_ping_to_leave(echo: &Echo, duration: Duration) {
    let end = seconds::deadline(duration);
    let (mut seen, mut answered) = (false, 0);
    while !seconds::passed(end) {
        let matched = !echo.producer.matched().is_empty();
        let now_answered = echo.echoed.load(Ordering::Relaxed);
        if seen && !matched && now_answered == answered {
            return;
        }
        seen |= matched || now_answered > 0;
        answered = now_answered;
        let left = end.map_or(CHECK, |end| end.saturating_duration_since(Instant::now()));
        std::thread::sleep(left.min(CHECK));
    }
}

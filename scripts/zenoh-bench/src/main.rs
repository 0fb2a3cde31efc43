//! The Zenoh side of `scripts/bench-zenoh.sh`: a publisher that writes flat out and a
//! subscriber that counts what arrives in a steady window, reported with the field names of
//! `ndds perf sub --json`.
//!
//! ```text
//! zenoh-bench sub --port P [--duration S] [--warmup W] [--json]
//! zenoh-bench pub --port P [--size N] [--duration S] [--json]
//! ```
//!
//! Both are Zenoh peers with multicast and gossip scouting off: the subscriber listens on
//! tcp/127.0.0.1:P only, the publisher listens nowhere and connects to it, so every byte stays
//! on loopback. The publisher is reliable with congestion control `Block` and Zenoh's default
//! batching; each payload starts with its sequence number (8 bytes, little-endian, from 1),
//! the rest is a fixed pattern. The subscriber counts the sequence numbers that never arrive.
//!
//! It is not part of the ndds workspace (its own `[workspace]`) and CI never builds it.

use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use zenoh::Wait;
use zenoh::qos::CongestionControl;

/// The key both sides use.
const KEY: &str = "ndds/bench/zenoh";
/// How often the subscriber looks at its counters (as `ndds perf sub`).
const TICK: Duration = Duration::from_millis(10);
/// Silence taken as the publisher's end (as `ndds perf sub`).
const IDLE: Duration = Duration::from_millis(500);
/// Longest wait for the first sample.
const FIRST_WAIT: Duration = Duration::from_secs(10);
/// How often the publisher asks whether its subscriber is still there.
const ALIVE_EVERY: Duration = Duration::from_millis(20);
/// Bytes of the sequence number at the start of each payload.
const SEQ_BYTES: usize = 8;

/// The command line: a mode and its options.
#[derive(Debug)]
struct Args {
    mode: Mode,
    port: u16,
    size: usize,
    duration: Duration,
    warmup: Duration,
    json: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Pub,
    Sub,
}

fn parse_args() -> Result<Args, String> {
    let mut words = std::env::args().skip(1);
    let mode = match words.next().as_deref() {
        Some("pub") => Mode::Pub,
        Some("sub") => Mode::Sub,
        other => return Err(format!("expected `pub` or `sub`, got {other:?}")),
    };
    let mut args = Args {
        mode,
        port: 0,
        size: 64,
        duration: Duration::from_secs(3),
        warmup: Duration::from_millis(500),
        json: false,
    };
    while let Some(word) = words.next() {
        let mut value = || words.next().ok_or(format!("{word} needs a value"));
        match word.as_str() {
            "--port" => args.port = value()?.parse().map_err(|e| format!("--port: {e}"))?,
            "--size" => args.size = value()?.parse().map_err(|e| format!("--size: {e}"))?,
            "--duration" => args.duration = seconds(&value()?)?,
            "--warmup" => args.warmup = seconds(&value()?)?,
            "--json" => args.json = true,
            _ => return Err(format!("unknown option {word}")),
        }
    }
    if args.port == 0 {
        return Err("--port is required".into());
    }
    if args.size < SEQ_BYTES {
        return Err(format!("--size must be at least {SEQ_BYTES}"));
    }
    Ok(args)
}

fn seconds(text: &str) -> Result<Duration, String> {
    text.parse::<f64>()
        .ok()
        .and_then(|s| Duration::try_from_secs_f64(s).ok())
        .ok_or(format!("not a number of seconds: {text}"))
}

/// A peer with no scouting; the subscriber listens on loopback, the publisher connects there.
fn config(mode: Mode, port: u16) -> zenoh::Result<zenoh::Config> {
    let endpoint = format!(r#"["tcp/127.0.0.1:{port}"]"#);
    let (listen, connect) = match mode {
        Mode::Sub => (endpoint.as_str(), "[]"),
        Mode::Pub => ("[]", endpoint.as_str()),
    };
    let mut config = zenoh::Config::default();
    config.insert_json5("mode", r#""peer""#)?;
    config.insert_json5("scouting/multicast/enabled", "false")?;
    config.insert_json5("scouting/gossip/enabled", "false")?;
    config.insert_json5("listen/endpoints", listen)?;
    config.insert_json5("connect/endpoints", connect)?;
    Ok(config)
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(args) => args,
        Err(err) => {
            eprintln!("zenoh-bench: {err}");
            return ExitCode::from(2);
        }
    };
    let outcome = match args.mode {
        Mode::Pub => publish(&args),
        Mode::Sub => subscribe(&args),
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("zenoh-bench {:?}: {err}", args.mode);
            ExitCode::FAILURE
        }
    }
}

// ------------------------------------------------------------------------------- publisher

fn publish(args: &Args) -> zenoh::Result<()> {
    let session = zenoh::open(config(Mode::Pub, args.port)?).wait()?;
    // Reliable is the publisher's default (setting it is an `unstable` API); over TCP it
    // means that nothing is dropped, and `Block` that a full queue waits instead of dropping.
    let publisher = session
        .declare_publisher(KEY)
        .congestion_control(CongestionControl::Block)
        .wait()?;
    let pattern: Vec<u8> = (0..args.size).map(|i| (i % 251) as u8).collect();
    let start = Instant::now();
    let (mut written, mut errors) = (0u64, 0u64);
    let (mut now, mut asked, mut matched) = (start, start, false);
    while now.duration_since(start) < args.duration {
        // The clock is read once per 64 writes, as `ndds perf pub` does flat out.
        for _ in 0..64 {
            written += 1;
            let mut payload = pattern.clone();
            payload[..SEQ_BYTES].copy_from_slice(&written.to_le_bytes());
            if publisher.put(payload).wait().is_err() {
                errors += 1;
            }
        }
        now = Instant::now();
        // Like `ndds perf pub`: stop once the subscriber that was there has gone.
        if now.duration_since(asked) >= ALIVE_EVERY {
            let matching = publisher.matching_status().wait()?.matching();
            if matched && !matching {
                break;
            }
            (matched, asked) = (matched || matching, now);
        }
    }
    let elapsed = start.elapsed().as_secs_f64();
    let rate = written as f64 / elapsed;
    if args.json {
        println!(
            r#"{{"mode":"pub","transport":"zenoh","reliability":"reliable","size":{},"written":{written},"errors":{errors},"elapsed_s":{elapsed},"samples_per_s":{rate},"mb_per_s":{}}}"#,
            args.size,
            rate * args.size as f64 / 1e6
        );
    } else {
        println!(
            "pub zenoh reliable {} B: {written} samples in {elapsed:.2} s: {rate:.0} samples/s, {errors} errors",
            args.size
        );
    }
    drop(publisher);
    session.close().wait()
}

// ------------------------------------------------------------------------------ subscriber

/// What the subscriber counted so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Counts {
    samples: u64,
    bytes: u64,
    /// Sequence numbers skipped.
    lost: u64,
    /// Samples at or below one already seen.
    late: u64,
    /// The sequence number expected next (0: nothing seen yet).
    next: u64,
}

impl Counts {
    fn see(&mut self, seq: u64, bytes: usize) {
        self.samples += 1;
        self.bytes += bytes as u64;
        if self.next == 0 || seq == self.next {
            self.next = seq + 1;
        } else if seq > self.next {
            self.lost += seq - self.next;
            self.next = seq + 1;
        } else {
            self.late += 1;
        }
    }

    fn minus(self, earlier: Counts) -> Counts {
        Counts {
            samples: self.samples - earlier.samples,
            bytes: self.bytes - earlier.bytes,
            lost: self.lost - earlier.lost,
            late: self.late - earlier.late,
            next: self.next,
        }
    }
}

fn subscribe(args: &Args) -> zenoh::Result<()> {
    let session = zenoh::open(config(Mode::Sub, args.port)?).wait()?;
    let counts = Arc::new(Mutex::new(Counts::default()));
    let counter = Arc::clone(&counts);
    let subscriber = session
        .declare_subscriber(KEY)
        .callback(move |sample| {
            let payload = sample.payload().to_bytes();
            if let Some(head) = payload.get(..SEQ_BYTES) {
                let seq = u64::from_le_bytes(head.try_into().expect("8 bytes"));
                let mut counts = counter.lock().unwrap_or_else(|p| p.into_inner());
                counts.see(seq, payload.len());
            }
        })
        .wait()?;
    let poll = || *counts.lock().unwrap_or_else(|p| p.into_inner());
    let (window, span, total) = measure(args, poll)?;
    report(args, window, span, total);
    drop(subscriber);
    session.close().wait()
}

/// Waits for the first sample, skips the warm-up, then measures for `--duration` or until
/// the publisher falls silent: the window's counts, its length and the counts of the run.
fn measure(
    args: &Args,
    mut poll: impl FnMut() -> Counts,
) -> zenoh::Result<(Counts, Duration, Counts)> {
    let waited = Instant::now();
    while poll().samples == 0 {
        if waited.elapsed() > FIRST_WAIT {
            return Err(format!("no sample within {} s", FIRST_WAIT.as_secs()).into());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let first = Instant::now();
    let (mut last_at, mut last) = (first, poll());
    let mut start: Option<(Instant, Counts)> = None;
    loop {
        std::thread::sleep(TICK);
        let (now, counts) = (Instant::now(), poll());
        if counts != last {
            (last_at, last) = (now, counts);
        }
        if start.is_none() && now >= first + args.warmup {
            start = Some((now, counts));
        }
        let idle = now.duration_since(last_at) >= IDLE;
        let full = start.is_some_and(|(at, _)| now.duration_since(at) >= args.duration);
        if idle || full {
            let (begin_at, begin) = start.unwrap_or((last_at, last));
            let (end_at, end) = if idle { (last_at, last) } else { (now, counts) };
            let span = end_at.saturating_duration_since(begin_at);
            return Ok((end.minus(begin), span, counts));
        }
    }
}

fn report(args: &Args, w: Counts, span: Duration, total: Counts) {
    let secs = span.as_secs_f64();
    let per_s = |n: u64| if secs > 0.0 { n as f64 / secs } else { 0.0 };
    let (rate, mbps) = (per_s(w.samples), per_s(w.bytes) / 1e6);
    let loss = match w.samples + w.lost {
        0 => 0.0,
        all => 100.0 * w.lost as f64 / all as f64,
    };
    let size = w.bytes.checked_div(w.samples).unwrap_or(0);
    if args.json {
        println!(
            r#"{{"mode":"sub","transport":"zenoh","reliability":"reliable","size":{size},"window_s":{secs},"samples":{},"bytes":{},"lost":{},"late":{},"loss_pct":{loss},"samples_per_s":{rate},"mb_per_s":{mbps},"total_samples":{},"total_lost":{}}}"#,
            w.samples, w.bytes, w.lost, w.late, total.samples, total.lost
        );
    } else {
        println!(
            "sub zenoh reliable {size} B: {} samples in a {secs:.2} s window: {rate:.0} samples/s, \
             {mbps:.1} MB/s, {} lost ({loss:.2} %), {} late; {} samples in all",
            w.samples, w.lost, w.late, total.samples
        );
    }
}

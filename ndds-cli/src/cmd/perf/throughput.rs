//! Throughput: the publishing loop (paced or flat out, for a duration), the receiving side's
//! steady window (start-up and tail excluded), and their reports.

use std::time::{Duration, Instant};

use serde_json::json;

use crate::{outln, seconds};

/// How often the receiving side looks at its counters.
const TICK: Duration = Duration::from_millis(10);
/// Writes between two clock reads when publishing flat out.
const CLOCK_EVERY: u64 = 64;

/// How fast `pub` writes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rate {
    /// As fast as the writes return.
    Max,
    /// This many samples per second.
    Hz(f64),
}

/// `max`, or a positive rate in Hz.
pub fn parse_rate(text: &str) -> Result<Rate, String> {
    if text.trim().eq_ignore_ascii_case("max") {
        return Ok(Rate::Max);
    }
    seconds::parse_rate(text).map(|period| Rate::Hz(1.0 / period.as_secs_f64()))
}

/// What a publishing loop did.
#[derive(Clone, Debug, Default)]
pub struct Published {
    pub written: u64,
    pub errors: u64,
    pub first_error: Option<String>,
    pub elapsed: Duration,
}

/// How often the publishing loop asks whether anyone still listens.
const ALIVE_EVERY: Duration = Duration::from_millis(20);

/// Calls `write(seq)` with seq = 1, 2, ... at `rate` until `duration` has passed, or until
/// `listened` (asked every 20 ms) says that nobody receives any more.
pub fn publish_for<E: std::fmt::Display>(
    duration: Duration,
    rate: Rate,
    mut write: impl FnMut(u64) -> Result<(), E>,
    mut listened: impl FnMut() -> bool,
) -> Published {
    let start = Instant::now();
    let end = start.checked_add(duration);
    let mut out = Published::default();
    let (mut now, mut asked) = (start, start);
    while end.is_none_or(|end| now < end) {
        let due = match rate {
            Rate::Max => out.written + CLOCK_EVERY,
            Rate::Hz(hz) => (now.duration_since(start).as_secs_f64() * hz) as u64 + 1,
        };
        while out.written < due {
            out.written += 1;
            if let Err(err) = write(out.written) {
                out.errors += 1;
                out.first_error.get_or_insert_with(|| err.to_string());
            }
        }
        if let Rate::Hz(hz) = rate {
            pause_until(
                start + Duration::from_secs_f64(out.written as f64 / hz),
                end,
            );
        }
        now = Instant::now();
        if now.duration_since(asked) >= ALIVE_EVERY {
            if !listened() {
                break;
            }
            asked = now;
        }
    }
    out.elapsed = start.elapsed();
    out
}

/// Whether sample `seq` (1, 2, ...) gets a fresh timestamp. A clock read costs about 20 ns
/// on these machines, a tenth of a batched write: flat out, the timestamp is refreshed every
/// 64 samples (so it is at most some tens of microseconds old); paced, every time.
pub fn stamp_due(seq: u64, rate: Rate) -> bool {
    match rate {
        Rate::Max => seq % 64 == 1,
        Rate::Hz(_) => true,
    }
}

/// Sleeps (or, for short waits, yields) until `at`, but not past `end`.
fn pause_until(at: Instant, end: Option<Instant>) {
    let at = end.map_or(at, |end| at.min(end));
    let wait = at.saturating_duration_since(Instant::now());
    if wait >= Duration::from_micros(100) {
        std::thread::sleep(wait);
    } else if !wait.is_zero() {
        std::thread::yield_now();
    }
}

/// What a receiver counted so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Samples received whole.
    pub samples: u64,
    /// Their payload bytes.
    pub bytes: u64,
    /// Samples the sequence numbers show missing.
    pub lost: u64,
    /// Samples that arrived late or twice.
    pub late: u64,
}

impl Counts {
    fn minus(self, earlier: Counts) -> Counts {
        Counts {
            samples: self.samples - earlier.samples,
            bytes: self.bytes - earlier.bytes,
            lost: self.lost - earlier.lost,
            late: self.late - earlier.late,
        }
    }
}

/// The receiving side's timing: wait for the first sample, skip a warm-up, measure.
#[derive(Clone, Copy, Debug)]
pub struct Window {
    /// Longest wait for the first sample.
    pub wait: Duration,
    /// Skipped after the first sample.
    pub warmup: Duration,
    /// Length of the measured window.
    pub length: Duration,
    /// Silence that ends the window early (the publisher stopped).
    pub idle: Duration,
}

/// The counts of the steady window, and of the whole run.
#[derive(Clone, Copy, Debug)]
pub struct Measured {
    pub window: Counts,
    pub span: Duration,
    pub total: Counts,
}

/// Watches the counters `poll` returns and cuts the steady window out of them.
pub fn measure(window: &Window, mut poll: impl FnMut() -> Counts) -> anyhow::Result<Measured> {
    let first = wait_first(window.wait, &mut poll)?;
    let start_at = first + window.warmup;
    let (mut last_at, mut last) = (first, poll());
    let mut start = None;
    loop {
        std::thread::sleep(TICK);
        let (now, counts) = (Instant::now(), poll());
        if counts != last {
            (last_at, last) = (now, counts);
        }
        if start.is_none() && now >= start_at {
            start = Some((now, counts));
        }
        let idle = now.duration_since(last_at) >= window.idle;
        let full = start.is_some_and(|(at, _)| now.duration_since(at) >= window.length);
        if idle || full {
            let (begin_at, begin) = start.unwrap_or((last_at, last));
            let (end_at, end) = if idle { (last_at, last) } else { (now, counts) };
            return Ok(Measured {
                window: end.minus(begin),
                span: end_at.saturating_duration_since(begin_at),
                total: counts,
            });
        }
    }
}

/// When the first sample was seen.
fn wait_first(wait: Duration, poll: &mut impl FnMut() -> Counts) -> anyhow::Result<Instant> {
    let deadline = seconds::deadline(wait);
    loop {
        if poll().samples > 0 {
            return Ok(Instant::now());
        }
        if seconds::passed(deadline) {
            anyhow::bail!("no sample arrived within {} s", wait.as_secs_f64());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Describes a run for its report.
#[derive(Clone, Debug)]
pub struct Setup {
    pub transport: &'static str,
    pub reliability: &'static str,
    pub size: usize,
    /// How samples were packed (`off`, or the batching limits).
    pub batching: String,
}

fn mb_per_s(bytes: u64, span: Duration) -> f64 {
    per_s(bytes, span) / 1e6
}

fn per_s(count: u64, span: Duration) -> f64 {
    if span.is_zero() {
        0.0
    } else {
        count as f64 / span.as_secs_f64()
    }
}

/// Prints what a publisher did.
pub fn report_pub(setup: &Setup, out: &Published, as_json: bool) -> anyhow::Result<()> {
    let rate = per_s(out.written, out.elapsed);
    let mbps = mb_per_s(out.written * setup.size as u64, out.elapsed);
    if as_json {
        let value = json!({
            "mode": "pub",
            "transport": setup.transport,
            "reliability": setup.reliability,
            "size": setup.size,
            "batching": setup.batching,
            "written": out.written,
            "errors": out.errors,
            "first_error": out.first_error,
            "elapsed_s": out.elapsed.as_secs_f64(),
            "samples_per_s": rate,
            "mb_per_s": mbps,
        });
        outln!("{value}")?;
        return Ok(());
    }
    outln!(
        "pub {} {} {} B (batching {}): {} samples in {:.2} s: {:.0} samples/s, {:.1} MB/s, \
         {} write errors",
        setup.transport,
        setup.reliability,
        setup.size,
        setup.batching,
        out.written,
        out.elapsed.as_secs_f64(),
        rate,
        mbps,
        out.errors
    )?;
    if let Some(err) = &out.first_error {
        outln!("first write error: {err}")?;
    }
    Ok(())
}

/// Prints what a subscriber measured.
pub fn report_sub(setup: &Setup, m: &Measured, as_json: bool) -> anyhow::Result<()> {
    let w = m.window;
    let rate = per_s(w.samples, m.span);
    let mbps = mb_per_s(w.bytes, m.span);
    let loss = if w.samples + w.lost == 0 {
        0.0
    } else {
        100.0 * w.lost as f64 / (w.samples + w.lost) as f64
    };
    let size = w.bytes.checked_div(w.samples).unwrap_or(0);
    if as_json {
        let value = json!({
            "mode": "sub",
            "transport": setup.transport,
            "reliability": setup.reliability,
            "size": size,
            "window_s": m.span.as_secs_f64(),
            "samples": w.samples,
            "bytes": w.bytes,
            "lost": w.lost,
            "late": w.late,
            "loss_pct": loss,
            "samples_per_s": rate,
            "mb_per_s": mbps,
            "total_samples": m.total.samples,
            "total_lost": m.total.lost,
        });
        outln!("{value}")?;
        return Ok(());
    }
    outln!(
        "sub {} {} {size} B: {} samples in a {:.2} s window: {:.0} samples/s, {:.1} MB/s, \
         {} lost ({loss:.2} %), {} late; {} samples in all",
        setup.transport,
        setup.reliability,
        w.samples,
        m.span.as_secs_f64(),
        rate,
        mbps,
        w.lost,
        w.late,
        m.total.samples
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates() {
        assert_eq!(parse_rate("max"), Ok(Rate::Max));
        assert_eq!(parse_rate("1000"), Ok(Rate::Hz(1000.0)));
        assert!(parse_rate("0").is_err() && parse_rate("fast").is_err());
    }

    #[test]
    fn timestamps_are_refreshed_every_64_samples_when_flat_out() {
        let due = |rate| (1..=128).filter(|seq| stamp_due(*seq, rate)).count();
        assert_eq!((due(Rate::Max), due(Rate::Hz(10.0))), (2, 128));
        assert!(stamp_due(1, Rate::Max));
    }

    #[test]
    fn a_paced_publisher_keeps_its_rate() {
        let out = publish_for(
            Duration::from_millis(200),
            Rate::Hz(1000.0),
            |_| Ok::<(), String>(()),
            || true,
        );
        assert!((180..=220).contains(&out.written), "{out:?}");
        let flat = publish_for(
            Duration::from_millis(20),
            Rate::Max,
            |seq| if seq == 3 { Err("three") } else { Ok(()) },
            || true,
        );
        assert!(flat.written > 1000 && flat.errors == 1, "{flat:?}");
        assert_eq!(flat.first_error.as_deref(), Some("three"));
        let deaf = publish_for(
            Duration::from_secs(10),
            Rate::Max,
            |_| Ok::<(), String>(()),
            || false,
        );
        assert!(deaf.elapsed < Duration::from_secs(5), "{deaf:?}");
    }

    #[test]
    fn the_window_skips_the_warm_up_and_ends_when_the_sender_stops() {
        let start = Instant::now();
        let window = Window {
            wait: Duration::from_secs(1),
            warmup: Duration::from_millis(50),
            length: Duration::from_secs(5),
            idle: Duration::from_millis(100),
        };
        // 1 sample per ms for 300 ms, then silence.
        let m = measure(&window, || {
            let ms = start.elapsed().as_millis().min(300) as u64;
            Counts {
                samples: ms,
                bytes: ms * 10,
                lost: 0,
                late: 0,
            }
        })
        .unwrap();
        assert_eq!(m.total.samples, 300);
        assert!((100..=260).contains(&m.window.samples), "{m:?}");
        let rate = m.window.samples as f64 / m.span.as_secs_f64();
        assert!((500.0..2000.0).contains(&rate), "{m:?}");
    }

    #[test]
    fn no_sample_is_an_error() {
        let window = Window {
            wait: Duration::from_millis(20),
            warmup: Duration::ZERO,
            length: Duration::from_secs(1),
            idle: Duration::from_secs(1),
        };
        assert!(measure(&window, Counts::default).is_err());
    }
}

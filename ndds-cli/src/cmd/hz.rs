//! `ndds hz TOPIC`: the rate at which samples of a topic arrive here, how old they are when
//! they arrive, and how often a deadline was missed.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use ndds_client::{ConsumerQos, Notification, RawEvent, RawSample};
use serde_json::json;

use crate::cmd::echo::wait_for_type;
use crate::connect::{DaemonArgs, connect};
use crate::{outln, seconds};

/// Options of `ndds hz`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Topic name.
    topic: String,
    /// Number of most recent intervals the statistics cover.
    #[arg(long, default_value_t = 100)]
    window: usize,
    /// Seconds between reports (at least 0.01).
    #[arg(long, value_parser = seconds::parse_interval, default_value = "1")]
    every: Duration,
    /// Stop after this many seconds, with a final report [default: run until interrupted].
    #[arg(long, value_parser = seconds::parse)]
    duration: Option<Duration>,
    /// Seconds to wait for the topic to appear (`inf`: no limit).
    #[arg(long, value_parser = seconds::parse, default_value = "0")]
    wait: Duration,
    /// Choose among incompatible types on the topic by fingerprint.
    #[arg(long)]
    fingerprint: Option<String>,
    /// Count a deadline miss each time no sample arrived for this many seconds.
    #[arg(long, value_parser = seconds::parse)]
    deadline: Option<Duration>,
    /// One JSON object per report.
    #[arg(long)]
    json: bool,
}

/// Runs `ndds hz`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let participant = connect(daemon)?;
    let desc = wait_for_type(&args.topic, args.fingerprint.as_deref(), args.wait, || {
        Ok(participant.graph()?)
    })?;
    let consumer = participant.raw_consumer(
        &args.topic,
        desc,
        ConsumerQos {
            depth: 4096,
            deadline: args.deadline,
            ..ConsumerQos::default()
        },
    )?;
    let end = args.duration.and_then(seconds::deadline);
    let mut window = Window::new(args.window.max(2));
    let mut misses = 0u64;
    let mut next_report = Instant::now() + args.every;
    loop {
        let until = end.map_or(next_report, |end| end.min(next_report));
        let mut wait = until.saturating_duration_since(Instant::now());
        while let Ok(event) = consumer.recv_raw_event_timeout(wait) {
            match event {
                RawEvent::Sample(sample) => window.push(Instant::now(), age_ms(&sample)),
                RawEvent::Notification(
                    Notification::NoNewData { .. } | Notification::NeverReceived { .. },
                ) => misses += 1,
                RawEvent::Notification(_) => {}
            }
            wait = Duration::ZERO;
        }
        if seconds::passed(end) {
            report(&window, misses, args.json)?;
            return Ok(());
        }
        if Instant::now() >= next_report {
            report(&window, misses, args.json)?;
            next_report += args.every;
        }
    }
}

/// How old a sample was when it arrived, by the two hosts' clocks (0 if the source clock is
/// ahead of ours).
fn age_ms(sample: &RawSample) -> f64 {
    let info = &sample.info;
    info.reception_timestamp
        .duration_since(info.source_timestamp)
        .map_or(0.0, |age| age.as_secs_f64() * 1000.0)
}

fn report(window: &Window, misses: u64, as_json: bool) -> anyhow::Result<()> {
    let stats = window.stats();
    if as_json {
        let value = match stats {
            Some(s) => json!({
                "rate_hz": s.rate, "min_ms": s.min_ms, "max_ms": s.max_ms,
                "std_dev_ms": s.std_dev_ms, "window": s.intervals,
                "age_mean_ms": s.age_mean_ms, "age_max_ms": s.age_max_ms,
                "deadline_misses": misses,
            }),
            None => json!({"rate_hz": 0.0, "window": 0, "deadline_misses": misses}),
        };
        outln!("{value}")?;
        return Ok(());
    }
    match stats {
        Some(s) => outln!(
            "rate {:.2} Hz  min {:.3} ms  max {:.3} ms  std dev {:.3} ms  window {}  \
             age mean {:.3} ms max {:.3} ms  deadline misses {misses}",
            s.rate,
            s.min_ms,
            s.max_ms,
            s.std_dev_ms,
            s.intervals,
            s.age_mean_ms,
            s.age_max_ms
        )?,
        None => outln!("no samples yet  deadline misses {misses}")?,
    }
    Ok(())
}

/// Arrival times and ages of the last `capacity` samples.
struct Window {
    arrivals: VecDeque<(Instant, f64)>,
    capacity: usize,
}

struct Stats {
    rate: f64,
    min_ms: f64,
    max_ms: f64,
    std_dev_ms: f64,
    intervals: usize,
    age_mean_ms: f64,
    age_max_ms: f64,
}

impl Window {
    fn new(capacity: usize) -> Self {
        Window {
            arrivals: VecDeque::with_capacity(capacity + 1),
            capacity: capacity + 1,
        }
    }

    fn push(&mut self, at: Instant, age_ms: f64) {
        if self.arrivals.len() == self.capacity {
            self.arrivals.pop_front();
        }
        self.arrivals.push_back((at, age_ms));
    }

    fn stats(&self) -> Option<Stats> {
        let intervals: Vec<f64> = self
            .arrivals
            .iter()
            .zip(self.arrivals.iter().skip(1))
            .map(|((a, _), (b, _))| b.duration_since(*a).as_secs_f64() * 1000.0)
            .collect();
        if intervals.is_empty() {
            return None;
        }
        let n = intervals.len() as f64;
        let mean = intervals.iter().sum::<f64>() / n;
        let variance = intervals.iter().map(|i| (i - mean).powi(2)).sum::<f64>() / n;
        Some(Stats {
            rate: if mean > 0.0 {
                1000.0 / mean
            } else {
                f64::INFINITY
            },
            min_ms: intervals.iter().copied().fold(f64::INFINITY, f64::min),
            max_ms: intervals.iter().copied().fold(0.0, f64::max),
            std_dev_ms: variance.sqrt(),
            intervals: intervals.len(),
            age_mean_ms: self.arrivals.iter().map(|(_, age)| age).sum::<f64>()
                / self.arrivals.len() as f64,
            age_max_ms: self
                .arrivals
                .iter()
                .map(|(_, age)| *age)
                .fold(0.0, f64::max),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_statistics_of_a_regular_stream() {
        let start = Instant::now();
        let mut window = Window::new(10);
        for i in 0..30u32 {
            window.push(start + Duration::from_millis(10) * i, f64::from(i % 3));
        }
        let stats = window.stats().unwrap();
        assert_eq!(stats.intervals, 10);
        assert!((stats.rate - 100.0).abs() < 1e-6);
        assert!(stats.std_dev_ms < 1e-6);
        assert_eq!(stats.age_max_ms, 2.0);
        assert!((stats.age_mean_ms - 1.0).abs() < 0.2);
        assert!(Window::new(5).stats().is_none());
    }
}

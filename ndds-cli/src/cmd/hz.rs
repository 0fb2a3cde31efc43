//! `ndds hz TOPIC`: the rate at which samples of a topic arrive here.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use ndds_client::ConsumerQos;
use serde_json::json;

use crate::cmd::echo::wait_for_type;
use crate::connect::{DaemonArgs, connect};
use crate::seconds;

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
            ..ConsumerQos::default()
        },
    )?;
    let end = args.duration.and_then(seconds::deadline);
    let mut window = Window::new(args.window.max(2));
    let mut next_report = Instant::now() + args.every;
    loop {
        let until = end.map_or(next_report, |end| end.min(next_report));
        if consumer
            .recv_raw_timeout(until.saturating_duration_since(Instant::now()))
            .is_ok()
        {
            window.push(Instant::now());
            while consumer.try_recv_raw().is_ok() {
                window.push(Instant::now());
            }
        }
        if seconds::passed(end) {
            report(&window, args.json);
            return Ok(());
        }
        if Instant::now() >= next_report {
            report(&window, args.json);
            next_report += args.every;
        }
    }
}

fn report(window: &Window, as_json: bool) {
    let stats = window.stats();
    if as_json {
        let value = match stats {
            Some(s) => {
                json!({"rate_hz": s.rate, "min_ms": s.min_ms, "max_ms": s.max_ms, "std_dev_ms": s.std_dev_ms, "window": s.intervals})
            }
            None => json!({"rate_hz": 0.0, "window": 0}),
        };
        println!("{value}");
        return;
    }
    match stats {
        Some(s) => println!(
            "rate {:.2} Hz  min {:.3} ms  max {:.3} ms  std dev {:.3} ms  window {}",
            s.rate, s.min_ms, s.max_ms, s.std_dev_ms, s.intervals
        ),
        None => println!("no samples yet"),
    }
}

/// Arrival times of the last `capacity` samples.
struct Window {
    arrivals: VecDeque<Instant>,
    capacity: usize,
}

struct Stats {
    rate: f64,
    min_ms: f64,
    max_ms: f64,
    std_dev_ms: f64,
    intervals: usize,
}

impl Window {
    fn new(capacity: usize) -> Self {
        Window {
            arrivals: VecDeque::with_capacity(capacity + 1),
            capacity: capacity + 1,
        }
    }

    fn push(&mut self, at: Instant) {
        if self.arrivals.len() == self.capacity {
            self.arrivals.pop_front();
        }
        self.arrivals.push_back(at);
    }

    fn stats(&self) -> Option<Stats> {
        let intervals: Vec<f64> = self
            .arrivals
            .iter()
            .zip(self.arrivals.iter().skip(1))
            .map(|(a, b)| b.duration_since(*a).as_secs_f64() * 1000.0)
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
            window.push(start + Duration::from_millis(10) * i);
        }
        let stats = window.stats().unwrap();
        assert_eq!(stats.intervals, 10);
        assert!((stats.rate - 100.0).abs() < 1e-6);
        assert!(stats.std_dev_ms < 1e-6);
        assert!(Window::new(5).stats().is_none());
    }
}

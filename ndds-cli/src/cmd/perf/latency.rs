//! Round-trip latencies: recorded in an HDR histogram (nanoseconds, three significant
//! digits), warm-up excluded, and reported as percentiles.

use std::time::{Duration, Instant};

use hdrhistogram::Histogram;
use serde_json::json;

use crate::outln;

/// Longest round trip the histogram holds exactly; longer ones are recorded as this.
const HIGHEST_NS: u64 = 60_000_000_000;

/// The round trips of one `ping` run.
#[derive(Debug)]
pub struct RoundTrips {
    histogram: Histogram<u64>,
    /// Replies still to ignore before recording.
    warmup_left: u64,
    /// Replies received, warm-up included.
    pub replies: u64,
    /// Pings that got no reply within the timeout.
    pub lost: u64,
}

impl RoundTrips {
    /// Ignores the first `warmup` replies.
    pub fn new(warmup: u64) -> Self {
        RoundTrips {
            histogram: Histogram::new_with_bounds(1, HIGHEST_NS, 3)
                .expect("static histogram bounds are valid"),
            warmup_left: warmup,
            replies: 0,
            lost: 0,
        }
    }

    /// Takes one round trip of `ns` nanoseconds.
    pub fn record(&mut self, ns: u64) {
        self.replies += 1;
        if self.warmup_left > 0 {
            self.warmup_left -= 1;
            return;
        }
        self.histogram.saturating_record(ns.clamp(1, HIGHEST_NS));
    }

    /// Round trips recorded (warm-up excluded).
    pub fn samples(&self) -> u64 {
        self.histogram.len()
    }

    /// The summary to print.
    pub fn summary(&self) -> Summary {
        let h = &self.histogram;
        let us = |ns: u64| ns as f64 / 1000.0;
        Summary {
            samples: h.len(),
            lost: self.lost,
            p50_us: us(h.value_at_quantile(0.5)),
            p90_us: us(h.value_at_quantile(0.9)),
            p99_us: us(h.value_at_quantile(0.99)),
            p999_us: us(h.value_at_quantile(0.999)),
            max_us: us(h.max()),
            min_us: us(h.min()),
            mean_us: h.mean() / 1000.0,
        }
    }
}

/// When a ping run ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Limit {
    /// After this many round trips past the warm-up.
    Count(u64),
    /// This long after the warm-up.
    Duration(Duration),
}

/// The round trips of a run, and whether it is over.
#[derive(Debug)]
pub struct Progress {
    pub trips: RoundTrips,
    limit: Limit,
    warmup: u64,
    /// End of a timed run, once the warm-up is over.
    until: Option<Instant>,
}

impl Progress {
    pub fn new(warmup: u64, limit: Limit) -> Self {
        Progress {
            trips: RoundTrips::new(warmup),
            limit,
            warmup,
            until: None,
        }
    }

    /// Takes a round trip of `ns` nanoseconds that ended at `now`.
    pub fn record(&mut self, ns: u64, now: Instant) {
        self.trips.record(ns);
        if let Limit::Duration(length) = self.limit
            && self.until.is_none()
            && self.trips.replies >= self.warmup
        {
            self.until = Some(now.checked_add(length).unwrap_or(now));
        }
    }

    /// Whether enough was measured.
    pub fn done(&self, now: Instant) -> bool {
        match self.limit {
            Limit::Count(count) => self.trips.samples() >= count,
            Limit::Duration(_) => self.until.is_some_and(|until| now >= until),
        }
    }

    /// Whether a run that sends at a fixed rate should send another ping, `sent` sent so far.
    pub fn wants_more(&self, sent: u64, now: Instant) -> bool {
        match self.limit {
            Limit::Count(count) => sent < self.warmup.saturating_add(count),
            Limit::Duration(_) => !self.done(now),
        }
    }
}

/// Percentiles of the round trips, in microseconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    pub samples: u64,
    pub lost: u64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
    pub min_us: f64,
    pub mean_us: f64,
}

/// What was measured, for the report's first line and its JSON fields.
#[derive(Clone, Debug)]
pub struct Setup {
    /// `ndds` or `raw-udp`.
    pub transport: &'static str,
    /// `best-effort` or `reliable`.
    pub reliability: &'static str,
    pub size: usize,
    pub warmup: u64,
    pub elapsed: Duration,
}

/// Prints the run's figures, as text or as one JSON object.
pub fn report(setup: &Setup, summary: &Summary, as_json: bool) -> anyhow::Result<()> {
    if as_json {
        let value = json!({
            "mode": "ping",
            "transport": setup.transport,
            "reliability": setup.reliability,
            "size": setup.size,
            "warmup": setup.warmup,
            "samples": summary.samples,
            "lost": summary.lost,
            "elapsed_s": setup.elapsed.as_secs_f64(),
            "p50_us": summary.p50_us,
            "p90_us": summary.p90_us,
            "p99_us": summary.p99_us,
            "p999_us": summary.p999_us,
            "max_us": summary.max_us,
            "min_us": summary.min_us,
            "mean_us": summary.mean_us,
        });
        outln!("{value}")?;
        return Ok(());
    }
    outln!(
        "ping {} {} {} B: {} round trips in {:.2} s ({} warm-up excluded), {} lost",
        setup.transport,
        setup.reliability,
        setup.size,
        summary.samples,
        setup.elapsed.as_secs_f64(),
        setup.warmup,
        summary.lost
    )?;
    outln!(
        "round trip us: p50 {:.1}  p90 {:.1}  p99 {:.1}  p99.9 {:.1}  max {:.1}  mean {:.1}",
        summary.p50_us,
        summary.p90_us,
        summary.p99_us,
        summary.p999_us,
        summary.max_us,
        summary.mean_us
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warm_up_is_excluded_and_percentiles_follow_the_data() {
        let mut trips = RoundTrips::new(10);
        for _ in 0..10 {
            trips.record(1_000_000_000);
        }
        for us in 1..=1000u64 {
            trips.record(us * 1000);
        }
        let s = trips.summary();
        assert_eq!((trips.replies, s.samples), (1010, 1000));
        assert!((s.p50_us - 500.0).abs() < 1.0, "{s:?}");
        assert!((s.p99_us - 990.0).abs() < 1.0, "{s:?}");
        assert!((s.max_us - 1000.0).abs() < 1.0, "{s:?}");
        assert!((s.mean_us - 500.5).abs() < 1.0, "{s:?}");
    }
}

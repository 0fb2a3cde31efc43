//! Habitat timing statistics: what each habitat publishes on `cs/<runtime>/<habitat>/stats`.
//!
//! Three distributions are kept per habitat, in microseconds:
//! - **latency**: how late each sample started against its absolute deadline;
//! - **period jitter**: how far each interval between two sample starts was from the period;
//! - **exec**: how long the sample (every `execute` and `state_update`) took.
//!
//! The habitat's thread records into histograms it owns (no lock, no allocation) and hands
//! them over once per statistics interval with a `try_lock`, so a reader never delays a sample.

use std::time::Duration;

use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};

/// p50 / p99 / max of one distribution, in microseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    /// Samples the figures are over.
    pub count: u64,
    /// Median.
    pub p50_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// Largest.
    pub max_us: f64,
}

/// A habitat's statistics (the sample type of its stats topic).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct HabitatStats {
    /// The runtime the habitat belongs to.
    pub runtime: String,
    /// The habitat.
    pub habitat: String,
    /// Whether sampling runs.
    pub running: bool,
    /// Nominal rate in Hz.
    pub rate_hz: f64,
    /// Samples executed since sampling began.
    pub samples: u64,
    /// Deadlines skipped because a sample ran past the next one, since sampling began.
    pub overruns: u64,
    /// Failed entry routines since the habitat was created.
    pub module_errors: u64,
    /// Active modules.
    pub active_modules: u32,
    /// The runtime's current configuration (empty if none was switched to).
    pub configuration: String,
    /// Seconds the distributions below cover (the last complete interval).
    pub interval_s: f64,
    /// Sample start latency against the absolute deadline.
    pub latency: Percentiles,
    /// Deviation of the interval between sample starts from the period.
    pub period_jitter: Percentiles,
    /// Execution time of a sample.
    pub exec: Percentiles,
}

/// Below this share of its nominal rate a habitat is behind.
pub const BEHIND_BELOW: f64 = 0.95;

/// What a habitat achieved between two snapshots of its statistics (two status reports).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pace {
    /// Samples per second over the span.
    pub achieved_hz: f64,
    /// The nominal rate at the later snapshot.
    pub nominal_hz: f64,
    /// Overruns counted during the span.
    pub new_overruns: u64,
}

impl Pace {
    /// The pace from `earlier` to `later`, `elapsed` apart. `None` when there is nothing to
    /// judge: no time passed, the habitat is not sampling, or it restarted in between (its
    /// counters went back).
    pub fn between(
        earlier: &HabitatStats,
        later: &HabitatStats,
        elapsed: Duration,
    ) -> Option<Self> {
        let seconds = elapsed.as_secs_f64();
        if seconds <= 0.0 || !later.running || later.samples < earlier.samples {
            return None;
        }
        Some(Self {
            achieved_hz: (later.samples - earlier.samples) as f64 / seconds,
            nominal_hz: later.rate_hz,
            new_overruns: later.overruns.saturating_sub(earlier.overruns),
        })
    }

    /// Achieved over nominal (1.0: on time).
    pub fn ratio(&self) -> f64 {
        if self.nominal_hz > 0.0 {
            self.achieved_hz / self.nominal_hz
        } else {
            1.0
        }
    }

    /// Falling behind: below [`BEHIND_BELOW`] of the nominal rate, or overrunning.
    pub fn is_behind(&self) -> bool {
        self.ratio() < BEHIND_BELOW || self.new_overruns > 0
    }
}

/// The three distributions, in nanoseconds.
pub(crate) struct Timings {
    pub(crate) latency: Histogram<u64>,
    pub(crate) jitter: Histogram<u64>,
    pub(crate) exec: Histogram<u64>,
}

impl Timings {
    pub(crate) fn new() -> Self {
        // 1 ns .. 100 s at 2 significant digits: about 30 KiB each, allocated once.
        let make = || {
            Histogram::new_with_bounds(1, 100_000_000_000, 2)
                .expect("constant histogram bounds are valid")
        };
        Self {
            latency: make(),
            jitter: make(),
            exec: make(),
        }
    }

    pub(crate) fn record(&mut self, latency_ns: Option<u64>, jitter_ns: Option<u64>, exec_ns: u64) {
        if let Some(latency) = latency_ns {
            self.latency.saturating_record(latency.max(1));
        }
        if let Some(jitter) = jitter_ns {
            self.jitter.saturating_record(jitter.max(1));
        }
        self.exec.saturating_record(exec_ns.max(1));
    }

    pub(crate) fn reset(&mut self) {
        self.latency.reset();
        self.jitter.reset();
        self.exec.reset();
    }

    /// Adds `other` into `self` (same bounds: never allocates).
    pub(crate) fn add(&mut self, other: &Timings) {
        let _ = self.latency.add(&other.latency);
        let _ = self.jitter.add(&other.jitter);
        let _ = self.exec.add(&other.exec);
    }
}

pub(crate) fn percentiles(h: &Histogram<u64>) -> Percentiles {
    if h.is_empty() {
        return Percentiles::default();
    }
    let us = |ns: u64| ns as f64 / 1000.0;
    Percentiles {
        count: h.len(),
        p50_us: us(h.value_at_quantile(0.5)),
        p99_us: us(h.value_at_quantile(0.99)),
        max_us: us(h.max()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(samples: u64, overruns: u64) -> HabitatStats {
        HabitatStats {
            running: true,
            rate_hz: 100_000.0,
            samples,
            overruns,
            ..HabitatStats::default()
        }
    }

    #[test]
    fn a_habitat_at_forty_percent_is_behind() {
        let pace = Pace::between(&stats(0, 0), &stats(40_213, 0), Duration::from_secs(1)).unwrap();
        assert!((pace.achieved_hz - 40_213.0).abs() < 1e-6);
        assert!((pace.ratio() - 0.40213).abs() < 1e-9);
        assert!(pace.is_behind());
    }

    #[test]
    fn on_time_within_five_percent_without_overruns() {
        let at = |samples| stats(samples, 7);
        let pace = Pace::between(&at(100_000), &at(296_000), Duration::from_secs(2)).unwrap();
        assert_eq!(pace.achieved_hz, 98_000.0);
        assert_eq!(pace.new_overruns, 0);
        assert!(!pace.is_behind(), "old overruns do not count: {pace:?}");
    }

    #[test]
    fn rising_overruns_are_behind_even_at_full_rate() {
        let pace = Pace::between(&stats(0, 3), &stats(100_000, 4), Duration::from_secs(1)).unwrap();
        assert_eq!(pace.new_overruns, 1);
        assert!(pace.is_behind());
    }

    #[test]
    fn nothing_to_judge_without_time_sampling_or_after_a_restart() {
        let one = Duration::from_secs(1);
        assert!(Pace::between(&stats(0, 0), &stats(10, 0), Duration::ZERO).is_none());
        assert!(Pace::between(&stats(500, 0), &stats(10, 0), one).is_none());
        let stopped = HabitatStats {
            running: false,
            ..stats(10, 0)
        };
        assert!(Pace::between(&stats(0, 0), &stopped, one).is_none());
    }
}

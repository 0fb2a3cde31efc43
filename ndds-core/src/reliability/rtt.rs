//! A round-trip estimate in the manner of TCP's retransmission timer (smoothed mean plus four
//! mean deviations), used by a reader to decide how soon an unanswered request is repeated
//! (for whole samples here, and by drivers for the pieces of large samples).

use std::time::Duration;

/// Smoothed round trip and its mean deviation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RttEstimate {
    smoothed: Option<Duration>,
    deviation: Duration,
}

impl RttEstimate {
    /// Takes one measured round trip into account.
    pub fn sample(&mut self, rtt: Duration) {
        let Some(smoothed) = self.smoothed else {
            self.smoothed = Some(rtt);
            self.deviation = rtt / 2;
            return;
        };
        let error = smoothed.abs_diff(rtt);
        self.deviation = self.deviation.saturating_mul(3).saturating_add(error) / 4;
        self.smoothed = Some(smoothed.saturating_mul(7).saturating_add(rtt) / 8);
    }

    /// How long to wait for an answer before asking again: `smoothed + 4 × deviation` within
    /// `min..=max`, or `max` before the first sample.
    pub fn timeout(&self, min: Duration, max: Duration) -> Duration {
        let Some(smoothed) = self.smoothed else {
            return max;
        };
        let rto = smoothed.saturating_add(self.deviation.saturating_mul(4));
        rto.max(min).min(max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn the_timeout_follows_the_round_trip_within_bounds() {
        let mut rtt = RttEstimate::default();
        assert_eq!(rtt.timeout(MS, 20 * MS), 20 * MS);
        rtt.sample(2 * MS);
        assert_eq!(rtt.timeout(MS, 20 * MS), 6 * MS);
        for _ in 0..50 {
            rtt.sample(2 * MS);
        }
        assert!(rtt.timeout(MS, 20 * MS) < 3 * MS);
        rtt.sample(Duration::from_micros(10));
        assert!(rtt.timeout(MS, 20 * MS) >= MS);
        rtt.sample(Duration::MAX);
        assert_eq!(rtt.timeout(MS, 20 * MS), 20 * MS);
    }
}

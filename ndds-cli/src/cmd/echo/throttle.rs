//! `ndds echo --rate HZ`: at most one sample per period, the newest of each window.
//!
//! Time is cut into windows of one period, the first starting when a sample arrives after a
//! quiet spell; when a window ends, the newest sample it received is due, the others are
//! dropped. No clock inside: the caller passes `now`. Call order, for each wake-up:
//!
//! 1. [`Throttle::poll_due`]`(now)`: the sample of a window that has ended, if any;
//! 2. [`Throttle::handle_sample`]`(now, sample)` for a sample that arrived;
//! 3. sleep until [`Throttle::poll_timeout`] (or the next sample; forever if `None`).

use std::time::{Duration, Instant};

/// The newest sample of the current window, and when the window ends.
#[derive(Debug)]
pub struct Throttle<T> {
    period: Duration,
    window_end: Option<Instant>,
    newest: Option<T>,
}

impl<T> Throttle<T> {
    /// At most one sample every `period`.
    pub fn new(period: Duration) -> Self {
        Throttle {
            period,
            window_end: None,
            newest: None,
        }
    }

    /// A sample arrived at `now` (after [`Throttle::poll_due`] for the same `now`).
    pub fn handle_sample(&mut self, now: Instant, sample: T) {
        let window_running = self.window_end.is_some_and(|end| now < end);
        if !window_running {
            // The first window, or the first sample after empty windows: a new one starts.
            self.window_end = now.checked_add(self.period);
        }
        self.newest = Some(sample);
    }

    /// The newest sample of a window that ended by `now`; the next window follows it at once.
    pub fn poll_due(&mut self, now: Instant) -> Option<T> {
        let end = self.window_end?;
        if now < end || self.newest.is_none() {
            return None;
        }
        self.window_end = end.checked_add(self.period);
        self.newest.take()
    }

    /// When a sample is next due (`None`: nothing is waiting).
    pub fn poll_timeout(&self) -> Option<Instant> {
        self.newest.as_ref().and(self.window_end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD: Duration = Duration::from_millis(100);

    fn ms(start: Instant, ms: u64) -> Instant {
        start + Duration::from_millis(ms)
    }

    #[test]
    fn the_newest_sample_of_each_window_is_due_at_its_end() {
        let start = Instant::now();
        let mut throttle = Throttle::new(PERIOD);
        assert_eq!(throttle.poll_timeout(), None);
        for (at, sample) in [(0, 'a'), (30, 'b'), (90, 'c')] {
            assert_eq!(throttle.poll_due(ms(start, at)), None);
            throttle.handle_sample(ms(start, at), sample);
        }
        assert_eq!(throttle.poll_timeout(), Some(ms(start, 100)));
        assert_eq!(throttle.poll_due(ms(start, 99)), None);
        assert_eq!(throttle.poll_due(ms(start, 100)), Some('c'));
        assert_eq!(throttle.poll_due(ms(start, 100)), None);
        // The next window follows at once: 100..200.
        throttle.handle_sample(ms(start, 150), 'd');
        throttle.handle_sample(ms(start, 160), 'e');
        assert_eq!(throttle.poll_timeout(), Some(ms(start, 200)));
        assert_eq!(throttle.poll_due(ms(start, 205)), Some('e'));
    }

    #[test]
    fn after_a_quiet_spell_a_window_starts_with_the_next_sample() {
        let start = Instant::now();
        let mut throttle = Throttle::new(PERIOD);
        throttle.handle_sample(start, 1);
        assert_eq!(throttle.poll_due(ms(start, 100)), Some(1));
        // Nothing in 100..200 and 200..300; a sample at 340 opens 340..440.
        assert_eq!(throttle.poll_due(ms(start, 340)), None);
        throttle.handle_sample(ms(start, 340), 2);
        assert_eq!(throttle.poll_timeout(), Some(ms(start, 440)));
        assert_eq!(throttle.poll_due(ms(start, 439)), None);
        assert_eq!(throttle.poll_due(ms(start, 440)), Some(2));
    }

    #[test]
    fn a_sample_arriving_after_the_window_ended_belongs_to_the_next() {
        let start = Instant::now();
        let mut throttle = Throttle::new(PERIOD);
        throttle.handle_sample(start, 'a');
        // Woken late, at 120, with a new sample: 'a' is due first, 'b' waits for 200.
        assert_eq!(throttle.poll_due(ms(start, 120)), Some('a'));
        throttle.handle_sample(ms(start, 120), 'b');
        assert_eq!(throttle.poll_timeout(), Some(ms(start, 200)));
        assert_eq!(throttle.poll_due(ms(start, 200)), Some('b'));
    }
}

//! A budget for the log lines that other hosts' traffic can cause in numbers.
//!
//! A node may announce thousands of endpoints at once, and each one of another type on a topic a
//! local endpoint uses is an `Incompatible` pair (each one refused by the permissions document, a
//! `Refused` pair). Every pair still reaches the client that owns the local endpoint; the log
//! says the first few of each window and then one line with how many more there were, so a flood
//! of forged announcements cannot fill the disk with log lines (a line per pair wrote 140 940
//! warnings in one run of the flood test, `netns_flood`).

use std::time::{Duration, Instant};

/// Lines of one kind logged per window before the rest are held back.
pub const LINES_PER_WINDOW: u32 = 10;

/// The window of [`LINES_PER_WINDOW`].
pub const WINDOW: Duration = Duration::from_secs(10);

/// What to do with one line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Log it; `held_back` lines of this kind were not logged in the window that ended before
    /// it (0: none, or already reported).
    Log {
        /// Lines held back before this one.
        held_back: u64,
    },
    /// Do not log it: counted, and reported when the window ends.
    Hold,
}

/// One kind of line's budget: [`LINES_PER_WINDOW`] per [`WINDOW`] unless set otherwise. Pure
/// logic: the caller passes the time.
#[derive(Clone, Debug)]
pub struct LogBudget {
    per_window: u32,
    window: Duration,
    opened: Option<Instant>,
    used: u32,
    held_back: u64,
}

impl Default for LogBudget {
    fn default() -> Self {
        LogBudget::new(LINES_PER_WINDOW, WINDOW)
    }
}

impl LogBudget {
    /// `per_window` lines per `window`.
    pub const fn new(per_window: u32, window: Duration) -> Self {
        LogBudget {
            per_window,
            window,
            opened: None,
            used: 0,
            held_back: 0,
        }
    }

    /// The window.
    pub fn window(&self) -> Duration {
        self.window
    }

    /// Whether a line at `now` may be logged. A line after the window ended opens a new one and
    /// carries the count held back in the old one.
    pub fn ask(&mut self, now: Instant) -> Verdict {
        let open = self
            .opened
            .is_some_and(|opened| now.saturating_duration_since(opened) < self.window);
        if !open {
            self.opened = Some(now);
            self.used = 1;
            return Verdict::Log {
                held_back: std::mem::take(&mut self.held_back),
            };
        }
        if self.used < self.per_window {
            self.used += 1;
            return Verdict::Log { held_back: 0 };
        }
        self.held_back += 1;
        Verdict::Hold
    }

    /// The lines held back in a window that has ended by `now`, once (for a timer, so the count
    /// is reported even when no line of the kind follows).
    pub fn ended(&mut self, now: Instant) -> Option<u64> {
        let over = self
            .opened
            .is_some_and(|opened| now.saturating_duration_since(opened) >= self.window);
        (over && self.held_back > 0).then(|| std::mem::take(&mut self.held_back))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn the_first_lines_of_a_window_are_logged_and_the_rest_held_back_and_counted() {
        let t0 = Instant::now();
        let mut budget = LogBudget::new(3, 100 * MS);
        let verdicts: Vec<_> = (0..5).map(|i| budget.ask(t0 + i * MS)).collect();
        assert_eq!(
            verdicts,
            [
                Verdict::Log { held_back: 0 },
                Verdict::Log { held_back: 0 },
                Verdict::Log { held_back: 0 },
                Verdict::Hold,
                Verdict::Hold,
            ]
        );
        // Still inside the window: nothing to report yet.
        assert_eq!(budget.ended(t0 + 99 * MS), None);
        assert_eq!(budget.ask(t0 + 99 * MS), Verdict::Hold);
        // The next window's first line carries the three held back.
        assert_eq!(budget.ask(t0 + 100 * MS), Verdict::Log { held_back: 3 });
        assert_eq!(budget.ask(t0 + 101 * MS), Verdict::Log { held_back: 0 });
    }

    #[test]
    fn a_timer_reports_what_was_held_back_once_when_no_line_follows() {
        let t0 = Instant::now();
        let mut budget = LogBudget::new(1, 100 * MS);
        assert_eq!(budget.ended(t0), None, "nothing asked yet");
        assert_eq!(budget.ask(t0), Verdict::Log { held_back: 0 });
        assert_eq!(budget.ask(t0 + MS), Verdict::Hold);
        assert_eq!(budget.ask(t0 + 2 * MS), Verdict::Hold);
        assert_eq!(budget.ended(t0 + 50 * MS), None);
        assert_eq!(budget.ended(t0 + 100 * MS), Some(2));
        assert_eq!(budget.ended(t0 + 200 * MS), None, "reported once");
        // Reported already: the next line carries nothing.
        assert_eq!(budget.ask(t0 + 300 * MS), Verdict::Log { held_back: 0 });
    }

    #[test]
    fn a_window_with_nothing_held_back_reports_nothing() {
        let t0 = Instant::now();
        let mut budget = LogBudget::default();
        assert_eq!(budget.window(), WINDOW);
        for i in 0..LINES_PER_WINDOW {
            assert_eq!(budget.ask(t0 + i * MS), Verdict::Log { held_back: 0 });
        }
        assert_eq!(budget.ended(t0 + WINDOW), None);
        assert_eq!(budget.ask(t0 + WINDOW), Verdict::Log { held_back: 0 });
    }

    #[test]
    fn a_clock_that_goes_back_keeps_the_window_open_instead_of_panicking() {
        let t0 = Instant::now() + Duration::from_secs(1);
        let mut budget = LogBudget::new(1, 100 * MS);
        assert_eq!(budget.ask(t0), Verdict::Log { held_back: 0 });
        assert_eq!(budget.ask(t0 - 10 * MS), Verdict::Hold);
        assert_eq!(budget.ended(t0 - 10 * MS), None);
    }
}

//! The replay window of one sender's session: which counters were accepted lately.

/// Counters behind the highest accepted one that are still told apart: older ones are refused
/// as replays. 1024 datagrams of reordering is far more than a network shows.
pub const REPLAY_WINDOW: u64 = 1024;

/// One word more than the window: a window that does not start on a word boundary touches
/// one word more than it fills, and its oldest and newest words must not share a slot.
const WORDS: usize = (REPLAY_WINDOW / 64) as usize + 1;

/// A bit per counter in `highest - REPLAY_WINDOW + 1 ..= highest`, kept in a ring of words
/// indexed by the counter itself.
#[derive(Clone, Debug)]
pub(crate) struct ReplayWindow {
    highest: Option<u64>,
    bits: [u64; WORDS],
}

impl ReplayWindow {
    /// A window that has accepted nothing.
    pub(crate) fn new() -> Self {
        ReplayWindow {
            highest: None,
            bits: [0; WORDS],
        }
    }

    /// True if `counter` would be accepted (new, and not too old). Asked before the tag is
    /// checked, so replays cost no cryptography; [`ReplayWindow::accept`] after it verified.
    pub(crate) fn fresh(&self, counter: u64) -> bool {
        match self.highest {
            None => true,
            Some(highest) if counter > highest => true,
            Some(highest) => {
                highest - counter < REPLAY_WINDOW && self.bits[word(counter)] & bit(counter) == 0
            }
        }
    }

    /// The highest counter accepted.
    pub(crate) fn highest(&self) -> Option<u64> {
        self.highest
    }

    /// Marks `counter` accepted (it was [`ReplayWindow::fresh`]).
    pub(crate) fn accept(&mut self, counter: u64) {
        match self.highest {
            Some(highest) if counter <= highest => {}
            Some(highest) => {
                // Clear the words the window moves over (all of them after a long jump).
                let words = ((counter / 64) - (highest / 64)).min(WORDS as u64);
                for step in 1..=words {
                    self.bits[word(highest.wrapping_add(step * 64))] = 0;
                }
                self.highest = Some(counter);
            }
            None => self.highest = Some(counter),
        }
        self.bits[word(counter)] |= bit(counter);
    }
}

fn word(counter: u64) -> usize {
    ((counter / 64) % WORDS as u64) as usize
}

fn bit(counter: u64) -> u64 {
    1 << (counter % 64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    #[test]
    fn each_counter_is_accepted_once_and_old_ones_never() {
        let mut window = ReplayWindow::new();
        for counter in [5, 3, 4, 2000, 1500, 977, 976] {
            if window.fresh(counter) {
                window.accept(counter);
            }
        }
        assert!(!window.fresh(5), "older than the window");
        assert!(!window.fresh(2000), "accepted already");
        assert!(!window.fresh(1500), "accepted already");
        assert!(window.fresh(1000), "inside the window, not seen");
        assert!(!window.fresh(976), "2000 - 976 = 1024: just outside");
        assert!(window.fresh(1999));
    }

    #[test]
    fn it_agrees_with_a_set_of_every_counter_seen() {
        // Random walks with reordering and long jumps, against the plain definition.
        let mut rng = fastrand::Rng::with_seed(11);
        let mut window = ReplayWindow::new();
        let mut seen = BTreeSet::new();
        let mut top = 0u64;
        for _ in 0..50_000 {
            let counter = match rng.u8(0..20) {
                0 => top + rng.u64(0..5000),
                1..=9 => top + rng.u64(0..3),
                _ => top.saturating_sub(rng.u64(0..1100)),
            };
            let highest = seen.last().copied();
            let expected = !seen.contains(&counter)
                && highest.is_none_or(|h: u64| counter > h || h - counter < REPLAY_WINDOW);
            assert_eq!(window.fresh(counter), expected, "counter {counter}");
            if expected {
                window.accept(counter);
                seen.insert(counter);
                top = top.max(counter);
            }
        }
    }
}

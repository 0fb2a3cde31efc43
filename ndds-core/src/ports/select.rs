//! [`PrioritySelect`]: messages waiting on several ports, taken highest port priority first and
//! in arrival order within a port.
//!
//! Deterministic: among ports of equal priority, the one added first wins. A port without a
//! priority (`None`) ranks below every port with one, whatever its number, as the paper gives
//! unprioritised ports "a default priority lower than any user-specifiable priorities". Each
//! port holds at most its capacity; a push beyond it is refused and the message handed back.

use std::fmt;

/// Why a port cannot be added.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SelectError {
    /// A port of that name is there already.
    #[error("port `{0}` is already in the select")]
    Duplicate(String),
    /// A port with room for nothing.
    #[error("port `{0}` needs a capacity of at least 1")]
    ZeroCapacity(String),
}

/// A push refused because the port's queue is full (or the port is unknown); the message comes
/// back.
#[derive(Clone, PartialEq, Eq)]
pub struct Full<T> {
    /// The port.
    pub port: String,
    /// The message.
    pub message: T,
    /// The port is not in the select at all.
    pub unknown: bool,
}

impl<T> fmt::Debug for Full<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Full")
            .field("port", &self.port)
            .field("unknown", &self.unknown)
            .finish_non_exhaustive()
    }
}

impl<T> fmt::Display for Full<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.unknown {
            write!(f, "port `{}` is not in the select", self.port)
        } else {
            write!(f, "port `{}` is full", self.port)
        }
    }
}

impl<T> std::error::Error for Full<T> {}

struct Port<T> {
    name: String,
    priority: Option<i32>,
    capacity: usize,
    queue: std::collections::VecDeque<T>,
}

/// Messages waiting on several ports (see the module docs).
pub struct PrioritySelect<T> {
    /// Kept sorted: highest priority first, then in the order added.
    ports: Vec<Port<T>>,
    waiting: usize,
}

impl<T> Default for PrioritySelect<T> {
    fn default() -> Self {
        Self {
            ports: Vec::new(),
            waiting: 0,
        }
    }
}

impl<T> PrioritySelect<T> {
    /// No ports.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds port `name` with `priority` (higher is served first; a number, or `None` for a
    /// port without one, served after every port with one) and room for `capacity` messages.
    pub fn add_port(
        &mut self,
        name: &str,
        priority: impl Into<Option<i32>>,
        capacity: usize,
    ) -> Result<(), SelectError> {
        let priority = priority.into();
        if self.ports.iter().any(|p| p.name == name) {
            return Err(SelectError::Duplicate(name.to_owned()));
        }
        if capacity == 0 {
            return Err(SelectError::ZeroCapacity(name.to_owned()));
        }
        let at = self
            .ports
            .iter()
            .position(|p| p.priority < priority)
            .unwrap_or(self.ports.len());
        self.ports.insert(
            at,
            Port {
                name: name.to_owned(),
                priority,
                capacity,
                queue: std::collections::VecDeque::new(),
            },
        );
        Ok(())
    }

    /// Removes a port and the messages waiting on it (returned in arrival order).
    pub fn remove_port(&mut self, name: &str) -> Vec<T> {
        match self.ports.iter().position(|p| p.name == name) {
            Some(at) => {
                let port = self.ports.remove(at);
                self.waiting -= port.queue.len();
                port.queue.into_iter().collect()
            }
            None => Vec::new(),
        }
    }

    /// Queues `message` on port `port`.
    pub fn push(&mut self, port: &str, message: T) -> Result<(), Full<T>> {
        let Some(p) = self.ports.iter_mut().find(|p| p.name == port) else {
            return Err(Full {
                port: port.to_owned(),
                message,
                unknown: true,
            });
        };
        if p.queue.len() >= p.capacity {
            return Err(Full {
                port: port.to_owned(),
                message,
                unknown: false,
            });
        }
        p.queue.push_back(message);
        self.waiting += 1;
        Ok(())
    }

    /// The oldest message of the highest-priority port that has one.
    pub fn pop(&mut self) -> Option<(&str, T)> {
        let port = self.ports.iter_mut().find(|p| !p.queue.is_empty())?;
        let message = port.queue.pop_front()?;
        self.waiting -= 1;
        Some((&port.name, message))
    }

    /// The same, among `ports` only (a select over some of the ports).
    pub fn pop_from(&mut self, ports: &[&str]) -> Option<(&str, T)> {
        let port = self
            .ports
            .iter_mut()
            .find(|p| !p.queue.is_empty() && ports.contains(&p.name.as_str()))?;
        let message = port.queue.pop_front()?;
        self.waiting -= 1;
        Some((&port.name, message))
    }

    /// Messages waiting on all ports.
    pub fn len(&self) -> usize {
        self.waiting
    }

    /// Nothing waiting.
    pub fn is_empty(&self) -> bool {
        self.waiting == 0
    }

    /// Messages waiting on `port` (0 for an unknown port).
    pub fn waiting(&self, port: &str) -> usize {
        self.ports
            .iter()
            .find(|p| p.name == port)
            .map_or(0, |p| p.queue.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn highest_priority_first_fifo_within_a_port_ties_by_order_added() {
        let mut s = PrioritySelect::new();
        s.add_port("status", 0, 8).unwrap();
        s.add_port("command", 5, 8).unwrap();
        s.add_port("alarm", 9, 8).unwrap();
        s.add_port("log", 0, 8).unwrap();
        for (port, m) in [
            ("log", 1),
            ("status", 2),
            ("command", 3),
            ("status", 4),
            ("alarm", 5),
            ("command", 6),
        ] {
            s.push(port, m).unwrap();
        }
        let order: Vec<(String, i32)> =
            std::iter::from_fn(|| s.pop().map(|(p, m)| (p.to_owned(), m))).collect();
        let expected = [
            ("alarm", 5),
            ("command", 3),
            ("command", 6),
            ("status", 2),
            ("status", 4),
            ("log", 1),
        ];
        let expected: Vec<(String, i32)> = expected
            .iter()
            .map(|(p, m)| ((*p).to_owned(), *m))
            .collect();
        assert_eq!(order, expected);
        assert!(s.is_empty());
    }

    #[test]
    fn a_port_without_a_priority_comes_after_every_port_with_one() {
        let mut s = PrioritySelect::new();
        s.add_port("plain", None, 8).unwrap();
        s.add_port("low", -1000, 8).unwrap();
        s.add_port("also plain", None, 8).unwrap();
        for port in ["also plain", "plain", "low"] {
            s.push(port, port).unwrap();
        }
        let order: Vec<&str> = std::iter::from_fn(|| s.pop().map(|(_, m)| m)).collect();
        assert_eq!(order, ["low", "plain", "also plain"]);
    }

    #[test]
    fn full_and_unknown_ports_hand_the_message_back() {
        let mut s = PrioritySelect::new();
        s.add_port("p", 0, 1).unwrap();
        s.push("p", 1).unwrap();
        let full = s.push("p", 2).unwrap_err();
        assert_eq!((full.message, full.unknown), (2, false));
        let unknown = s.push("q", 3).unwrap_err();
        assert_eq!((unknown.message, unknown.unknown), (3, true));
        assert_eq!(
            s.add_port("p", 1, 1),
            Err(SelectError::Duplicate("p".into()))
        );
        assert_eq!(
            s.add_port("z", 1, 0),
            Err(SelectError::ZeroCapacity("z".into()))
        );
        assert_eq!(s.remove_port("p"), [1]);
        assert!(s.is_empty());
        assert_eq!(s.pop_from(&["p"]), None);
    }

    proptest! {
        /// Against a model: every pop is the oldest message of the highest-priority non-empty
        /// port (first added among equals), over a random mix of pushes and pops.
        #[test]
        fn pops_follow_priority_then_arrival(
            priorities in prop::collection::vec(prop::option::of(-3i32..4), 1..6),
            ops in prop::collection::vec((any::<bool>(), 0usize..6), 0..200),
        ) {
            let mut s = PrioritySelect::new();
            let names: Vec<String> = (0..priorities.len()).map(|i| format!("p{i}")).collect();
            for (name, priority) in names.iter().zip(&priorities) {
                s.add_port(name, *priority, 16).unwrap();
            }
            let mut model: Vec<std::collections::VecDeque<u32>> = vec![Default::default(); names.len()];
            let mut next = 0u32;
            for (push, port) in ops {
                let port = port % names.len();
                if push {
                    let accepted = s.push(&names[port], next).is_ok();
                    prop_assert_eq!(accepted, model[port].len() < 16);
                    if accepted {
                        model[port].push_back(next);
                    }
                    next += 1;
                } else {
                    // The model's choice: max priority, then lowest index.
                    let choice = (0..names.len())
                        .filter(|&i| !model[i].is_empty())
                        .max_by_key(|&i| (priorities[i], std::cmp::Reverse(i)));
                    let got = s.pop().map(|(p, m)| (p.to_owned(), m));
                    let want = choice.map(|i| (names[i].clone(), model[i].pop_front().unwrap()));
                    prop_assert_eq!(got, want);
                }
                prop_assert_eq!(s.len(), model.iter().map(|q| q.len()).sum::<usize>());
            }
        }
    }
}

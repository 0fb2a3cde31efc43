//! The arbiter of one consumer: decides, for each arriving sample, whether it is delivered,
//! held for the end of the minimum-separation window, or refused, and raises deadline and
//! producer notifications.
//!
//! # Call order
//! Like the discovery engine: feed [`Arbiter::handle_sample`], [`Arbiter::handle_writer_lost`]
//! and, when [`Arbiter::poll_timeout`] is reached, [`Arbiter::handle_timeout`]; then drain
//! [`Arbiter::poll_output`]. The arbiter never reads a clock.
//!
//! # Rules
//! - **Arbitration**: a sample from the producer in charge is accepted; a sample from another
//!   producer is accepted when its strength is at least the strength of the producer in
//!   charge, or when the persistence of the last accepted sample has run out (counted from its
//!   arrival here), or when the producer in charge was lost. The accepting producer is then in
//!   charge.
//! - **Old data**: a sample of the producer in charge whose sequence number is not above the
//!   last accepted one's is refused with [`Notification::OldData`] (a duplicate, or one that
//!   was overtaken). Sequence numbers, not clocks: a producer whose clock steps back is still
//!   accepted, and a sample stamped far in the future does not make later ones "old".
//! - **Minimum separation**: at most one delivery per window; a sample accepted inside the
//!   window is held, a newer one replaces it, and the held one is delivered when the window
//!   ends, so a slow consumer always gets the newest data.
//! - **Every producer** ([`Rules::every_producer`], for recorders and monitors): no
//!   arbitration and no minimum separation; every sample is delivered as it arrives, marked
//!   fresh, and nobody is in charge. Deadlines still apply.
//! - **Deadline**: when no sample was accepted for a deadline, [`Notification::NoNewData`]
//!   (or [`Notification::NeverReceived`] before the first sample), repeated each deadline.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use super::status::{Notification, SampleStatus};
use crate::wire::Guid;

/// The rules of one consumer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Rules {
    /// At most one delivery per this window (zero: no limit).
    pub min_separation: Duration,
    /// Notify when no sample was accepted for this long (`None`: never).
    pub deadline: Option<Duration>,
    /// No arbitration: every producer's samples are delivered as they arrive, whatever its
    /// strength, and minimum separation does not apply (for tools that must see everything on
    /// a topic, such as a recorder; see the module docs).
    pub every_producer: bool,
}

/// What arbitration needs to know of an arriving sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Incoming {
    /// Its producer.
    pub writer: Guid,
    /// Its sequence number (what old data is judged by).
    pub seq: u64,
    /// The producer's strength.
    pub strength: i32,
    /// The producer's persistence.
    pub persistence: Duration,
    /// Source timestamp, nanoseconds since the Unix epoch on the producer's clock (carried to
    /// the application; arbitration never compares clocks).
    pub source_ns: u64,
}

/// An output of the arbiter.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Output<S> {
    /// Deliver this sample now.
    Deliver {
        /// The sample.
        sample: S,
        /// Its status.
        status: SampleStatus,
    },
    /// Tell the consumer this.
    Notify(Notification),
}

/// Counters of one arbiter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ArbiterStats {
    /// Samples accepted (delivered, or held and later delivered or superseded).
    pub accepted: u64,
    /// Samples delivered.
    pub delivered: u64,
    /// Samples refused because a stronger producer is in charge.
    pub weaker: u64,
    /// Samples refused as old data.
    pub old_data: u64,
    /// Held samples replaced by a newer one within the minimum-separation window.
    pub superseded: u64,
    /// Deadline notifications raised.
    pub deadline_misses: u64,
}

#[derive(Clone, Copy, Debug)]
struct InCharge {
    writer: Guid,
    strength: i32,
    persistence: Duration,
    accepted_at: Instant,
    seq: u64,
    lost: bool,
}

/// The arbiter of one consumer; `S` is the sample it hands back (opaque to it).
#[derive(Debug)]
pub struct Arbiter<S> {
    rules: Rules,
    created: Instant,
    in_charge: Option<InCharge>,
    last_delivery: Option<Instant>,
    held: Option<(S, SampleStatus)>,
    next_deadline: Option<Instant>,
    output: VecDeque<Output<S>>,
    stats: ArbiterStats,
}

impl<S> Arbiter<S> {
    /// An arbiter for a consumer created at `now`.
    pub fn new(rules: Rules, now: Instant) -> Self {
        Arbiter {
            rules,
            created: now,
            in_charge: None,
            last_delivery: None,
            held: None,
            next_deadline: rules.deadline.and_then(|d| now.checked_add(d)),
            output: VecDeque::new(),
            stats: ArbiterStats::default(),
        }
    }

    /// The rules in force.
    pub fn rules(&self) -> Rules {
        self.rules
    }

    /// Counters.
    pub fn stats(&self) -> ArbiterStats {
        self.stats
    }

    /// The producer in charge, if any.
    pub fn in_charge(&self) -> Option<Guid> {
        self.in_charge.map(|c| c.writer)
    }

    /// Offers an arriving sample.
    pub fn handle_sample(&mut self, now: Instant, meta: Incoming, sample: S) {
        if self.rules.every_producer {
            self.stats.accepted += 1;
            self.next_deadline = self.rules.deadline.and_then(|d| now.checked_add(d));
            self.deliver(now, sample, SampleStatus::Fresh);
            return;
        }
        let status = match self.in_charge {
            Some(current) if current.writer == meta.writer => {
                if meta.seq <= current.seq {
                    self.stats.old_data += 1;
                    self.output.push_back(Output::Notify(Notification::OldData {
                        writer: meta.writer,
                        seq: meta.seq,
                    }));
                    return;
                }
                SampleStatus::Fresh
            }
            Some(current) => {
                let expired = current.lost
                    || current
                        .accepted_at
                        .checked_add(current.persistence)
                        .is_some_and(|end| now >= end);
                if meta.strength < current.strength && !expired {
                    self.stats.weaker += 1;
                    return;
                }
                SampleStatus::TookOver {
                    previous: current.writer,
                }
            }
            None => SampleStatus::Fresh,
        };
        self.accept(now, meta, sample, status);
    }

    fn accept(&mut self, now: Instant, meta: Incoming, sample: S, status: SampleStatus) {
        self.stats.accepted += 1;
        // A lost producer's last samples may still arrive: they are delivered, but do not
        // put it back in charge (any producer may take over from a lost one at once).
        let lost = self
            .in_charge
            .is_some_and(|c| c.writer == meta.writer && c.lost);
        self.in_charge = Some(InCharge {
            writer: meta.writer,
            strength: meta.strength,
            persistence: meta.persistence,
            accepted_at: now,
            seq: meta.seq,
            lost,
        });
        self.next_deadline = self.rules.deadline.and_then(|d| now.checked_add(d));
        match self.window_end() {
            Some(end) if now < end => {
                let status = self.supersede_held(status);
                self.held = Some((sample, status));
            }
            _ => {
                // The window ended but its timer has not run yet: the held sample is older
                // than this one, which replaces it (never delivered after it).
                let status = self.supersede_held(status);
                self.deliver(now, sample, status);
            }
        }
    }

    /// Drops the held sample, if any, for a newer one with `status`; returns the status the
    /// newer one gets (a takeover stays visible even if a newer sample replaces the held one).
    fn supersede_held(&mut self, status: SampleStatus) -> SampleStatus {
        match self.held.take() {
            Some((_, held @ SampleStatus::TookOver { .. })) => {
                self.stats.superseded += 1;
                held
            }
            Some(_) => {
                self.stats.superseded += 1;
                status
            }
            None => status,
        }
    }

    fn deliver(&mut self, now: Instant, sample: S, status: SampleStatus) {
        self.stats.delivered += 1;
        self.last_delivery = Some(now);
        self.output.push_back(Output::Deliver { sample, status });
    }

    /// End of the current minimum-separation window, if one is open.
    fn window_end(&self) -> Option<Instant> {
        if self.rules.min_separation.is_zero() {
            return None;
        }
        self.last_delivery
            .and_then(|at| at.checked_add(self.rules.min_separation))
    }

    /// A matched producer went away (discovery says so).
    pub fn handle_writer_lost(&mut self, writer: Guid) {
        let mut was_current = false;
        if let Some(current) = self.in_charge.as_mut()
            && current.writer == writer
        {
            current.lost = true;
            was_current = true;
        }
        self.output
            .push_back(Output::Notify(Notification::ProducerLost {
                writer,
                was_current,
            }));
    }

    /// A producer is matched (again): if it was in charge when it was lost, it is in charge
    /// with its strength and persistence again.
    pub fn handle_writer_back(&mut self, writer: Guid) {
        if let Some(current) = self.in_charge.as_mut()
            && current.writer == writer
        {
            current.lost = false;
        }
    }

    /// Runs what is due at `now`: the end of a separation window, a missed deadline.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.window_end().is_some_and(|end| now >= end)
            && let Some((sample, status)) = self.held.take()
        {
            self.deliver(now, sample, status);
        }
        let (Some(due), Some(deadline)) = (self.next_deadline, self.rules.deadline) else {
            return;
        };
        if now < due {
            return;
        }
        self.stats.deadline_misses += 1;
        let notification = match self.in_charge {
            Some(current) => Notification::NoNewData {
                silent_for: now.saturating_duration_since(current.accepted_at),
            },
            None => Notification::NeverReceived {
                waited: now.saturating_duration_since(self.created),
            },
        };
        self.output.push_back(Output::Notify(notification));
        // The next miss is one deadline later; after a long stall, from now rather than a
        // burst of catch-up notifications.
        let next = due.checked_add(deadline);
        self.next_deadline = match next {
            Some(next) if next > now => Some(next),
            _ => now.checked_add(deadline),
        };
    }

    /// When [`Arbiter::handle_timeout`] must next run.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let window = self.held.as_ref().and_then(|_| self.window_end());
        match (window, self.next_deadline) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The next output.
    pub fn poll_output(&mut self) -> Option<Output<S>> {
        self.output.pop_front()
    }
}

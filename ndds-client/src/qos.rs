//! Quality of service of producers and consumers, as the SDK takes it.

use std::time::Duration;

use ndds_core::arbitration::Rules;
use ndds_core::wire::{ConsumerQosWire, ProducerQosWire, Reliability};

pub use ndds_core::wire::ConsumerMode;

/// Persistence of a producer that does not set one.
pub const DEFAULT_PERSISTENCE: Duration = Duration::from_secs(1);

/// A producer's quality of service. `Default`: strength 0, persistence 1 s, best effort.
///
/// Consumers arbitrate per sample: a sample of another producer is accepted when that
/// producer's strength is at least the strength of the producer in charge, or when the last
/// accepted sample is older than its persistence, or when the producer in charge is lost.
/// Redundant producers of one topic therefore give hot stand-by: the strongest live one wins,
/// and the next takes over within the persistence when it falls silent. Both values are
/// announced in discovery (`ndds topics` shows them) and travel with every sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProducerQos {
    /// Arbitration strength among producers of one topic.
    pub strength: i32,
    /// How long the producer's last sample stays authoritative at a consumer.
    pub persistence: Duration,
}

impl Default for ProducerQos {
    fn default() -> Self {
        ProducerQos {
            strength: 0,
            persistence: DEFAULT_PERSISTENCE,
        }
    }
}

impl ProducerQos {
    pub(crate) fn to_wire(self) -> ProducerQosWire {
        ProducerQosWire {
            strength: self.strength,
            persistence_us: duration_us(self.persistence),
            reliability: Reliability::BestEffort,
        }
    }
}

/// A consumer's quality of service. `Default`: immediate delivery through a queue of 64, no
/// minimum separation, no deadline, best effort.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConsumerQos {
    /// Immediate (queue, stream or callback) or polled (`poll()` returns the latest).
    pub mode: ConsumerMode,
    /// Immediate mode: how many samples and notifications wait for the application; when
    /// full, the oldest is dropped (and counted) so the application always finds the newest.
    pub depth: usize,
    /// At most one delivery per window; the newest sample wins when the window ends
    /// (zero: every accepted sample is delivered).
    pub min_separation: Duration,
    /// Notify "no new data" when no sample was accepted for this long, and again each deadline
    /// while silent ("never received" before the first sample). `None`: no deadline.
    pub deadline: Option<Duration>,
}

impl Default for ConsumerQos {
    fn default() -> Self {
        ConsumerQos {
            mode: ConsumerMode::Immediate,
            depth: 64,
            min_separation: Duration::ZERO,
            deadline: None,
        }
    }
}

impl ConsumerQos {
    pub(crate) fn to_wire(self) -> ConsumerQosWire {
        ConsumerQosWire {
            min_separation_us: duration_us(self.min_separation),
            deadline_us: self.deadline.map_or(0, duration_us),
            mode: self.mode,
            reliability: Reliability::BestEffort,
        }
    }

    pub(crate) fn rules(self) -> Rules {
        Rules {
            min_separation: self.min_separation,
            deadline: self.deadline.filter(|d| !d.is_zero()),
        }
    }
}

/// Whole microseconds, saturating.
pub(crate) fn duration_us(duration: Duration) -> u64 {
    u64::try_from(duration.as_micros()).unwrap_or(u64::MAX)
}

//! Quality of service of producers and consumers, as the SDK takes it.

use std::time::Duration;

use ndds_core::wire::{ConsumerQosWire, ProducerQosWire, Reliability};

/// A producer's quality of service. `Default`: strength 0, persistence 0, best effort.
///
/// Strength and persistence are announced in discovery (`ndds topics` shows them) and travel
/// with every sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ProducerQos {
    /// Arbitration strength among producers of one topic.
    pub strength: i32,
    /// How long the producer's last sample stays authoritative.
    pub persistence: Duration,
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

/// A consumer's quality of service. `Default`: a queue of 64 samples, best effort.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConsumerQos {
    /// How many received samples wait for the application; when full, the oldest is dropped
    /// (and counted) so the application always finds the newest data.
    pub depth: usize,
}

impl Default for ConsumerQos {
    fn default() -> Self {
        ConsumerQos { depth: 64 }
    }
}

impl ConsumerQos {
    pub(crate) fn to_wire(self) -> ConsumerQosWire {
        ConsumerQosWire::default()
    }
}

/// Whole microseconds, saturating.
pub(crate) fn duration_us(duration: Duration) -> u64 {
    u64::try_from(duration.as_micros()).unwrap_or(u64::MAX)
}

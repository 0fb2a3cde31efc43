//! Quality of service of producers and consumers, as the SDK takes it.

use std::time::Duration;

use ndds_core::arbitration::Rules;
use ndds_core::wire::{ConsumerQosWire, ProducerQosWire};

pub use ndds_core::wire::{ConsumerMode, Reliability};

/// Persistence of a producer that does not set one.
pub const DEFAULT_PERSISTENCE: Duration = Duration::from_secs(1);
/// How long a reliable producer's `write` waits for a full window to open, by default.
pub const DEFAULT_WRITE_TIMEOUT: Duration = Duration::from_secs(1);

/// Whether a producer packs small samples written close together into shared datagrams.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Batching {
    /// Every sample leaves at once in its own datagram (lowest latency).
    #[default]
    Off,
    /// Samples wait up to `max_delay` (or until `max_bytes` are pending, or
    /// [`crate::RawProducer::flush`]) and leave together (highest throughput).
    On {
        /// Longest a sample may wait.
        max_delay: Duration,
        /// Largest batch datagram, in bytes (capped by the path's datagram size).
        max_bytes: usize,
    },
}

/// What a reliable producer's `write` does while its flow-control window is full (its
/// slowest reliable consumer has `depth` samples not yet taken and acknowledged).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum WhenFull {
    /// Wait for the window to open, up to the write timeout, then fail with
    /// [`crate::WriteError::WouldBlock`] without sending. Nothing is ever lost; a consumer
    /// that stops taking samples stops its producers.
    #[default]
    Block,
    /// Never wait: the oldest samples not yet acknowledged leave the history to make room,
    /// and each reliable consumer that still needed them receives a
    /// [`crate::Notification::SamplesLost`] in their place. For producers that must not be
    /// held up (a control loop), at the price of gaps for consumers that fall behind.
    DropOldest,
}

/// A producer's quality of service. `Default`: strength 0, persistence 1 s, best effort, no
/// batching; when reliable, a full window blocks `write` for up to 1 s.
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
    /// Best effort, or reliable with a history of `depth` samples for repair. The depth is
    /// also the flow-control window: a reliable producer never has more than `depth` samples
    /// unacknowledged by its slowest reliable consumer.
    pub reliability: Reliability,
    /// Packing of small samples into shared datagrams.
    pub batching: Batching,
    /// What `write` of a reliable producer does while its window is full.
    pub when_full: WhenFull,
    /// How long `write` of a reliable producer waits for its window to open before it fails
    /// with [`crate::WriteError::WouldBlock`] ([`WhenFull::Block`]).
    pub write_timeout: Duration,
    /// Late joiners get the last values (DDS's TRANSIENT_LOCAL, ROS 2's latched topics): the
    /// newest this many samples are kept for consumers that match later. A reliable
    /// consumer gets them in order before what is written after its match; a best-effort
    /// one gets the newest. 0 (the default): a new consumer gets only what follows its
    /// match.
    pub late_joiners: usize,
}

impl Default for ProducerQos {
    fn default() -> Self {
        ProducerQos {
            strength: 0,
            persistence: DEFAULT_PERSISTENCE,
            reliability: Reliability::BestEffort,
            batching: Batching::Off,
            when_full: WhenFull::Block,
            write_timeout: DEFAULT_WRITE_TIMEOUT,
            late_joiners: 0,
        }
    }
}

impl ProducerQos {
    pub(crate) fn to_wire(self) -> ProducerQosWire {
        ProducerQosWire {
            strength: self.strength,
            persistence_us: duration_us(self.persistence),
            reliability: self.reliability,
        }
    }
}

/// A consumer's quality of service. `Default`: immediate delivery through a queue of 64, no
/// minimum separation, no deadline, best effort.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConsumerQos {
    /// Immediate (queue, stream or callback) or polled (`poll()` returns the latest).
    pub mode: ConsumerMode,
    /// Immediate mode: how many samples wait for the application. When full, a best-effort
    /// consumer drops the oldest (and counts it) so the application always finds the newest;
    /// a reliable one takes no more samples from its producers until there is room.
    /// Notifications have 64 places of their own beyond the depth and never push a sample
    /// out (past those, further notifications are dropped and counted as overflow).
    pub depth: usize,
    /// At most one delivery per window; the newest sample wins when the window ends
    /// (zero: every accepted sample is delivered).
    pub min_separation: Duration,
    /// Notify "no new data" when no sample was accepted for this long, and again each deadline
    /// while silent ("never received" before the first sample). `None`: no deadline.
    pub deadline: Option<Duration>,
    /// Requested reliability: a reliable consumer matches only reliable producers, receives
    /// their samples in order without loss (or a "samples lost" notification when a producer's
    /// history could not repair a gap), and slows its producers down instead of dropping when
    /// it falls behind (`depth` bounds its reordering buffer per producer).
    pub reliability: Reliability,
    /// Take every producer's samples, not only those of the producer in charge: no
    /// arbitration by strength and persistence, and no minimum separation (for recorders and
    /// monitors; `false` by default, as NDDS consumers arbitrate).
    pub every_producer: bool,
}

impl Default for ConsumerQos {
    fn default() -> Self {
        ConsumerQos {
            mode: ConsumerMode::Immediate,
            depth: 64,
            min_separation: Duration::ZERO,
            deadline: None,
            reliability: Reliability::BestEffort,
            every_producer: false,
        }
    }
}

impl ConsumerQos {
    pub(crate) fn to_wire(self) -> ConsumerQosWire {
        ConsumerQosWire {
            min_separation_us: duration_us(self.min_separation),
            deadline_us: self.deadline.map_or(0, duration_us),
            mode: self.mode,
            reliability: self.reliability,
        }
    }

    pub(crate) fn rules(self) -> Rules {
        Rules {
            min_separation: self.min_separation,
            deadline: self.deadline.filter(|d| !d.is_zero()),
            every_producer: self.every_producer,
        }
    }
}

/// Whole microseconds, saturating.
pub(crate) fn duration_us(duration: Duration) -> u64 {
    u64::try_from(duration.as_micros()).unwrap_or(u64::MAX)
}

//! Quality-of-service fields as they travel in discovery.
//!
//! Durations travel as whole microseconds; zero means "none" where the field says so.

use serde::{Deserialize, Serialize};

use super::endpoint::EndpointKind;

/// Delivery guarantee offered by a producer or requested by a consumer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Reliability {
    /// Samples may be lost; the newest sample is what matters.
    #[default]
    BestEffort,
    /// Samples are repaired from a history of `depth` samples.
    Reliable {
        /// History depth kept for repair.
        depth: u32,
    },
}

/// How a consumer wants its samples handed over.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ConsumerMode {
    /// Each accepted sample is delivered as it arrives (queue, stream or callback).
    #[default]
    Immediate,
    /// The application polls the latest accepted sample.
    Polled,
}

/// A producer's quality of service.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ProducerQosWire {
    /// Arbitration strength: the strongest live producer of a topic wins.
    pub strength: i32,
    /// How long, in µs, the producer's last sample stays authoritative.
    pub persistence_us: u64,
    /// Offered reliability.
    pub reliability: Reliability,
}

/// A consumer's quality of service.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ConsumerQosWire {
    /// Minimum separation between deliveries, in µs (0: none).
    pub min_separation_us: u64,
    /// Deadline for fresh data, in µs (0: none).
    pub deadline_us: u64,
    /// Immediate or polled delivery.
    pub mode: ConsumerMode,
    /// Requested reliability.
    pub reliability: Reliability,
}

/// QoS of either kind of endpoint; the variant is the endpoint's kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum EndpointQos {
    /// A producer.
    Producer(ProducerQosWire),
    /// A consumer.
    Consumer(ConsumerQosWire),
}

impl EndpointQos {
    /// Producer or consumer.
    pub fn kind(&self) -> EndpointKind {
        match self {
            EndpointQos::Producer(_) => EndpointKind::Producer,
            EndpointQos::Consumer(_) => EndpointKind::Consumer,
        }
    }
}

//! Samples as the application receives them.

use std::sync::Arc;
use std::time::SystemTime;

use ndds_core::wire::Guid;

/// Where a sample came from and when.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleInfo {
    /// The producer that wrote it.
    pub writer: Guid,
    /// The producer's sequence number (1, 2, ...).
    pub seq: u64,
    /// When the producer wrote it (the producer host's clock).
    pub source_timestamp: SystemTime,
    /// When this process received it.
    pub reception_timestamp: SystemTime,
    /// The producer's strength.
    pub strength: i32,
}

/// A typed sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample<T> {
    /// The value.
    pub value: T,
    /// Its metadata.
    pub info: SampleInfo,
}

/// An undecoded sample: the postcard bytes of the value.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RawSample {
    /// postcard encoding of the value; shared by every consumer of this process that received
    /// the same datagram.
    pub payload: Arc<[u8]>,
    /// Its metadata.
    pub info: SampleInfo,
}

//! What a consumer is handed: an undecoded sample and where it came from.

use std::time::SystemTime;

use bytes::Bytes;

use crate::arbitration::SampleStatus;
use crate::wire::Guid;

/// Where a sample came from, when, and how it was accepted.
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
    /// Fresh, or the first sample of a producer that took over.
    pub status: SampleStatus,
}

/// An undecoded sample: the postcard bytes of the value.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RawSample {
    /// postcard encoding of the value; a view into the received datagram, shared by every
    /// consumer of this participant that the datagram addressed (small samples kept for a
    /// while get a buffer of their own, see [`RawSample::detached`]).
    pub payload: Bytes,
    /// Its metadata.
    pub info: SampleInfo,
}

impl RawSample {
    /// The same sample in a buffer of its own (not sharing the datagram's).
    pub fn detached(self) -> Self {
        RawSample {
            payload: Bytes::copy_from_slice(&self.payload),
            info: self.info,
        }
    }
}

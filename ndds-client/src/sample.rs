//! What consumers receive: samples with their status, and notifications.

use std::time::SystemTime;

use bytes::Bytes;

use ndds_core::wire::Guid;

pub use ndds_core::arbitration::{Notification, SampleStatus};

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
    pub payload: Bytes,
    /// Its metadata.
    pub info: SampleInfo,
}

impl RawSample {
    /// The same sample in a buffer of its own (not sharing the datagram's).
    pub(crate) fn detached(self) -> Self {
        RawSample {
            payload: Bytes::copy_from_slice(&self.payload),
            info: self.info,
        }
    }
}

/// What an immediate consumer receives: a sample, or a notification without one.
#[derive(Clone, Debug, PartialEq)]
pub enum Event<T> {
    /// An accepted sample.
    Sample(Sample<T>),
    /// A status without a sample: deadline missed, producer lost, incompatible type, ...
    Notification(Notification),
}

/// An [`Event`] before decoding.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RawEvent {
    /// An accepted sample.
    Sample(RawSample),
    /// A status without a sample.
    Notification(Notification),
}

/// What [`crate::Consumer::poll`] says about the latest accepted sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PollStatus {
    /// Nothing was ever accepted.
    NeverReceived,
    /// A sample accepted since the previous poll.
    Fresh,
    /// The same sample as the previous poll, and the deadline (if any) has not passed.
    Unchanged,
    /// The deadline passed since the last accepted sample: the data is stale.
    NoNewData,
}

/// The answer of [`crate::Consumer::poll`].
#[derive(Clone, Debug, PartialEq)]
pub struct Polled<T> {
    /// The latest accepted sample, if any.
    pub sample: Option<Sample<T>>,
    /// What it is.
    pub status: PollStatus,
}

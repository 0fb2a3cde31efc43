//! What consumers receive: samples with their status, and notifications.

pub use ndds_core::arbitration::{Notification, SampleStatus};

pub use ndds_core::participant::{RawSample, SampleInfo};

/// A typed sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample<T> {
    /// The value.
    pub value: T,
    /// Its metadata.
    pub info: SampleInfo,
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

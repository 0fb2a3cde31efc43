//! What a consumer is told: the status that comes with each delivered sample, and the
//! notifications that come without one.

use std::time::Duration;

use crate::wire::Guid;

/// The status delivered with a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleStatus {
    /// A fresh sample from the producer already in charge (or the very first sample).
    Fresh,
    /// A fresh sample from a producer that has just taken over from `previous`: it is stronger,
    /// or the previous one fell silent past its persistence or was lost.
    TookOver {
        /// The producer in charge before.
        previous: Guid,
    },
}

/// A notification delivered without a sample.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Notification {
    /// The deadline passed without a fresh sample; repeated each deadline while silent.
    NoNewData {
        /// Time since the last accepted sample.
        silent_for: Duration,
    },
    /// The deadline passed and no sample was ever accepted; repeated each deadline.
    NeverReceived {
        /// Time since the consumer was created.
        waited: Duration,
    },
    /// A sample whose source timestamp is not newer than the last one accepted from the same
    /// producer (a duplicate or a reordered datagram); it was not delivered.
    OldData {
        /// Its producer.
        writer: Guid,
        /// Its sequence number.
        seq: u64,
    },
    /// A matched producer went away (closed, crashed, or its host was lost).
    ProducerLost {
        /// The producer.
        writer: Guid,
        /// True if it was the producer in charge; any producer may take over at once.
        was_current: bool,
    },
    /// A producer of this topic has another type, or offers best effort to this reliable
    /// consumer: its samples never reach this consumer.
    Incompatible {
        /// Why.
        reason: crate::discovery::Incompatibility,
        /// The other endpoint.
        writer: Guid,
        /// Its type name.
        type_name: String,
        /// Its type fingerprint.
        fingerprint: u64,
        /// This consumer's type name.
        local_type: String,
        /// This consumer's fingerprint.
        local_fingerprint: u64,
    },
    /// A producer of this topic is not matched because the domain's permissions document
    /// does not allow it (or this consumer): its samples never reach this consumer.
    NotPermitted {
        /// The other endpoint.
        writer: Guid,
        /// Why, in words: the subject and the rule.
        reason: String,
    },
    /// A reliable producer's samples `from..to` will never arrive: its history no longer
    /// held them when they were found missing.
    SamplesLost {
        /// The producer.
        writer: Guid,
        /// First lost sequence number.
        from: u64,
        /// One past the last lost sequence number.
        to: u64,
    },
    /// A sample did not decode as the consumer's type; it was not delivered.
    DeserializationError {
        /// Its producer.
        writer: Guid,
        /// Its sequence number.
        seq: u64,
        /// The decoder's message.
        error: String,
    },
}

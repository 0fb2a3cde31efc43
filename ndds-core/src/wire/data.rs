//! `Data` (kind 16): one user sample, from a producing process to one consuming process.
//!
//! ```text
//! header(kind = 16, sender = writer's participant id)
//!   | varint writer entity | u64 reader participant (varint) | varint n | n × varint reader entity
//!   | varint seq | varint timestamp_ns | zigzag strength | varint persistence_us
//!   | varint len | len × payload byte
//! ```
//!
//! One datagram goes to each consuming process (locator) that has matched readers; `readers`
//! lists the reader entities of `reader_participant` at that locator. The payload is the
//! postcard encoding of the sample value. Strength and persistence travel with every sample so a
//! consumer can arbitrate between producers without consulting discovery.

use std::borrow::Cow;

use serde::{Deserialize, Serialize};

/// Body of a `Data` datagram. The payload borrows from the received buffer.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Data<'a> {
    /// Entity number of the producing endpoint within the sender participant.
    pub writer: u32,
    /// Participant id of the consuming process this datagram is for.
    pub reader_participant: u64,
    /// Entity numbers of the consuming endpoints, within `reader_participant`.
    /// Borrowed when sending (no allocation per sample), owned after decoding.
    #[serde(deserialize_with = "super::bounded::cow_vec")]
    pub readers: Cow<'a, [u32]>,
    /// Per-writer sequence number, starting at 1.
    pub seq: u64,
    /// Source timestamp: nanoseconds since the Unix epoch when the sample was written.
    pub timestamp_ns: u64,
    /// The writer's strength.
    pub strength: i32,
    /// The writer's persistence in µs.
    pub persistence_us: u64,
    /// postcard-encoded sample value.
    #[serde(borrow)]
    pub payload: &'a [u8],
}

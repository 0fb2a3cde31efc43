//! What ports exchange on their topics (`port/<P>/request`, `port/<P>/reply/<user>`,
//! `port/<P>/owner`).

use serde::{Deserialize, Serialize};

/// A request from a user to the owner.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Request {
    /// Per-user sequence number; the reply carries it back.
    pub id: u64,
    /// The user's reply topic suffix (unique per user handle).
    pub user: String,
    /// The task that sent it.
    pub task: String,
    /// The message, postcard-encoded.
    #[serde(with = "serde_bytes")]
    pub payload: Vec<u8>,
}

/// A reply from the owner.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Reply {
    /// The request's id.
    pub id: u64,
    /// The reply, postcard-encoded.
    #[serde(with = "serde_bytes")]
    pub payload: Vec<u8>,
}

/// An owner's declaration, repeated while it owns the port.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OwnerInfo {
    /// The owning task.
    pub task: String,
    /// Its process id.
    pub pid: u32,
    /// Random per owner handle: two owners never share it.
    pub incarnation: u64,
    /// Fingerprint of the request type.
    pub request_format: u64,
    /// Fingerprint of the reply type.
    pub reply_format: u64,
}

//! `Withdraw` (kind 3): endpoints that no longer exist.
//!
//! ```text
//! header(kind = 3) | varint n | n × Guid
//! ```
//!
//! Sent the moment a local endpoint is closed or its client disconnects. Receivers remove the
//! listed endpoints of the sending node at once. The same guids are repeated in the `withdrawn`
//! list of the sender's next periodic announcements.

use serde::{Deserialize, Serialize};

use super::endpoint::Guid;

/// Body of a `Withdraw` datagram.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Withdraw {
    /// The endpoints removed.
    #[serde(deserialize_with = "super::bounded::vec")]
    pub endpoints: Vec<Guid>,
}

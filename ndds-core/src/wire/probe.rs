//! `Probe` (kind 5) and `ProbeReply` (kind 6): proof that a daemon receives at the address it
//! claims, before anything larger than the datagrams it sent is sent there.
//!
//! ```text
//! header(kind = 5)   token: u64 (varint)      to an address not yet validated
//! header(kind = 6)   token: u64 (varint)      the same token, back to the probe's source
//! ```
//!
//! A daemon that hears a new node at an address it has not validated sends that address a
//! `Probe` with a token only it can compute; the node answers with a `ProbeReply` carrying the
//! token. Until the reply arrives, the address gets nothing but probes (no full announcement,
//! no unicast copies of refreshes), so a datagram with a forged source address cannot make a
//! daemon send a victim more than it received.

use serde::{Deserialize, Serialize};

/// Body of a `Probe` datagram.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Probe {
    /// To be echoed in the `ProbeReply`.
    pub token: u64,
}

/// Body of a `ProbeReply` datagram.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProbeReply {
    /// The token of the `Probe` answered.
    pub token: u64,
}

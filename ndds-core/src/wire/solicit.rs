//! `Solicit` (kind 1): "announce yourselves to me".
//!
//! ```text
//! header(kind = 1) | NodeInfo
//! ```
//!
//! Sent by a daemon to the discovery multicast group when it starts, and again after a short
//! back-off in case the first one was lost. Every daemon that receives
//! it answers with a full `Announce` sent by unicast to `node.unicast`, and records the
//! soliciting node as if it had announced itself.

use serde::{Deserialize, Serialize};

use super::node::NodeInfo;

/// Body of a `Solicit` datagram.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Solicit {
    /// The soliciting daemon.
    pub node: NodeInfo,
}

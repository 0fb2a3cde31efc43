//! `Announce` (kind 2): a daemon's node information and some or all of its local endpoints.
//!
//! ```text
//! header(kind = 2) | NodeInfo | varint n | n × EndpointInfo | varint m | m × Guid
//! ```
//!
//! Every endpoint listed is created or refreshed at the receiver with a lease of
//! `node.lease_ms` (capped at one hour); every guid in `withdrawn` is removed at once. A full announcement
//! (periodic refresh, or the answer to a `Solicit`) may be split over several datagrams, each a
//! complete `Announce`; receivers treat every datagram on its own.

use serde::{Deserialize, Serialize};

use super::endpoint::{EndpointInfo, Guid};
use super::node::NodeInfo;

/// Body of an `Announce` datagram.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Announce {
    /// The announcing daemon.
    pub node: NodeInfo,
    /// Endpoints created or refreshed by this datagram.
    #[serde(deserialize_with = "super::bounded::vec")]
    pub endpoints: Vec<EndpointInfo>,
    /// Endpoints recently withdrawn, repeated for a few periods so a lost `Withdraw` heals.
    #[serde(deserialize_with = "super::bounded::vec")]
    pub withdrawn: Vec<Guid>,
}

//! What a daemon says about itself in `Solicit` and `Announce`.

use serde::{Deserialize, Serialize};

use super::endpoint::Locator;

/// A daemon's self-description. The node id itself is the header's sender id.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NodeInfo {
    /// Host name of the machine the daemon runs on.
    pub hostname: String,
    /// Process id of the daemon.
    pub pid: u32,
    /// Unicast address where the daemon receives discovery datagrams.
    pub unicast: Locator,
    /// How long, in ms, receivers keep this node's entries without a refresh.
    pub lease_ms: u32,
    /// How often, in ms, the node refreshes its announcements.
    pub announce_period_ms: u32,
    /// Version string of the daemon software.
    pub version: String,
}

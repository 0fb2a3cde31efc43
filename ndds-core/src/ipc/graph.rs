//! The daemon's view of the domain, as tools receive it.

use serde::{Deserialize, Serialize};

use super::client::Role;
use crate::wire::{EndpointInfo, Locator, NodeInfo};

/// A daemon's complete view: itself, the nodes it knows, its clients, every endpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Graph {
    /// The answering daemon.
    pub local: NodeSummary,
    /// Remote nodes it currently knows.
    pub nodes: Vec<NodeSummary>,
    /// Its connected clients and tools.
    pub clients: Vec<ClientSummary>,
    /// Every endpoint it knows, local and remote.
    pub endpoints: Vec<EndpointSummary>,
    /// Named counters (datagrams received, dropped by reason, ...).
    pub counters: Vec<(String, u64)>,
}

/// One daemon.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NodeSummary {
    /// Node id.
    pub node: u64,
    /// What it says about itself.
    pub info: NodeInfo,
    /// The discovery multicast group and port; `None` when the answering daemon has multicast
    /// off, and for remote nodes (whose settings are not known).
    pub multicast: Option<Locator>,
    /// Interface address the node uses (the address of its unicast locator).
    pub interface: [u8; 4],
    /// Milliseconds since it was last heard from (0 for the local node).
    pub last_seen_ms: u64,
    /// Milliseconds until it is forgotten unless refreshed (`None` for the local node).
    pub expires_in_ms: Option<u64>,
    /// The answering daemon's configured unicast peers, as configured (empty for remote nodes).
    pub peers: Vec<PeerSummary>,
    /// Milliseconds since a `Solicit` or `Announce` of this remote node last arrived through
    /// the multicast group (`None`: never, and for the local node).
    pub multicast_seen_ms: Option<u64>,
    /// Whether the answering daemon also sends its domain-wide datagrams to this remote node by
    /// unicast: a configured peer, or a node not heard by multicast lately (false for the local
    /// node).
    pub unicast_copies: bool,
    /// The identity that signs its datagrams, in a domain with permissions (`ed25519:...`;
    /// `None`: it signs nothing, or the answering daemon checks no signatures).
    pub identity: Option<String>,
    /// The subject the answering daemon's permissions document gives that identity.
    pub subject: Option<String>,
    /// Whether the answering daemon verified its signatures (for the local node: whether it
    /// signs).
    pub authenticated: bool,
    /// How many of its endpoints the answering daemon's document refuses (0 for the local
    /// node, whose refused declarations never enter the table).
    pub refused_endpoints: u32,
}

/// One configured unicast peer of the answering daemon.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct PeerSummary {
    /// As configured: `host`, `host:port`, `address` or `address:port`.
    pub name: String,
    /// The unicast locator it resolved to at start.
    pub locator: Locator,
    /// The node currently known at that locator, if any.
    pub node: Option<u64>,
}

/// One client or tool connected to the answering daemon.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClientSummary {
    /// Participant id.
    pub participant: u64,
    /// Process id, as the daemon's kernel saw it (`SO_PEERCRED`), not as the client said.
    pub pid: u32,
    /// User id, from the kernel.
    pub uid: u32,
    /// Process name.
    pub name: String,
    /// Client or tool.
    pub role: Role,
    /// Number of endpoints it declared.
    pub endpoints: u32,
}

/// One endpoint, local or remote.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EndpointSummary {
    /// As declared or announced.
    pub info: EndpointInfo,
    /// Node id of the daemon that owns it.
    pub node: u64,
    /// Host name of that daemon.
    pub hostname: String,
    /// Milliseconds until it decays unless refreshed (`None` for local endpoints).
    pub expires_in_ms: Option<u64>,
}

//! Frames from a daemon to a client or tool.

use serde::{Deserialize, Serialize};

use super::graph::Graph;
use crate::security::DataKeys;
use crate::wire::{EndpointInfo, Guid, Locator};

/// The daemon's answer to a valid `Hello`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Welcome {
    /// The daemon's [`super::IPC_VERSION`].
    pub ipc_version: u16,
    /// The daemon's node id.
    pub node: u64,
    /// The client's participant id: the one its `Hello` named, or the one the daemon chose
    /// for it when `Hello` named none (0).
    pub participant: u64,
    /// The daemon's domain.
    pub domain: u16,
    /// Host name.
    pub hostname: String,
    /// IPv4 address of the interface the daemon uses; clients bind their data sockets to it.
    pub interface: [u8; 4],
    /// Daemon process id.
    pub pid: u32,
    /// Daemon software version.
    pub version: String,
    /// The domain has a permissions document: the client must seal its data for, and open it
    /// from, its matched peers with the data keys the daemon gives ([`DaemonMessage::PairKeys`])
    /// and nobody else.
    pub pairwise: bool,
}

/// A frame from daemon to client.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum DaemonMessage {
    /// The session is open.
    Welcome(Welcome),
    /// The session is refused; the daemon closes the connection after this frame.
    Refused {
        /// Why, for the user.
        reason: String,
    },
    /// Result of a `Declare`.
    Declared {
        /// The entity declared.
        entity: u32,
        /// `Err` carries the reason for the user.
        result: Result<(), String>,
    },
    /// A local endpoint of this client matched another endpoint.
    Matched {
        /// The client's entity.
        local: u32,
        /// The other endpoint.
        remote: EndpointInfo,
    },
    /// A local endpoint shares its topic with an endpoint of another type.
    Incompatible {
        /// The client's entity.
        local: u32,
        /// The other endpoint.
        remote: EndpointInfo,
    },
    /// A matched, incompatible or refused endpoint went away.
    Unmatched {
        /// The client's entity.
        local: u32,
        /// The endpoint that went away.
        remote: Guid,
    },
    /// Answer to `QueryGraph`: one page of the daemon's view.
    Graph {
        /// The request number.
        request: u32,
        /// The daemon's view of the domain, with the page's endpoints only (in guid order).
        graph: Graph,
        /// The guid to ask the next page after; `None` on the last page.
        next: Option<Guid>,
    },
    /// A local endpoint of this client would pair with another endpoint, but the domain's
    /// permissions document does not allow one of them.
    NotPermitted {
        /// The client's entity.
        local: u32,
        /// The other endpoint.
        remote: EndpointInfo,
        /// Why, in words: the subject and the rule.
        reason: String,
    },
    /// The data keys of the pair of this client's participant and `participant` (at
    /// `locator`), sent before the pair's first `Matched` in a domain with permissions.
    PairKeys {
        /// The client's entity the match is for.
        local: u32,
        /// The other participant.
        participant: u64,
        /// Its data socket.
        locator: Locator,
        /// The keys.
        keys: DataKeys,
    },
}

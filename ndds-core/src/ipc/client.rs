//! Frames from a client or tool to its daemon.

use serde::{Deserialize, Serialize};

use crate::types::TypeDescription;
use crate::wire::{EndpointQos, Guid, Locator};

/// What kind of program is connecting.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Role {
    /// A control program with producers and consumers.
    Client,
    /// An inspection tool (`ndds topics`, ...); listed separately.
    Tool,
}

/// The first frame of every connection.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Hello {
    /// Must equal the daemon's [`super::IPC_VERSION`].
    pub ipc_version: u16,
    /// The participant id the client had before (reconnecting), or 0: the daemon chooses
    /// one ([`super::Welcome::participant`]; in a domain with permissions it must be one of
    /// the daemon's identity).
    pub participant: u64,
    /// Client process id.
    pub pid: u32,
    /// Client process name.
    pub name: String,
    /// Client or tool.
    pub role: Role,
}

/// A producer or consumer declared by a client.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EndpointDecl {
    /// Entity number, unique within the participant.
    pub entity: u32,
    /// Topic name.
    pub topic: String,
    /// Sample type.
    pub type_desc: TypeDescription,
    /// Fingerprint of `type_desc`.
    pub fingerprint: u64,
    /// Kind and quality of service.
    pub qos: EndpointQos,
    /// The client's data socket address.
    pub locator: Locator,
}

/// A frame from client to daemon.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ClientMessage {
    /// Opens the session.
    Hello(Hello),
    /// Declares an endpoint; answered by [`super::DaemonMessage::Declared`].
    Declare(EndpointDecl),
    /// Closes an endpoint.
    Undeclare {
        /// Its entity number.
        entity: u32,
    },
    /// Asks for one page of the daemon's [`super::Graph`]; answered by
    /// [`super::DaemonMessage::Graph`].
    QueryGraph {
        /// Echoed in the answer.
        request: u32,
        /// The page: endpoints with guids after this one (`None`: the first page, which also
        /// carries the nodes, clients and counters; a later page carries endpoints only).
        after: Option<Guid>,
    },
}

//! Identities, locators and endpoint declarations shared by several messages.

use std::fmt;
use std::net::{Ipv4Addr, SocketAddrV4};

use serde::{Deserialize, Serialize};

use super::qos::EndpointQos;
use crate::types::TypeDescription;

/// Globally unique endpoint identity: the participant (client process connection) that owns
/// the endpoint and an entity number unique within that participant.
///
/// Participant ids are 64-bit random numbers chosen by the client; entity numbers count from 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Guid {
    /// Id of the owning participant.
    pub participant: u64,
    /// Entity number within the participant.
    pub entity: u32,
}

impl fmt::Display for Guid {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:016x}.{}", self.participant, self.entity)
    }
}

/// An IPv4 UDP address as it travels on the wire: four address bytes then the port.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Locator {
    /// IPv4 address, network order.
    pub addr: [u8; 4],
    /// UDP port.
    pub port: u16,
}

impl Locator {
    /// The unspecified locator `0.0.0.0:0`.
    pub const UNSPECIFIED: Locator = Locator {
        addr: [0; 4],
        port: 0,
    };
}

impl From<SocketAddrV4> for Locator {
    fn from(addr: SocketAddrV4) -> Self {
        Locator {
            addr: addr.ip().octets(),
            port: addr.port(),
        }
    }
}

impl From<Locator> for SocketAddrV4 {
    fn from(locator: Locator) -> Self {
        SocketAddrV4::new(Ipv4Addr::from(locator.addr), locator.port)
    }
}

impl fmt::Display for Locator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        SocketAddrV4::from(*self).fmt(f)
    }
}

/// Whether an endpoint produces or consumes its topic.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum EndpointKind {
    /// Writes samples.
    Producer,
    /// Reads samples.
    Consumer,
}

impl EndpointKind {
    /// Lower-case name for listings.
    pub fn name(self) -> &'static str {
        match self {
            EndpointKind::Producer => "producer",
            EndpointKind::Consumer => "consumer",
        }
    }
}

/// Everything other hosts need to know about one producer or consumer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EndpointInfo {
    /// The endpoint's identity.
    pub guid: Guid,
    /// Topic name.
    pub topic: String,
    /// The sample type: display name and structural layout.
    pub type_desc: TypeDescription,
    /// Fingerprint of `type_desc`; receivers recompute it and drop entries where it differs.
    pub fingerprint: u64,
    /// Kind-specific quality of service (the variant also says producer or consumer).
    pub qos: EndpointQos,
    /// Where the owning process receives data (consumers) or sends from (producers).
    pub locator: Locator,
    /// Process id of the owning client.
    pub pid: u32,
    /// Name of the owning client process.
    pub process: String,
}

impl EndpointInfo {
    /// Producer or consumer.
    pub fn kind(&self) -> EndpointKind {
        self.qos.kind()
    }
}

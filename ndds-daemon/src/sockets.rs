//! The daemon's two UDP sockets.
//!
//! - The *multicast* socket is bound to `group:port` with `SO_REUSEADDR`, so several daemons on
//!   one host (or in one test) all receive the domain's discovery multicast, and joins the
//!   group on the configured interface only.
//! - The *unicast* socket is bound to `interface:unicast_port`. It receives answers to our
//!   solicitations and sends everything we send, with `IP_MULTICAST_IF` set to the configured
//!   interface: multicast never leaves through whatever interface the routing table prefers.

use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};

use socket2::{Domain, Protocol, Socket, Type};
use tokio::net::UdpSocket;

/// Receive buffer requested for both sockets.
const RECV_BUFFER: usize = 4 * 1024 * 1024;

/// The bound discovery sockets.
#[derive(Debug)]
pub struct DiscoverySockets {
    /// Receives the group's multicast.
    pub multicast: UdpSocket,
    /// Receives unicast, sends everything.
    pub unicast: UdpSocket,
    /// Where multicast transmits go.
    pub group: SocketAddrV4,
}

/// A socket operation failed; says which one.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {source}")]
pub struct SocketError {
    /// The failed step, with addresses.
    pub what: String,
    /// The OS error.
    pub source: io::Error,
}

fn step<T>(what: impl FnOnce() -> String, result: io::Result<T>) -> Result<T, SocketError> {
    result.map_err(|source| SocketError {
        what: what(),
        source,
    })
}

/// Opens both sockets. Must be called inside a tokio runtime.
pub fn open(
    interface: Ipv4Addr,
    group: Ipv4Addr,
    port: u16,
    unicast_port: u16,
    ttl: u32,
) -> Result<DiscoverySockets, SocketError> {
    let group_addr = SocketAddrV4::new(group, port);
    let multicast = new_udp()?;
    step(|| "SO_REUSEADDR".into(), multicast.set_reuse_address(true))?;
    step(
        || format!("bind multicast socket to {group_addr}"),
        multicast.bind(&SocketAddr::V4(group_addr).into()),
    )?;
    step(
        || format!("join {group} on {interface}"),
        multicast.join_multicast_v4(&group, &interface),
    )?;
    let _ = multicast.set_recv_buffer_size(RECV_BUFFER);

    let unicast = new_udp()?;
    let local = SocketAddrV4::new(interface, unicast_port);
    step(
        || format!("bind unicast socket to {local}"),
        unicast.bind(&SocketAddr::V4(local).into()),
    )?;
    step(
        || format!("IP_MULTICAST_IF {interface}"),
        unicast.set_multicast_if_v4(&interface),
    )?;
    step(
        || "IP_MULTICAST_LOOP".into(),
        unicast.set_multicast_loop_v4(true),
    )?;
    step(
        || format!("IP_MULTICAST_TTL {ttl}"),
        unicast.set_multicast_ttl_v4(ttl),
    )?;
    let _ = unicast.set_recv_buffer_size(RECV_BUFFER);

    Ok(DiscoverySockets {
        multicast: into_tokio(multicast)?,
        unicast: into_tokio(unicast)?,
        group: group_addr,
    })
}

fn new_udp() -> Result<Socket, SocketError> {
    let socket = step(
        || "create UDP socket".into(),
        Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)),
    )?;
    step(|| "set non-blocking".into(), socket.set_nonblocking(true))?;
    Ok(socket)
}

fn into_tokio(socket: Socket) -> Result<UdpSocket, SocketError> {
    step(
        || "register socket with tokio".into(),
        UdpSocket::from_std(socket.into()),
    )
}

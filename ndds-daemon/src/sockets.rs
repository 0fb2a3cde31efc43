//! The daemon's UDP sockets.
//!
//! - The *multicast* socket (only when multicast is on) is bound to `group:port` with
//!   `SO_REUSEADDR`, so several daemons on one host (or in one test) all receive the domain's
//!   discovery multicast, and joins the group on the configured interface only.
//! - The *unicast* socket is bound to `interface:unicast_port`. It receives datagrams addressed
//!   to this daemon (answers to its solicitations, copies from peers) and sends everything the
//!   daemon sends. With multicast on, `IP_MULTICAST_IF` is set to the configured interface:
//!   multicast never leaves through whatever interface the routing table prefers.
//!
//! Which socket received a datagram tells the engine how it arrived
//! ([`ndds_core::discovery::Via`]).

use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};

use socket2::{Domain, Protocol, Socket, Type};
use tokio::net::UdpSocket;

/// Receive buffer requested for both sockets.
const RECV_BUFFER: usize = 4 * 1024 * 1024;

/// Which unicast port to bind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnicastPort {
    /// The domain's default port; any free port if it is taken (logged).
    Default(u16),
    /// Exactly this port (0: any free port); taken is an error.
    Exact(u16),
}

/// The bound discovery sockets.
#[derive(Debug)]
pub struct DiscoverySockets {
    /// Receives the group's multicast (`None` with multicast off).
    pub multicast: Option<UdpSocket>,
    /// Receives unicast, sends everything.
    pub unicast: UdpSocket,
    /// Where multicast transmits go (`None` with multicast off).
    pub group: Option<SocketAddrV4>,
}

/// A socket could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum SocketError {
    /// A socket operation failed; says which one.
    #[error("{what}: {source}")]
    Step {
        /// The failed step, with addresses.
        what: String,
        /// The OS error.
        source: io::Error,
    },
    /// The unicast port given explicitly is in use.
    #[error(
        "unicast port {port} on {interface} is taken: choose a free --unicast-port, or 0 for any \
         free port"
    )]
    UnicastPortTaken {
        /// The interface address.
        interface: Ipv4Addr,
        /// The port asked for.
        port: u16,
    },
}

fn step<T>(what: impl FnOnce() -> String, result: io::Result<T>) -> Result<T, SocketError> {
    result.map_err(|source| SocketError::Step {
        what: what(),
        source,
    })
}

/// Opens the sockets: the multicast one only when `group` is given. Must be called inside a
/// tokio runtime.
pub fn open(
    interface: Ipv4Addr,
    group: Option<SocketAddrV4>,
    unicast_port: UnicastPort,
    ttl: u32,
) -> Result<DiscoverySockets, SocketError> {
    let multicast = match group {
        Some(group) => Some(into_tokio(open_multicast(interface, group)?)?),
        None => None,
    };
    let unicast = bind_unicast(interface, unicast_port)?;
    if group.is_some() {
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
    }
    let _ = unicast.set_recv_buffer_size(RECV_BUFFER);
    Ok(DiscoverySockets {
        multicast,
        unicast: into_tokio(unicast)?,
        group,
    })
}

fn open_multicast(interface: Ipv4Addr, group: SocketAddrV4) -> Result<Socket, SocketError> {
    let socket = new_udp()?;
    step(|| "SO_REUSEADDR".into(), socket.set_reuse_address(true))?;
    step(
        || format!("bind multicast socket to {group}"),
        socket.bind(&SocketAddr::V4(group).into()),
    )?;
    step(
        || format!("join {} on {interface}", group.ip()),
        socket.join_multicast_v4(group.ip(), &interface),
    )?;
    let _ = socket.set_recv_buffer_size(RECV_BUFFER);
    Ok(socket)
}

/// Binds the unicast socket, falling back to any free port when the default one is taken.
fn bind_unicast(interface: Ipv4Addr, port: UnicastPort) -> Result<Socket, SocketError> {
    let (wanted, fallback) = match port {
        UnicastPort::Default(port) => (port, true),
        UnicastPort::Exact(port) => (port, false),
    };
    let socket = new_udp()?;
    let local = SocketAddrV4::new(interface, wanted);
    match socket.bind(&SocketAddr::V4(local).into()) {
        Ok(()) => Ok(socket),
        Err(err) if err.kind() == io::ErrorKind::AddrInUse && fallback => {
            let any = SocketAddrV4::new(interface, 0);
            step(
                || format!("bind unicast socket to {any}"),
                socket.bind(&SocketAddr::V4(any).into()),
            )?;
            let chosen = socket
                .local_addr()
                .ok()
                .and_then(|a| a.as_socket())
                .map_or(0, |a| a.port());
            tracing::info!(
                default = wanted,
                port = chosen,
                "the default unicast discovery port is taken (another daemon of this domain on \
                 this interface?); using another one: peers that name this host without a port \
                 will not reach this daemon, but it still reaches its own peers"
            );
            Ok(socket)
        }
        Err(err) if err.kind() == io::ErrorKind::AddrInUse => Err(SocketError::UnicastPortTaken {
            interface,
            port: wanted,
        }),
        Err(source) => Err(SocketError::Step {
            what: format!("bind unicast socket to {local}"),
            source,
        }),
    }
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

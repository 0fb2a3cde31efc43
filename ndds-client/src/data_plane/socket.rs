//! The participant's data socket: how large datagrams may be on its interface, and sending
//! the datagrams the core asks for.

use std::io;
use std::net::Ipv4Addr;

use ndds_core::participant::Transmit;
use ndds_core::wire::MAX_DATAGRAM;

/// IPv4 and UDP headers.
const IP_UDP_HEADERS: usize = 28;
/// Largest sample a participant accepts by default (fragmented over datagrams).
pub const DEFAULT_MAX_SAMPLE: usize = 16 * 1024 * 1024;
/// Socket buffer sizes requested by default (the kernel may grant less: `net.core.rmem_max`
/// and `wmem_max`).
pub const DEFAULT_SOCKET_BUFFER: usize = 8 * 1024 * 1024;

/// How large datagrams and samples may be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Largest datagram sent: the interface's MTU minus the IP and UDP headers, so no
    /// datagram is fragmented by IP (one lost IP fragment would lose it all); 65 507 bytes on
    /// loopback.
    pub max_datagram: usize,
    /// Largest sample accepted, in encoded bytes.
    pub max_sample: usize,
    /// Receive buffer asked of the kernel, in bytes.
    pub recv_buffer: usize,
}

impl Limits {
    /// The limits for a data socket bound to `interface`.
    pub fn for_interface(interface: Ipv4Addr) -> Self {
        Limits {
            max_datagram: datagram_size(interface),
            max_sample: DEFAULT_MAX_SAMPLE,
            recv_buffer: DEFAULT_SOCKET_BUFFER,
        }
    }
}

/// The datagram size that avoids IP fragmentation on the interface with this address.
fn datagram_size(interface: Ipv4Addr) -> usize {
    if interface.is_loopback() {
        return MAX_DATAGRAM;
    }
    let mtu = if_addrs::get_if_addrs()
        .ok()
        .and_then(|all| {
            all.into_iter()
                .find(|i| i.ip() == std::net::IpAddr::V4(interface))
        })
        .and_then(|i| std::fs::read_to_string(format!("/sys/class/net/{}/mtu", i.name)).ok())
        .and_then(|text| text.trim().parse::<usize>().ok())
        .unwrap_or(1500);
    mtu.saturating_sub(IP_UDP_HEADERS).clamp(576, MAX_DATAGRAM)
}

/// Asks for large socket buffers: `recv` bytes to receive into. The kernel grants at most
/// `net.core.rmem_max` unless the process may force more (`CAP_NET_ADMIN`), which is tried
/// when it granted less. (Linux reports twice what it grants: the other half is its
/// bookkeeping.)
pub(crate) fn set_buffers(socket: &std::net::UdpSocket, recv: usize) {
    let sock = socket2::SockRef::from(socket);
    let _ = sock.set_send_buffer_size(DEFAULT_SOCKET_BUFFER);
    let _ = sock.set_recv_buffer_size(recv);
    let granted = |sock: &socket2::SockRef<'_>| sock.recv_buffer_size().unwrap_or(0) / 2;
    if granted(&sock) < recv {
        force_recv_buffer(socket, recv);
    }
    let got = granted(&sock);
    if got < recv {
        let line = format!(
            "receive buffer: {recv} bytes asked, the kernel granted {got}; raise \
             net.core.rmem_max (sysctl) for more"
        );
        if recv > DEFAULT_SOCKET_BUFFER {
            tracing::warn!("{line}");
        } else {
            tracing::debug!("{line}");
        }
    }
}

/// `SO_RCVBUFFORCE`: more than `rmem_max`, for a process with `CAP_NET_ADMIN` (refused
/// otherwise, and then nothing changes).
#[cfg(target_os = "linux")]
fn force_recv_buffer(socket: &std::net::UdpSocket, bytes: usize) {
    use std::os::fd::AsRawFd;
    let value = libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX);
    // SAFETY: a valid socket descriptor, a pointer to a c_int and its size.
    let _ = unsafe {
        libc::setsockopt(
            socket.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_RCVBUFFORCE,
            (&value as *const libc::c_int).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
}

#[cfg(not(target_os = "linux"))]
fn force_recv_buffer(_socket: &std::net::UdpSocket, _bytes: usize) {}

/// Sends one datagram, its head and tail gathered by the kernel (the tail, a sample's
/// payload, is not copied first); a full socket buffer is retried briefly rather than
/// dropped.
pub(crate) fn send(socket: &std::net::UdpSocket, transmit: &Transmit) -> io::Result<()> {
    let socket = socket2::SockRef::from(socket);
    let address = socket2::SockAddr::from(transmit.to);
    let tail = transmit.tail();
    let parts = [io::IoSlice::new(transmit.head()), io::IoSlice::new(tail)];
    let parts = if tail.is_empty() {
        &parts[..1]
    } else {
        &parts[..]
    };
    let mut attempts = 0;
    loop {
        match socket.send_to_vectored(parts, &address) {
            Ok(_) => return Ok(()),
            Err(err)
                if err.kind() == io::ErrorKind::WouldBlock || err.raw_os_error() == Some(105) =>
            {
                // ENOBUFS (105) or a full buffer: give the kernel a moment.
                attempts += 1;
                if attempts > 100 {
                    return Err(err);
                }
                std::thread::yield_now();
            }
            Err(err) if err.kind() == io::ErrorKind::Interrupted => {}
            Err(err) => return Err(err),
        }
    }
}

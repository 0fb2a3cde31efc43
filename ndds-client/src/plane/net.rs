//! Sending on the participant's data socket, and the datagram size of the path.

use std::io;
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicU64, Ordering};

use ndds_core::admission::AdmissionStats;
use ndds_core::wire::MAX_DATAGRAM;

/// IPv4 and UDP headers.
const IP_UDP_HEADERS: usize = 28;
/// Largest sample a participant accepts by default (fragmented over datagrams).
pub const DEFAULT_MAX_SAMPLE: usize = 16 * 1024 * 1024;

/// How large datagrams and samples may be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Largest datagram sent: the interface's MTU minus the IP and UDP headers, so no
    /// datagram is fragmented by IP (one lost IP fragment would lose it all); 65 507 bytes on
    /// loopback.
    pub max_datagram: usize,
    /// Largest sample accepted, in encoded bytes.
    pub max_sample: usize,
}

impl Limits {
    /// The limits for a data socket bound to `interface`.
    pub fn for_interface(interface: Ipv4Addr) -> Self {
        Limits {
            max_datagram: datagram_size(interface),
            max_sample: DEFAULT_MAX_SAMPLE,
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

/// The sending side of the data socket, shared by the participant's producers and consumers.
#[derive(Debug)]
pub(crate) struct Net {
    socket: UdpSocket,
    pub(crate) domain: u16,
    pub(crate) participant: u64,
    pub(crate) limits: Limits,
    /// What the participant's endpoints refused to believe, in total.
    pub(crate) unbelieved: Unbelieved,
}

/// Traffic from senders discovery did not match, summed over the participant's endpoints.
#[derive(Debug, Default)]
pub(crate) struct Unbelieved {
    /// From a sender never matched.
    pub(crate) unmatched: AtomicU64,
    /// From a matched sender's id, at another address.
    pub(crate) wrong_address: AtomicU64,
}

impl Unbelieved {
    /// Adds what an endpoint's admission counted between `before` and `after`.
    pub(crate) fn add(&self, before: AdmissionStats, after: AdmissionStats) {
        let unmatched = after.unmatched.saturating_sub(before.unmatched);
        let wrong = after.wrong_address.saturating_sub(before.wrong_address);
        if unmatched > 0 {
            self.unmatched.fetch_add(unmatched, Ordering::Relaxed);
        }
        if wrong > 0 {
            self.wrong_address.fetch_add(wrong, Ordering::Relaxed);
        }
    }
}

impl Net {
    pub(crate) fn new(socket: UdpSocket, domain: u16, participant: u64, limits: Limits) -> Self {
        Net {
            socket,
            domain,
            participant,
            limits,
            unbelieved: Unbelieved::default(),
        }
    }

    /// Sends one datagram; a full socket buffer is retried briefly rather than dropped.
    pub(crate) fn send(&self, bytes: &[u8], to: SocketAddrV4) -> io::Result<()> {
        self.send_parts(bytes, &[], to)
    }

    /// Sends one datagram made of `head` followed by `tail`, gathered by the kernel (the tail,
    /// a sample's payload, is not copied into a buffer first).
    pub(crate) fn send_parts(&self, head: &[u8], tail: &[u8], to: SocketAddrV4) -> io::Result<()> {
        let socket = socket2::SockRef::from(&self.socket);
        let address = socket2::SockAddr::from(to);
        let parts = [io::IoSlice::new(head), io::IoSlice::new(tail)];
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
                    if err.kind() == io::ErrorKind::WouldBlock
                        || err.raw_os_error() == Some(105) =>
                {
                    // ENOBUFS (105) or a full buffer: give the kernel a moment.
                    attempts += 1;
                    if attempts > 100 {
                        return Err(err);
                    }
                    std::thread::yield_now();
                }
                Err(err) => return Err(err),
            }
        }
    }
}

//! The raw-UDP baseline: the same four modes over plain UDP sockets on loopback, with no
//! ndds in the path: one datagram per sample (a sample larger than a datagram is cut into
//! datagrams of at most [`MAX_CHUNK`] payload bytes), sent with one `sendmsg` each.
//!
//! Every datagram starts with a 24-byte header, all little-endian:
//! ```text
//! 0        8          16      20      24
//! | seq u64 | sent_ns u64 | index u32 | count u32 | payload chunk ... |
//! ```
//! `count` is the number of datagrams of the sample and `index` this one's place among them.
//! `count` 0 marks control datagrams: `index` 0 is the end marker a ping sends to its pong when
//! it is done, `index` 1 the probe a publisher sends until the subscriber echoes it (raw UDP
//! has no discovery: this is how the publisher knows the subscriber listens).

mod latency;
mod stream;

use std::io::{self, IoSlice};
use std::net::{SocketAddrV4, UdpSocket};
use std::time::Duration;

use anyhow::Context as _;

pub use latency::{ping, pong};
pub use stream::{publish, subscribe};

/// Header bytes before each chunk.
pub const HEADER: usize = 24;
/// Largest payload chunk of one datagram: the largest UDP payload less the header.
pub const MAX_CHUNK: usize = 65_507 - HEADER;
/// Socket buffer sizes asked for (the same as an ndds data socket).
const SOCKET_BUFFER: usize = 8 * 1024 * 1024;
/// Interval between a publisher's probes.
const PROBE_RETRY: Duration = Duration::from_millis(20);

/// The header of one datagram.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Header {
    pub seq: u64,
    pub sent_ns: u64,
    pub index: u32,
    pub count: u32,
}

impl Header {
    pub fn encode(&self) -> [u8; HEADER] {
        let mut bytes = [0u8; HEADER];
        bytes[0..8].copy_from_slice(&self.seq.to_le_bytes());
        bytes[8..16].copy_from_slice(&self.sent_ns.to_le_bytes());
        bytes[16..20].copy_from_slice(&self.index.to_le_bytes());
        bytes[20..24].copy_from_slice(&self.count.to_le_bytes());
        bytes
    }

    /// The header of a datagram, if it is long enough to have one.
    pub fn decode(datagram: &[u8]) -> Option<Header> {
        let field = |at: usize| -> Option<u64> {
            Some(u64::from_le_bytes(
                datagram.get(at..at + 8)?.try_into().ok()?,
            ))
        };
        let word = |at: usize| -> Option<u32> {
            Some(u32::from_le_bytes(
                datagram.get(at..at + 4)?.try_into().ok()?,
            ))
        };
        Some(Header {
            seq: field(0)?,
            sent_ns: field(8)?,
            index: word(16)?,
            count: word(20)?,
        })
    }

    /// The probe of a publisher.
    pub const PROBE: Header = Header {
        seq: 0,
        sent_ns: 0,
        index: 1,
        count: 0,
    };

    /// Whether this is the end marker.
    pub fn is_end(&self) -> bool {
        self.count == 0 && self.index == 0
    }

    /// Whether this is a publisher's probe.
    pub fn is_probe(&self) -> bool {
        self.count == 0 && self.index == 1
    }
}

/// Number of datagrams a sample of `size` bytes takes.
pub fn chunk_count(size: usize) -> u32 {
    u32::try_from(size.div_ceil(MAX_CHUNK).max(1)).unwrap_or(u32::MAX)
}

/// Binds a UDP socket on `addr` (port 0: any) with large buffers.
pub fn bind(addr: SocketAddrV4) -> anyhow::Result<UdpSocket> {
    let socket = UdpSocket::bind(addr).with_context(|| format!("cannot bind UDP {addr}"))?;
    let sock = socket2::SockRef::from(&socket);
    let _ = sock.set_recv_buffer_size(SOCKET_BUFFER);
    let _ = sock.set_send_buffer_size(SOCKET_BUFFER);
    Ok(socket)
}

/// Sends a sample on a connected socket: one datagram per chunk, header and chunk gathered
/// by the kernel (no copy here).
pub fn send_sample(socket: &UdpSocket, seq: u64, sent_ns: u64, payload: &[u8]) -> io::Result<()> {
    let count = chunk_count(payload.len());
    let sock = socket2::SockRef::from(socket);
    let mut chunks = payload.chunks(MAX_CHUNK);
    for index in 0..count {
        let chunk = chunks.next().unwrap_or(&[]);
        let header = Header {
            seq,
            sent_ns,
            index,
            count,
        }
        .encode();
        send_retrying(|| sock.send_vectored(&[IoSlice::new(&header), IoSlice::new(chunk)]))?;
    }
    Ok(())
}

/// Tells the peer that this run is over (sent a few times: datagrams may be lost).
pub fn send_end(socket: &UdpSocket) {
    let end = Header::default().encode();
    for _ in 0..3 {
        let _ = socket.send(&end);
    }
}

/// Probes the peer of a connected socket until it echoes the probe, for up to `wait`.
pub fn await_listener(socket: &UdpSocket, wait: Duration) -> anyhow::Result<()> {
    let deadline = crate::seconds::deadline(wait);
    let probe = Header::PROBE.encode();
    let mut answer = [0u8; HEADER];
    socket.set_read_timeout(Some(PROBE_RETRY))?;
    loop {
        // A refusal (nobody bound yet) shows as an error of the send or of the receive.
        let _ = socket.send(&probe);
        match socket.recv(&mut answer) {
            Ok(len) if Header::decode(&answer[..len]).is_some_and(|h| h.is_probe()) => {
                return Ok(());
            }
            Ok(_) => {}
            Err(err) if err.kind() == io::ErrorKind::ConnectionRefused => {
                std::thread::sleep(PROBE_RETRY);
            }
            Err(err) if timed_out(&err) => {}
            Err(err) => return Err(err.into()),
        }
        if crate::seconds::passed(deadline) {
            anyhow::bail!(
                "no raw-UDP subscriber answered at {} within {} s",
                socket.peer_addr()?,
                wait.as_secs_f64()
            );
        }
    }
}

/// Retries a send the kernel refused for lack of buffer space (as the ndds data plane does).
fn send_retrying(mut send: impl FnMut() -> io::Result<usize>) -> io::Result<()> {
    let mut attempts = 0;
    loop {
        match send() {
            Ok(_) => return Ok(()),
            Err(err)
                if attempts < 100
                    && (err.kind() == io::ErrorKind::WouldBlock
                        || err.raw_os_error() == Some(105)) =>
            {
                attempts += 1;
                std::thread::yield_now();
            }
            Err(err) => return Err(err),
        }
    }
}

/// True for the errors a receive with a timeout returns when nothing came.
pub fn timed_out(err: &io::Error) -> bool {
    matches!(
        err.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}

/// Collects the datagrams of one sample at a time (loopback keeps them in order).
#[derive(Clone, Copy, Debug, Default)]
pub struct Collect {
    seq: u64,
    parts: u32,
    bytes: usize,
}

impl Collect {
    /// Takes one datagram; returns the sample's payload size once its last one is in.
    pub fn take(&mut self, header: &Header, chunk_len: usize) -> Option<usize> {
        if header.seq != self.seq || header.index == 0 {
            *self = Collect {
                seq: header.seq,
                parts: 0,
                bytes: 0,
            };
        }
        self.parts += 1;
        self.bytes += chunk_len;
        (self.parts == header.count && header.index + 1 == header.count).then_some(self.bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_round_trip() {
        let header = Header {
            seq: 7,
            sent_ns: u64::MAX - 1,
            index: 2,
            count: 3,
        };
        assert_eq!(Header::decode(&header.encode()), Some(header));
        assert_eq!(Header::decode(&[0; 23]), None);
        assert!(Header::default().is_end());
    }

    #[test]
    fn large_samples_are_cut_and_collected() {
        assert_eq!(chunk_count(0), 1);
        assert_eq!(chunk_count(MAX_CHUNK), 1);
        assert_eq!(chunk_count(1 << 20), 17);
        let mut collect = Collect::default();
        let head = |seq, index| Header {
            seq,
            sent_ns: 0,
            index,
            count: 3,
        };
        assert_eq!(collect.take(&head(1, 0), 10), None);
        assert_eq!(collect.take(&head(1, 1), 10), None);
        assert_eq!(collect.take(&head(1, 2), 5), Some(25));
        // A sample missing its middle datagram never completes.
        assert_eq!(collect.take(&head(2, 0), 10), None);
        assert_eq!(collect.take(&head(2, 2), 10), None);
    }

    #[test]
    fn a_sample_crosses_a_socket_pair() {
        let a = bind(SocketAddrV4::new(std::net::Ipv4Addr::LOCALHOST, 0)).unwrap();
        let b = bind(SocketAddrV4::new(std::net::Ipv4Addr::LOCALHOST, 0)).unwrap();
        a.connect(b.local_addr().unwrap()).unwrap();
        let payload = crate::cmd::perf::sample::pattern(100_000);
        send_sample(&a, 9, 1, &payload).unwrap();
        let mut buf = vec![0u8; 65_536];
        let mut collect = Collect::default();
        let mut whole = None;
        for _ in 0..2 {
            let len = b.recv(&mut buf).unwrap();
            let header = Header::decode(&buf[..len]).unwrap();
            assert_eq!(header.seq, 9);
            whole = collect.take(&header, len - HEADER);
        }
        assert_eq!(whole, Some(100_000));
    }
}

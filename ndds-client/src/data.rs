//! The data plane of one participant: one UDP socket on the daemon's interface, through which
//! producers send samples directly to consuming processes, and a receive thread that hands
//! each arriving sample to the queues of the consumers it is addressed to.

use std::collections::HashMap;
use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, RwLock};
use std::time::{Duration, SystemTime};

use ndds_core::wire::{self, Data, DropReason, Guid, Locator, MAX_DATAGRAM, Message};

use crate::sample::{RawSample, SampleInfo};
use crate::sync::{read, write};

/// How often the receive thread checks for shutdown when no datagram arrives.
const POLL_INTERVAL: Duration = Duration::from_millis(250);
/// Socket buffer sizes requested.
const SOCKET_BUFFER: usize = 4 * 1024 * 1024;

/// Where a consumer's samples wait for the application.
#[derive(Debug)]
pub(crate) struct ConsumerSlot {
    tx: flume::Sender<RawSample>,
    /// A second receiver, used only to drop the oldest sample when the queue is full.
    oldest: flume::Receiver<RawSample>,
    /// Samples dropped because the application did not keep up.
    pub(crate) overflow: AtomicU64,
    /// Samples queued.
    pub(crate) received: AtomicU64,
}

impl ConsumerSlot {
    /// A slot with room for `depth` samples, and the application's receiver.
    pub(crate) fn new(depth: usize) -> (Arc<Self>, flume::Receiver<RawSample>) {
        let (tx, rx) = flume::bounded(depth.max(1));
        let slot = ConsumerSlot {
            tx,
            oldest: rx.clone(),
            overflow: AtomicU64::new(0),
            received: AtomicU64::new(0),
        };
        (Arc::new(slot), rx)
    }

    /// Queues a sample, dropping the oldest one when full.
    fn push(&self, mut sample: RawSample) {
        // Counted before the sample becomes visible, so a woken reader sees the count.
        self.received.fetch_add(1, Ordering::Relaxed);
        loop {
            match self.tx.try_send(sample) {
                Ok(()) => return,
                Err(flume::TrySendError::Full(back)) => {
                    sample = back;
                    if self.oldest.try_recv().is_ok() {
                        self.overflow.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(flume::TrySendError::Disconnected(_)) => return,
            }
        }
    }
}

/// Counters of the receive path.
#[derive(Debug, Default)]
pub(crate) struct DataStats {
    pub(crate) received: AtomicU64,
    pub(crate) delivered: AtomicU64,
    pub(crate) dropped: [AtomicU64; DropReason::ALL.len()],
    /// Addressed to another participant (e.g. a previous process on the same port).
    pub(crate) misaddressed: AtomicU64,
    /// Addressed to a consumer that no longer exists.
    pub(crate) unknown_reader: AtomicU64,
}

/// A snapshot of a participant's data-socket counters.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ParticipantStats {
    /// Datagrams received on the data socket.
    pub received: u64,
    /// Samples handed to consumer queues.
    pub delivered: u64,
    /// Datagrams addressed to another participant.
    pub misaddressed: u64,
    /// Samples addressed to a consumer that no longer exists.
    pub unknown_reader: u64,
    /// Dropped datagrams by reason name (see `DropReason::name`).
    pub dropped: Vec<(&'static str, u64)>,
}

impl ParticipantStats {
    /// The drop count for one reason name (`"malformed"`, `"other_domain"`, ...).
    pub fn dropped(&self, reason: &str) -> u64 {
        self.dropped
            .iter()
            .find(|(name, _)| *name == reason)
            .map_or(0, |(_, count)| *count)
    }
}

/// The participant's data socket and consumer table.
#[derive(Debug)]
pub(crate) struct DataPlane {
    pub(crate) socket: UdpSocket,
    pub(crate) locator: Locator,
    domain: u16,
    participant: u64,
    consumers: RwLock<HashMap<u32, Arc<ConsumerSlot>>>,
    pub(crate) stats: DataStats,
    closed: AtomicBool,
}

impl DataPlane {
    /// Binds the data socket to `interface` on any free port.
    pub(crate) fn open(interface: Ipv4Addr, domain: u16, participant: u64) -> io::Result<Self> {
        let socket = UdpSocket::bind(SocketAddrV4::new(interface, 0))?;
        socket.set_read_timeout(Some(POLL_INTERVAL))?;
        set_buffers(&socket);
        let locator = match socket.local_addr()? {
            SocketAddr::V4(addr) => Locator::from(addr),
            SocketAddr::V6(_) => return Err(io::Error::other("data socket is not IPv4")),
        };
        Ok(DataPlane {
            socket,
            locator,
            domain,
            participant,
            consumers: RwLock::new(HashMap::new()),
            stats: DataStats::default(),
            closed: AtomicBool::new(false),
        })
    }

    pub(crate) fn snapshot(&self) -> ParticipantStats {
        let load = |counter: &AtomicU64| counter.load(Ordering::Relaxed);
        ParticipantStats {
            received: load(&self.stats.received),
            delivered: load(&self.stats.delivered),
            misaddressed: load(&self.stats.misaddressed),
            unknown_reader: load(&self.stats.unknown_reader),
            dropped: DropReason::ALL
                .iter()
                .map(|reason| (reason.name(), load(&self.stats.dropped[reason.index()])))
                .collect(),
        }
    }

    pub(crate) fn add_consumer(&self, entity: u32, slot: Arc<ConsumerSlot>) {
        write(&self.consumers).insert(entity, slot);
    }

    pub(crate) fn remove_consumer(&self, entity: u32) {
        write(&self.consumers).remove(&entity);
    }

    /// Receives until [`DataPlane::close`]. Runs on its own thread.
    pub(crate) fn run(&self) {
        let mut buf = vec![0u8; MAX_DATAGRAM + 1];
        while !self.closed.load(Ordering::Acquire) {
            match self.socket.recv_from(&mut buf) {
                Ok((len, _from)) => self.on_datagram(&buf[..len]),
                Err(err)
                    if matches!(
                        err.kind(),
                        io::ErrorKind::WouldBlock
                            | io::ErrorKind::TimedOut
                            | io::ErrorKind::Interrupted
                    ) => {}
                Err(err) => {
                    tracing::debug!(%err, "data receive error");
                    std::thread::sleep(Duration::from_millis(10));
                }
            }
        }
    }

    /// Stops the receive thread promptly by waking it with an empty datagram.
    pub(crate) fn close(&self) {
        self.closed.store(true, Ordering::Release);
        let _ = self.socket.send_to(&[], SocketAddrV4::from(self.locator));
    }

    fn on_datagram(&self, bytes: &[u8]) {
        if self.closed.load(Ordering::Acquire) {
            return;
        }
        self.stats.received.fetch_add(1, Ordering::Relaxed);
        match wire::decode_for_domain(bytes, self.domain) {
            Ok((header, Message::Data(data))) => self.deliver(header.sender, data),
            Ok(_) => self.count_drop(DropReason::Unexpected),
            Err(reason) => self.count_drop(reason),
        }
    }

    fn count_drop(&self, reason: DropReason) {
        self.stats.dropped[reason.index()].fetch_add(1, Ordering::Relaxed);
    }

    fn deliver(&self, sender: u64, data: Data<'_>) {
        if data.reader_participant != self.participant {
            self.stats.misaddressed.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let info = SampleInfo {
            writer: Guid {
                participant: sender,
                entity: data.writer,
            },
            seq: data.seq,
            source_timestamp: SystemTime::UNIX_EPOCH + Duration::from_nanos(data.timestamp_ns),
            reception_timestamp: SystemTime::now(),
            strength: data.strength,
        };
        // Each reader once, however often the datagram names it; one copy of the payload for
        // all of them.
        let mut readers = data.readers.into_owned();
        readers.sort_unstable();
        readers.dedup();
        let payload: Arc<[u8]> = Arc::from(data.payload);
        let consumers = read(&self.consumers);
        for reader in &readers {
            match consumers.get(reader) {
                Some(slot) => {
                    // Counted first: a reader woken by the push sees the count.
                    self.stats.delivered.fetch_add(1, Ordering::Relaxed);
                    slot.push(RawSample {
                        payload: payload.clone(),
                        info,
                    });
                }
                None => {
                    self.stats.unknown_reader.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }
}

fn set_buffers(socket: &UdpSocket) {
    let sock = socket2::SockRef::from(socket);
    let _ = sock.set_recv_buffer_size(SOCKET_BUFFER);
    let _ = sock.set_send_buffer_size(SOCKET_BUFFER);
}

//! The data plane of one participant: one UDP socket on the daemon's interface, through which
//! producers send samples directly to consuming processes; a receive thread that offers each
//! arriving sample to the consumers it is addressed to; and a timer thread that runs the
//! consumers' deadlines and minimum-separation windows.

use std::collections::HashMap;
use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, RwLock};
use std::time::{Duration, Instant, SystemTime};

use ndds_core::arbitration::{Incoming, SampleStatus};
use ndds_core::wire::{self, Data, DropReason, Guid, Locator, MAX_DATAGRAM, Message};

use crate::sample::{RawSample, SampleInfo};
use crate::slot::ConsumerSlot;
use crate::sync::{lock, read, write};

/// How often the receive thread checks for shutdown when no datagram arrives.
const POLL_INTERVAL: Duration = Duration::from_millis(250);
/// Socket buffer sizes requested.
const SOCKET_BUFFER: usize = 4 * 1024 * 1024;

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
    /// When the timer thread must next run the consumers' timers.
    timer: Mutex<Option<Instant>>,
    timer_changed: Condvar,
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
            timer: Mutex::new(None),
            timer_changed: Condvar::new(),
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

    /// Runs the consumers' timers until [`DataPlane::close`]. Runs on its own thread.
    pub(crate) fn run_timers(&self) {
        let mut next = lock(&self.timer);
        while !self.closed.load(Ordering::Acquire) {
            let now = Instant::now();
            match *next {
                Some(at) if at <= now => {
                    *next = None;
                    drop(next);
                    let earliest = read(&self.consumers)
                        .values()
                        .filter_map(|slot| slot.timeout(now))
                        .min();
                    next = lock(&self.timer);
                    if let Some(at) = earliest
                        && next.is_none_or(|n| at < n)
                    {
                        *next = Some(at);
                    }
                }
                pending => {
                    let wait =
                        pending.map_or(POLL_INTERVAL, |at| at.saturating_duration_since(now));
                    next = self
                        .timer_changed
                        .wait_timeout(next, wait.min(POLL_INTERVAL))
                        .map(|(guard, _)| guard)
                        .unwrap_or_else(|poison| poison.into_inner().0);
                }
            }
        }
    }

    /// Makes the timer thread run no later than `at`.
    pub(crate) fn schedule(&self, at: Instant) {
        let mut next = lock(&self.timer);
        if next.is_none_or(|n| at < n) {
            *next = Some(at);
            self.timer_changed.notify_one();
        }
    }

    /// Stops the receive and timer threads promptly (the receive thread is woken with an
    /// empty datagram).
    pub(crate) fn close(&self) {
        self.closed.store(true, Ordering::Release);
        self.timer_changed.notify_all();
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
        let writer = Guid {
            participant: sender,
            entity: data.writer,
        };
        let meta = Incoming {
            writer,
            seq: data.seq,
            strength: data.strength,
            persistence: Duration::from_micros(data.persistence_us),
            source_ns: data.timestamp_ns,
        };
        let info = SampleInfo {
            writer,
            seq: data.seq,
            source_timestamp: SystemTime::UNIX_EPOCH + Duration::from_nanos(data.timestamp_ns),
            reception_timestamp: SystemTime::now(),
            strength: data.strength,
            status: SampleStatus::Fresh,
        };
        // Each reader once, however often the datagram names it; one copy of the payload for
        // all of them.
        let mut readers = data.readers.into_owned();
        readers.sort_unstable();
        readers.dedup();
        let payload: Arc<[u8]> = Arc::from(data.payload);
        let now = Instant::now();
        let consumers = read(&self.consumers);
        for reader in &readers {
            let Some(slot) = consumers.get(reader) else {
                self.stats.unknown_reader.fetch_add(1, Ordering::Relaxed);
                continue;
            };
            self.stats.delivered.fetch_add(1, Ordering::Relaxed);
            let sample = RawSample {
                payload: payload.clone(),
                info,
            };
            if let Some(at) = slot.offer(now, meta, sample) {
                self.schedule(at);
            }
        }
    }
}

fn set_buffers(socket: &UdpSocket) {
    let sock = socket2::SockRef::from(socket);
    let _ = sock.set_recv_buffer_size(SOCKET_BUFFER);
    let _ = sock.set_send_buffer_size(SOCKET_BUFFER);
}

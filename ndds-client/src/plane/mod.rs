//! The data plane of one participant: one UDP socket on the daemon's interface, through which
//! producers send samples directly to consuming processes and consumers send feedback to
//! reliable producers; a receive thread that hands each arriving datagram to the consumers
//! and producers it is for; and a timer thread that runs the endpoints' timers (deadlines,
//! separation windows, batch flushes, heartbeats, repair requests).

mod net;
mod receive;

use std::collections::HashMap;
use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, RwLock};
use std::time::{Duration, Instant};

use ndds_core::wire::{DropReason, FeedbackSub, Guid, Locator};

pub(crate) use net::Net;
pub use net::{DEFAULT_MAX_SAMPLE, Limits};
pub(crate) use receive::Origin;

use crate::slot::ConsumerSlot;
use crate::sync::{lock, read, write};

/// How often the threads check for shutdown when nothing happens.
const POLL_INTERVAL: Duration = Duration::from_millis(250);
/// Socket buffer sizes requested.
const SOCKET_BUFFER: usize = 8 * 1024 * 1024;
/// Receive buffer per datagram: one byte more than the largest datagram, so an oversized
/// one is seen as such.
const RECV_SIZE: usize = ndds_core::wire::MAX_DATAGRAM + 1;

thread_local! {
    /// Set on a participant's receive and timer threads.
    static PLANE_THREAD: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// True on a participant's receive or timer thread (where direct callbacks run).
pub(crate) fn on_plane_thread() -> bool {
    PLANE_THREAD.with(std::cell::Cell::get)
}

/// An endpoint with timers, run by the participant's timer thread.
pub(crate) trait Timed: Send + Sync + std::fmt::Debug {
    /// Runs what is due at `now`; returns when to run next.
    fn timeout(&self, now: Instant) -> Option<Instant>;
}

/// A producer, as the receive thread sees it: it takes feedback from reliable consumers.
pub(crate) trait WriterSide: Timed {
    /// Acknowledgements and repair requests from reader `reader` (sent from `from`); returns
    /// when the writer's timers must run next, if that changed.
    fn on_feedback(
        &self,
        now: Instant,
        reader: Guid,
        from: SocketAddrV4,
        sub: &FeedbackSub<'_>,
    ) -> Option<Instant>;
}

/// Counters of the data socket.
#[derive(Debug, Default)]
pub(crate) struct DataStats {
    pub(crate) received: AtomicU64,
    pub(crate) delivered: AtomicU64,
    pub(crate) dropped: [AtomicU64; DropReason::ALL.len()],
    /// Addressed to another participant (e.g. a previous process on the same port).
    pub(crate) misaddressed: AtomicU64,
    /// Addressed to a consumer that no longer exists.
    pub(crate) unknown_reader: AtomicU64,
    /// Fragments refused by reassembly (inconsistent, too large, over budget).
    pub(crate) fragments_refused: AtomicU64,
}

/// A snapshot of a participant's data-socket counters.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ParticipantStats {
    /// Datagrams received on the data socket.
    pub received: u64,
    /// Samples handed to consumers (before arbitration).
    pub delivered: u64,
    /// Datagrams addressed to another participant.
    pub misaddressed: u64,
    /// Samples addressed to a consumer that no longer exists.
    pub unknown_reader: u64,
    /// Fragments of large samples refused by reassembly.
    pub fragments_refused: u64,
    /// Samples, heartbeats, gaps and feedback dropped because discovery never matched their
    /// sender with the endpoint they address (forged, or from an endpoint gone long ago).
    pub unmatched_sender: u64,
    /// Dropped because they carried a matched sender's id but came from another address.
    pub wrong_address: u64,
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

/// The participant's data socket, endpoint tables and timer.
#[derive(Debug)]
pub(crate) struct DataPlane {
    socket: UdpSocket,
    pub(crate) net: Arc<Net>,
    pub(crate) locator: Locator,
    consumers: RwLock<HashMap<u32, Arc<ConsumerSlot>>>,
    writers: RwLock<HashMap<u32, Arc<dyn WriterSide>>>,
    reassembly: receive::Reassembly,
    pub(crate) stats: DataStats,
    closed: AtomicBool,
    pub(crate) timer: Arc<Timer>,
}

/// When the timer thread must next run the endpoints' timers; anyone may bring it forward.
#[derive(Debug, Default)]
pub(crate) struct Timer {
    next: Mutex<Option<Instant>>,
    changed: Condvar,
}

impl Timer {
    /// Makes the timer thread run no later than `at`.
    pub(crate) fn schedule(&self, at: Instant) {
        let mut next = lock(&self.next);
        if next.is_none_or(|n| at < n) {
            *next = Some(at);
            self.changed.notify_one();
        }
    }
}

impl DataPlane {
    /// Binds the data socket to `interface` on any free port.
    pub(crate) fn open(
        interface: Ipv4Addr,
        domain: u16,
        participant: u64,
        limits: Limits,
    ) -> io::Result<Self> {
        let socket = UdpSocket::bind(SocketAddrV4::new(interface, 0))?;
        socket.set_read_timeout(Some(POLL_INTERVAL))?;
        set_buffers(&socket);
        let locator = match socket.local_addr()? {
            SocketAddr::V4(addr) => Locator::from(addr),
            SocketAddr::V6(_) => return Err(io::Error::other("data socket is not IPv4")),
        };
        let net = Net::new(socket.try_clone()?, domain, participant, limits);
        Ok(DataPlane {
            socket,
            net: Arc::new(net),
            locator,
            consumers: RwLock::new(HashMap::new()),
            writers: RwLock::new(HashMap::new()),
            reassembly: receive::Reassembly::new(limits),
            stats: DataStats::default(),
            closed: AtomicBool::new(false),
            timer: Arc::new(Timer::default()),
        })
    }

    pub(crate) fn snapshot(&self) -> ParticipantStats {
        let load = |counter: &AtomicU64| counter.load(Ordering::Relaxed);
        ParticipantStats {
            received: load(&self.stats.received),
            delivered: load(&self.stats.delivered),
            misaddressed: load(&self.stats.misaddressed),
            unknown_reader: load(&self.stats.unknown_reader),
            fragments_refused: load(&self.stats.fragments_refused),
            unmatched_sender: load(&self.net.unbelieved.unmatched),
            wrong_address: load(&self.net.unbelieved.wrong_address),
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

    pub(crate) fn add_writer(&self, entity: u32, writer: Arc<dyn WriterSide>) {
        write(&self.writers).insert(entity, writer);
    }

    pub(crate) fn remove_writer(&self, entity: u32) {
        write(&self.writers).remove(&entity);
    }

    /// Receives until [`DataPlane::close`]. Runs on its own thread.
    pub(crate) fn run(&self) {
        PLANE_THREAD.with(|t| t.set(true));
        let socket = socket2::SockRef::from(&self.socket);
        let mut buf = bytes::BytesMut::new();
        while !self.closed.load(Ordering::Acquire) {
            // Reuses the allocation once every sample cut from it has been dropped.
            buf.reserve(RECV_SIZE);
            let received = socket.recv_from(&mut buf.spare_capacity_mut()[..RECV_SIZE]);
            match received {
                Ok((len, from)) => {
                    // SAFETY: `recv_from` initialised the first `len` bytes of the spare
                    // capacity it was given.
                    unsafe { buf.set_len(len) };
                    let datagram = buf.split_to(len).freeze();
                    if let Some(from) = from.as_socket_ipv4() {
                        self.on_datagram(datagram, from);
                    }
                }
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

    /// Runs the endpoints' timers until [`DataPlane::close`]. Runs on its own thread.
    pub(crate) fn run_timers(&self) {
        PLANE_THREAD.with(|t| t.set(true));
        let timer = &self.timer;
        let mut next = lock(&timer.next);
        while !self.closed.load(Ordering::Acquire) {
            let now = Instant::now();
            match *next {
                Some(at) if at <= now => {
                    *next = None;
                    drop(next);
                    let earliest = self.fire(now);
                    next = lock(&timer.next);
                    if let Some(at) = earliest
                        && next.is_none_or(|n| at < n)
                    {
                        *next = Some(at);
                    }
                }
                pending => {
                    let wait =
                        pending.map_or(POLL_INTERVAL, |at| at.saturating_duration_since(now));
                    next = timer
                        .changed
                        .wait_timeout(next, wait.min(POLL_INTERVAL))
                        .map(|(guard, _)| guard)
                        .unwrap_or_else(|poison| poison.into_inner().0);
                }
            }
        }
    }

    /// Runs every endpoint's due timers; returns the earliest next one.
    fn fire(&self, now: Instant) -> Option<Instant> {
        let consumers: Vec<Arc<ConsumerSlot>> = read(&self.consumers).values().cloned().collect();
        let writers: Vec<Arc<dyn WriterSide>> = read(&self.writers).values().cloned().collect();
        let mut earliest = self.reassembly.timeout(now, &self.net);
        for at in consumers
            .iter()
            .filter_map(|slot| slot.timeout(now))
            .chain(writers.iter().filter_map(|w| w.timeout(now)))
        {
            earliest = Some(earliest.map_or(at, |e: Instant| e.min(at)));
        }
        earliest
    }

    /// Makes the timer thread run no later than `at`.
    pub(crate) fn schedule(&self, at: Instant) {
        self.timer.schedule(at);
    }

    /// Stops the receive and timer threads promptly (the receive thread is woken with an
    /// empty datagram).
    pub(crate) fn close(&self) {
        self.closed.store(true, Ordering::Release);
        self.timer.changed.notify_all();
        let _ = self.socket.send_to(&[], SocketAddrV4::from(self.locator));
    }

    fn count_drop(&self, reason: DropReason) {
        self.stats.dropped[reason.index()].fetch_add(1, Ordering::Relaxed);
    }
}

fn set_buffers(socket: &UdpSocket) {
    let sock = socket2::SockRef::from(socket);
    let _ = sock.set_recv_buffer_size(SOCKET_BUFFER);
    let _ = sock.set_send_buffer_size(SOCKET_BUFFER);
}

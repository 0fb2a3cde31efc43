//! The driver of one participant's data plane. The protocol — every producer's and
//! consumer's state, arbitration, reliability, batching, fragments, who is believed — is
//! `ndds_core::participant::ParticipantCore`, without IO. This module gives it a UDP socket
//! on the daemon's interface, the clock, and one I/O thread (`ndds-io`) that waits for
//! datagrams with the core's next timer as its timeout, hands them to the core, runs its
//! timers, and moves the events it produces to the consumers' queues.
//!
//! The core sits behind one mutex, held only while it changes state: datagrams are received
//! before it is taken and sent after it is released, samples are encoded before (by the
//! producer's handle, into a pooled buffer), and no user code ever runs under it. An
//! application thread that writes sends its own datagrams, so a write costs no thread
//! switch (unless another thread is sending at that moment: that one sends them next, so
//! that datagrams leave in the core's order; see `Outgoing`); when a command moves the core's next timer earlier than the I/O thread's wake-up,
//! or leaves events for it, the I/O thread is woken by an empty datagram to its own socket.
//! The thread waits in a blocking receive while its next timer is far (one system call per
//! datagram, as a plain UDP receiver), in `ppoll` while it is near.

mod socket;

use std::cell::RefCell;
use std::collections::{HashMap, VecDeque};
use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::os::fd::AsRawFd;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, RwLock};
use std::time::{Duration, Instant, SystemTime};

use bytes::BytesMut;
use ndds_core::arbitration::Notification;
use ndds_core::participant::{
    ConsumerCounters, ConsumerSpec, CoreConfig, Event, MatchedConsumer, ParticipantCore,
    ProducerSpec, SealSetup, Transmit, WriteRefused,
};
use ndds_core::seal::OpenError;
use ndds_core::wire::{DropReason, Guid, Locator};

pub use socket::{DEFAULT_MAX_SAMPLE, DEFAULT_SOCKET_BUFFER, Limits};

use crate::consumer::Delivery;
use crate::error::WriteError;
use crate::sample::RawEvent;
use crate::sync::{lock, read, write};

/// Receive buffer per datagram: one byte more than the largest datagram, so an oversized
/// one is seen as such.
const RECV_SIZE: usize = ndds_core::wire::MAX_DATAGRAM + 1;
/// The receive buffer's regions: datagrams are received one after another into a region,
/// so the samples the application keeps share a few regions instead of each pinning a buffer
/// of the largest datagram's size; a region is reused once nothing cut from it is alive.
const RECV_REGION: usize = 4 * RECV_SIZE;
/// Bytes of datagrams received before the core is taken to handle them (bounds the events
/// one round produces).
const RECV_BATCH_BYTES: usize = 32 * 1024;
/// Datagrams received before the core is taken to handle them together.
const RECV_BATCH: usize = 32;
/// How long a callback waiting for a window sleeps before it looks for other callbacks to run.
const HELP_WAIT: Duration = Duration::from_millis(1);
/// The I/O thread waits in a blocking receive when its next timer is at least this far
/// away (one system call per datagram, the receive timeout only as precise as the kernel's
/// tick), and in `ppoll` (precise to the microsecond) when it is closer.
const PRECISE_BELOW: Duration = Duration::from_millis(5);

thread_local! {
    /// Set on a participant's I/O thread.
    static IO_THREAD: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// Set on the I/O thread when a command it gave (from a direct callback) left the core
    /// work: events, or a timer earlier than the one the thread is about to wait for.
    static IO_DIRTY: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// Datagrams this thread took from a core and sent (and which core: its address); their
    /// buffers go back to that core the next time this thread holds it, so sending allocates
    /// nothing.
    static SENT: RefCell<(usize, Vec<Transmit>)> = const { RefCell::new((0, Vec::new())) };
}

/// True on a participant's I/O thread (where direct callbacks run).
pub(crate) fn on_io_thread() -> bool {
    IO_THREAD.with(std::cell::Cell::get)
}

/// A snapshot of a participant's data-plane counters.
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
    /// Feedback from a matched consumer's address that did not echo the address token of
    /// this participant's data there (forged with that address): not acted on, but for
    /// pieces within 3 times its bytes.
    pub unvalidated_feedback: u64,
    /// Pieces such feedback asked for and did not get.
    pub pieces_withheld: u64,
    /// Dropped datagrams by reason name (see `DropReason::name`).
    pub dropped: Vec<(&'static str, u64)>,
    /// Datagrams sent.
    pub sent: u64,
    /// Datagrams the operating system refused to send.
    pub send_errors: u64,
    /// Sealed datagrams that arrived while this participant holds no domain key.
    pub sealed_without_key: u64,
    /// Sealed datagrams opened (a domain with a key).
    pub seal_opened: u64,
    /// Datagrams that did not open, by reason name (see `OpenError::name`): not sealed, bad
    /// tag, replayed, unknown epoch, ...
    pub seal_dropped: Vec<(&'static str, u64)>,
    /// Datagrams not sent because they could not be sealed.
    pub unsealable: u64,
    /// Datagrams not sent because their destination has no data key (a domain with
    /// permissions: the daemon never matched the pair).
    pub unkeyed: u64,
}

impl ParticipantStats {
    /// The count of datagrams that did not open for one reason name (`"bad_tag"`, ...).
    pub fn seal_dropped(&self, reason: &str) -> u64 {
        self.seal_dropped
            .iter()
            .find(|(name, _)| *name == reason)
            .map_or(0, |(_, count)| *count)
    }

    /// The drop count for one reason name (`"malformed"`, `"other_domain"`, ...).
    pub fn dropped(&self, reason: &str) -> u64 {
        self.dropped
            .iter()
            .find(|(name, _)| *name == reason)
            .map_or(0, |(_, count)| *count)
    }
}

/// What the I/O thread needs to know of the local endpoints to hand out events.
#[derive(Debug, Default)]
struct Endpoints {
    consumers: HashMap<u32, Arc<Delivery>>,
    producers: HashMap<u32, Arc<str>>,
}

/// The I/O thread's own copy of the consumers' delivery ends, taken again only when
/// [`DataPlane::consumers_changed`] moved: handing out an event costs no lock and no
/// reference count.
#[derive(Debug, Default)]
struct LocalConsumers {
    generation: u64,
    consumers: HashMap<u32, Arc<Delivery>>,
}

impl LocalConsumers {
    /// Up to date with `plane`'s consumers.
    fn refresh(&mut self, plane: &DataPlane) {
        let generation = plane.consumers_changed.load(Ordering::Acquire);
        if generation == self.generation {
            return;
        }
        let endpoints = read(&plane.endpoints);
        self.consumers.clone_from(&endpoints.consumers);
        self.generation = plane.consumers_changed.load(Ordering::Acquire);
    }
}

/// The core and what the driver keeps beside it, under one lock.
#[derive(Debug)]
struct Locked {
    core: ParticipantCore,
    /// When the I/O thread will next wake by itself (`None`: only for a datagram).
    io_wakes_at: Option<Instant>,
    /// Async writers waiting for a reliable producer's window.
    window_wakers: Vec<std::task::Waker>,
    /// Threads in [`DataPlane::wait_acknowledged`]: while there are any, the I/O thread
    /// signals `window` after each round (acknowledgements that empty a history open no
    /// window, so nothing else would).
    ack_waiters: usize,
}

/// The participant's data socket, its core and its I/O thread.
#[derive(Debug)]
pub(crate) struct DataPlane {
    socket: UdpSocket,
    pub(crate) locator: Locator,
    locked: Mutex<Locked>,
    /// Signalled (with `locked`) when a reliable producer's window may have opened.
    window: Condvar,
    endpoints: RwLock<Endpoints>,
    /// Moved (under `endpoints`' write lock) whenever a consumer is added or removed.
    consumers_changed: AtomicU64,
    /// The data socket's own address: an empty datagram sent there wakes the I/O thread.
    wake_to: SocketAddrV4,
    closed: AtomicBool,
    /// Source timestamps.
    wall: WallClock,
    /// Datagrams sent, and datagrams the operating system refused.
    sent: AtomicU64,
    send_errors: AtomicU64,
    /// Datagrams taken from the core and not sent yet.
    outgoing: Mutex<Outgoing>,
}

/// Datagrams taken from the core, in its order, waiting to be sent. Any thread that released
/// the core may have queued some; the first of them to find nobody sending sends them all,
/// also those the others queue meanwhile, while they go on. So datagrams leave in the order
/// the core made them (a best-effort consumer drops a sample that overtook a later one as old
/// data, and a reliable one asks again for what seems missing), no thread waits for another's
/// system calls, and the core is never held across one. The price: datagrams queued behind
/// another thread's send leave when that thread gets to them, so a high-priority writer that
/// shares a CPU with a lower-priority writer of the same participant can see its datagrams
/// wait until the other runs again (give such writers participants of their own).
#[derive(Debug)]
struct Outgoing {
    queue: VecDeque<Transmit>,
    /// A thread is sending from the queue.
    sending: bool,
}

/// The data socket's receive timeout, set only when the I/O thread's wait needs another
/// one (a system call): never longer than the wait (the thread would sleep through a timer),
/// and lengthened only when it is much shorter (waking early is harmless, just not free).
#[derive(Debug, Default)]
struct ReceiveTimeout {
    set: Option<Option<Duration>>,
}

impl ReceiveTimeout {
    fn set(&mut self, socket: &UdpSocket, wait: Option<Duration>) {
        let fits = match (self.set, wait) {
            (Some(None), None) => true,
            (Some(Some(current)), Some(wait)) => current <= wait && current * 2 > wait,
            _ => false,
        };
        if fits {
            return;
        }
        // Rounded down to a power of two of milliseconds, so a timer drawing nearer changes
        // the timeout once per halving, not at every datagram. (A zero timeout would mean
        // "forever" to the socket; waits that short go to `ppoll`.)
        let timeout = wait.map(|wait| {
            let ms = u64::try_from(wait.as_millis()).unwrap_or(u64::MAX).max(1);
            Duration::from_millis(1 << ms.ilog2())
        });
        if socket.set_read_timeout(timeout).is_ok() {
            self.set = Some(timeout);
        }
    }
}

/// What sending the datagrams of one command came to.
#[derive(Debug, Default)]
struct Sent {
    ok: usize,
    failed: usize,
    last_error: Option<io::Error>,
}

impl DataPlane {
    /// Binds the data socket to `interface` on any free port.
    pub(crate) fn open(
        interface: Ipv4Addr,
        domain: u16,
        participant: u64,
        limits: Limits,
        seal: Option<SealSetup>,
    ) -> io::Result<Self> {
        let socket = UdpSocket::bind(SocketAddrV4::new(interface, 0))?;
        socket::set_buffers(&socket, limits.recv_buffer);
        let locator = match socket.local_addr()? {
            SocketAddr::V4(addr) => Locator::from(addr),
            SocketAddr::V6(_) => return Err(io::Error::other("data socket is not IPv4")),
        };
        let mut core = ParticipantCore::new(CoreConfig {
            max_datagram: limits.max_datagram,
            max_sample: limits.max_sample,
            secret: os_secret(),
            ..CoreConfig::new(domain, participant)
        });
        if let Some(seal) = seal {
            core.seal_with(seal);
        }
        Ok(DataPlane {
            socket,
            locator,
            locked: Mutex::new(Locked {
                core,
                io_wakes_at: None,
                window_wakers: Vec::new(),
                ack_waiters: 0,
            }),
            window: Condvar::new(),
            endpoints: RwLock::default(),
            consumers_changed: AtomicU64::new(0),
            wake_to: SocketAddrV4::from(locator),
            closed: AtomicBool::new(false),
            wall: WallClock::new(),
            sent: AtomicU64::new(0),
            send_errors: AtomicU64::new(0),
            outgoing: Mutex::new(Outgoing {
                // Room for a burst, so a steady state does not grow it.
                queue: VecDeque::with_capacity(256),
                sending: false,
            }),
        })
    }

    /// Takes the core: first hands back the buffers this thread sent since it last held it.
    fn lock(&self) -> MutexGuard<'_, Locked> {
        let mut locked = lock(&self.locked);
        self.recycle_sent(&mut locked);
        locked
    }

    /// Hands the buffers this thread sent back to the core.
    fn recycle_sent(&self, locked: &mut Locked) {
        SENT.with(|sent| {
            if let Ok(mut sent) = sent.try_borrow_mut() {
                let (owner, sent) = &mut *sent;
                if *owner == self.id() {
                    for transmit in sent.drain(..) {
                        locked.core.recycle(transmit);
                    }
                } else {
                    // Another participant's buffers: freed, not mixed into this core's.
                    sent.clear();
                }
            }
        });
    }

    /// This data plane's identity for the thread-local list of sent buffers.
    fn id(&self) -> usize {
        std::ptr::from_ref(self) as usize
    }

    /// Releases the core after a command: wakes the I/O thread if the command left it work
    /// (events, or a timer earlier than its wake-up), then sends the datagrams the command
    /// produced, outside the lock and in the core's order (see [`Outgoing`]).
    fn release(&self, mut locked: MutexGuard<'_, Locked>) -> Sent {
        let core = &mut locked.core;
        let wake = core.has_events()
            || core
                .poll_timeout()
                .is_some_and(|at| locked.io_wakes_at.is_none_or(|wakes| at < wakes));
        if wake {
            if on_io_thread() {
                IO_DIRTY.with(|dirty| dirty.set(true));
            } else {
                // Told once: the I/O thread recomputes its wake-up when it runs.
                locked.io_wakes_at = Some(Instant::now());
            }
        }
        let mut result = Sent::default();
        let mut local = Vec::new();
        SENT.with(|sent| {
            let mut borrowed = sent.try_borrow_mut().ok();
            let sent = match borrowed.as_deref_mut() {
                Some((owner, sent)) => {
                    if *owner != self.id() {
                        sent.clear();
                        *owner = self.id();
                    }
                    if sent.capacity() == 0 {
                        sent.reserve(256);
                    }
                    sent
                }
                // Never expected (nothing here calls back into a core), but then the
                // buffers are simply freed.
                None => &mut local,
            };
            // Taken while the core is held, so they follow everything taken before them.
            // With nobody sending (the queue is then empty), this thread sends them itself,
            // straight from its list; otherwise they join the queue for the thread that is.
            let first = sent.len();
            let sender = {
                let mut outgoing = lock(&self.outgoing);
                if outgoing.sending {
                    while let Some(transmit) = locked.core.poll_transmit() {
                        outgoing.queue.push_back(transmit);
                    }
                    false
                } else {
                    while let Some(transmit) = locked.core.poll_transmit() {
                        sent.push(transmit);
                    }
                    outgoing.sending = sent.len() > first;
                    outgoing.sending
                }
            };
            drop(locked);
            if wake && !on_io_thread() {
                self.wake_io();
            }
            if sender {
                self.send_outgoing(sent, first, &mut result);
            }
        });
        result
    }

    /// Sends `sent[first..]`, then what the other threads queued in [`DataPlane::outgoing`]
    /// meanwhile, until it is empty; called by the one thread that set its `sending`.
    fn send_outgoing(&self, sent: &mut Vec<Transmit>, mut first: usize, result: &mut Sent) {
        loop {
            for transmit in &mut sent[first..] {
                match socket::send(&self.socket, transmit) {
                    Ok(()) => result.ok += 1,
                    Err(err) => {
                        tracing::debug!(to = %transmit.to, %err, "data send failed");
                        result.failed += 1;
                        result.last_error = Some(err);
                    }
                }
                // The payload goes back to its producer's pool now, not at the next lock.
                transmit.release_tail();
            }
            first = sent.len();
            let mut outgoing = lock(&self.outgoing);
            if outgoing.queue.is_empty() {
                outgoing.sending = false;
                return;
            }
            sent.extend(outgoing.queue.drain(..));
        }
    }

    /// Runs `command` on the core, then [`DataPlane::release`].
    fn command<R>(&self, command: impl FnOnce(&mut ParticipantCore, Instant) -> R) -> R {
        let mut locked = self.lock();
        let result = command(&mut locked.core, Instant::now());
        self.count(&self.release(locked));
        result
    }

    fn count(&self, sent: &Sent) {
        if sent.ok > 0 {
            self.sent.fetch_add(sent.ok as u64, Ordering::Relaxed);
        }
        if sent.failed > 0 {
            self.send_errors
                .fetch_add(sent.failed as u64, Ordering::Relaxed);
        }
    }

    pub(crate) fn snapshot(&self) -> ParticipantStats {
        let locked = lock(&self.locked);
        let stats = locked.core.stats();
        ParticipantStats {
            received: stats.received,
            delivered: stats.delivered,
            misaddressed: stats.misaddressed,
            unknown_reader: stats.unknown_reader,
            fragments_refused: stats.fragments_refused,
            unmatched_sender: stats.unmatched_sender,
            wrong_address: stats.wrong_address,
            unvalidated_feedback: stats.unvalidated_feedback,
            pieces_withheld: stats.pieces_withheld,
            dropped: DropReason::ALL
                .iter()
                .map(|reason| (reason.name(), stats.dropped(*reason)))
                .collect(),
            sent: self.sent.load(Ordering::Relaxed),
            send_errors: self.send_errors.load(Ordering::Relaxed),
            sealed_without_key: stats.sealed_without_key,
            seal_opened: stats.seal.opened,
            seal_dropped: OpenError::ALL
                .iter()
                .map(|reason| (reason.name(), stats.seal.dropped(*reason)))
                .collect(),
            unsealable: stats.unsealable,
            unkeyed: stats.unkeyed,
        }
    }

    // ---- consumers ----

    pub(crate) fn add_consumer(&self, entity: u32, spec: ConsumerSpec, delivery: Arc<Delivery>) {
        // Known to the I/O thread before the core can produce an event for it (the core's
        // lock orders the two).
        {
            let mut endpoints = write(&self.endpoints);
            endpoints.consumers.insert(entity, delivery);
            self.consumers_changed.fetch_add(1, Ordering::AcqRel);
        }
        self.command(|core, now| core.add_consumer(now, entity, spec));
    }

    pub(crate) fn remove_consumer(&self, entity: u32) {
        self.command(|core, _| core.remove_consumer(entity));
        {
            let mut endpoints = write(&self.endpoints);
            endpoints.consumers.remove(&entity);
            self.consumers_changed.fetch_add(1, Ordering::AcqRel);
        }
        // The I/O thread lets go of its copy of the delivery end (and of the samples queued
        // there) at its next round: one now.
        if on_io_thread() {
            IO_DIRTY.with(|dirty| dirty.set(true));
        } else {
            self.wake_io();
        }
    }

    pub(crate) fn set_consumer_matched(
        &self,
        entity: u32,
        producers: impl IntoIterator<Item = (Guid, SocketAddrV4)>,
    ) {
        self.command(|core, now| core.set_consumer_matched(now, entity, producers));
    }

    pub(crate) fn producer_lost(&self, entity: u32, writer: Guid) {
        self.command(|core, now| core.producer_lost(now, entity, writer));
    }

    /// The domain has permissions: data goes to, and comes from, peers with data keys only.
    pub(crate) fn require_pair_keys(&self) -> bool {
        self.command(|core, _| core.require_pair_keys())
    }

    /// The data keys of this participant's pair with `peer` (its data socket `at`).
    pub(crate) fn set_pair_keys(
        &self,
        peer: u64,
        at: SocketAddrV4,
        keys: &ndds_core::security::DataKeys,
    ) -> bool {
        self.command(|core, now| core.set_pair_keys(now, peer, at, keys))
    }

    /// A rotation step: seals with `keyring`'s sending key and accepts its keys only.
    pub(crate) fn set_keyring(&self, keyring: ndds_core::seal::Keyring) {
        self.command(|core, _| core.set_keyring(keyring));
    }

    /// True once the participant closed its data plane.
    pub(crate) fn is_closed(&self) -> bool {
        self.closed.load(Ordering::Acquire)
    }

    pub(crate) fn notify(&self, entity: u32, notification: Notification) {
        self.command(|core, _| core.notify(entity, notification));
    }

    /// The application took `samples` samples of a reliable consumer.
    pub(crate) fn taken(&self, entity: u32, samples: usize) {
        self.command(|core, now| core.taken(now, entity, samples));
    }

    pub(crate) fn set_unlimited(&self, entity: u32) {
        self.command(|core, now| core.set_unlimited(now, entity));
    }

    pub(crate) fn consumer_counters(&self, entity: u32) -> ConsumerCounters {
        lock(&self.locked)
            .core
            .consumer_counters(entity)
            .unwrap_or_default()
    }

    // ---- producers ----

    pub(crate) fn add_producer(&self, entity: u32, spec: ProducerSpec, topic: &str) {
        write(&self.endpoints)
            .producers
            .insert(entity, Arc::from(topic));
        self.command(|core, _| core.add_producer(entity, spec));
    }

    pub(crate) fn remove_producer(&self, entity: u32) {
        self.command(|core, _| core.remove_producer(entity));
        write(&self.endpoints).producers.remove(&entity);
        // A writer waiting for its window must see that the producer is gone.
        self.wake_writers();
    }

    pub(crate) fn set_producer_matched(&self, entity: u32, consumers: &[MatchedConsumer]) {
        self.command(|core, now| core.set_producer_matched(now, entity, consumers));
        self.wake_writers();
    }

    /// Wakes every writer waiting for a window, blocking or async.
    fn wake_writers(&self) {
        self.window.notify_all();
        let wakers = std::mem::take(&mut lock(&self.locked).window_wakers);
        for waker in wakers {
            waker.wake();
        }
    }

    /// Ready when producer `entity` may write without waiting (or is gone); otherwise wakes
    /// `cx` when its window may have opened.
    pub(crate) fn poll_window(&self, entity: u32, cx: &mut std::task::Context<'_>) -> bool {
        let mut locked = lock(&self.locked);
        if locked.core.window_open(entity) || self.closed.load(Ordering::Acquire) {
            return true;
        }
        if !locked.window_wakers.iter().any(|w| w.will_wake(cx.waker())) {
            locked.window_wakers.push(cx.waker().clone());
        }
        false
    }

    /// Writes one encoded sample, waiting up to `timeout` for a reliable producer's window
    /// (never on the I/O thread, where the acknowledgements that would open it arrive).
    pub(crate) fn write(
        &self,
        entity: u32,
        payload: &Arc<Vec<u8>>,
        timeout: Duration,
    ) -> Result<(), WriteError> {
        let mut now = Instant::now();
        let timestamp_ns = self.wall.at(now);
        let mut locked = self.lock();
        let mut started = None;
        loop {
            match locked.core.write(now, timestamp_ns, entity, payload) {
                Ok(_) => break,
                Err(WriteRefused::TooLarge { size, max }) => {
                    return Err(WriteError::TooLarge { size, max });
                }
                Err(WriteRefused::UnknownProducer(_)) => {
                    return Err(WriteError::Io(io::Error::other(
                        "the producer was withdrawn",
                    )));
                }
                Err(WriteRefused::WindowFull { unacknowledged }) => {
                    let started = *started.get_or_insert(now);
                    let waited = now.saturating_duration_since(started);
                    let left = timeout
                        .checked_sub(waited)
                        .filter(|left| !left.is_zero() && !on_io_thread());
                    let Some(left) = left else {
                        return Err(WriteError::WouldBlock {
                            waited,
                            unacknowledged,
                        });
                    };
                    let mut wait = left;
                    if crate::consumer::on_dispatcher_thread() {
                        // A callback waits: the participant's other callbacks run meanwhile
                        // (one of them may be what takes the samples that open the window).
                        drop(locked);
                        let helped = crate::consumer::help_dispatch();
                        locked = self.lock();
                        if helped {
                            continue;
                        }
                        wait = wait.min(HELP_WAIT);
                    }
                    locked = self
                        .window
                        .wait_timeout(locked, wait)
                        .map(|(guard, _)| guard)
                        .unwrap_or_else(|poison| poison.into_inner().0);
                    now = Instant::now();
                }
            }
        }
        let sent = self.release(locked);
        self.count(&sent);
        match sent.last_error {
            // Only when no destination got it (as one unreachable consumer must not fail
            // the write for the others). A write whose datagrams another thread sent learns
            // of no error; the participant's `send_errors` counts it.
            Some(err) if sent.ok == 0 => Err(WriteError::Io(err)),
            _ => Ok(()),
        }
    }

    pub(crate) fn flush(&self, entity: u32) -> Result<(), WriteError> {
        let mut locked = self.lock();
        locked.core.flush(entity);
        let sent = self.release(locked);
        self.count(&sent);
        match sent.last_error {
            Some(err) => Err(WriteError::Io(err)),
            None => Ok(()),
        }
    }

    pub(crate) fn written(&self, entity: u32) -> u64 {
        lock(&self.locked).core.written(entity)
    }

    /// Waits until every reliable consumer acknowledged everything producer `entity` wrote;
    /// false at the timeout.
    pub(crate) fn wait_acknowledged(&self, entity: u32, timeout: Duration) -> bool {
        let deadline = crate::sync::deadline(timeout);
        let mut locked = self.lock();
        locked.ack_waiters += 1;
        let acknowledged = loop {
            if locked.core.unacknowledged(entity) == 0 {
                break true;
            }
            let left = deadline.map_or(Duration::from_secs(3600), |d| {
                d.saturating_duration_since(Instant::now())
            });
            if left.is_zero() {
                break false;
            }
            locked = self
                .window
                .wait_timeout(locked, left)
                .map(|(guard, _)| guard)
                .unwrap_or_else(|poison| poison.into_inner().0);
        };
        locked.ack_waiters -= 1;
        acknowledged
    }

    // ---- the I/O thread ----

    /// Wakes the I/O thread: an empty datagram to its own socket (which ends a blocking
    /// receive as well as a `ppoll`, and costs one system call, like an eventfd).
    fn wake_io(&self) {
        let _ = self.socket.send_to(&[], self.wake_to);
    }

    /// Receives, runs the timers and hands out events until [`DataPlane::close`]. Runs on
    /// its own thread.
    pub(crate) fn run(&self) {
        IO_THREAD.with(|t| t.set(true));
        let mut buf = BytesMut::new();
        let mut batch: Vec<(BytesMut, SocketAddrV4)> = Vec::with_capacity(RECV_BATCH);
        let mut events: VecDeque<Event> = VecDeque::with_capacity(1024);
        let mut credits: Vec<(u32, usize)> = Vec::new();
        let mut local = LocalConsumers::default();
        let mut next: Option<Instant> = None;
        let mut receive_timeout = ReceiveTimeout::default();
        // Whether the last round found more than one datagram waiting: then the socket is
        // drained (until empty, up to a batch) after each wait; otherwise (one datagram at a
        // time, as in a ping-pong) the thread goes back to waiting at once.
        let mut draining = false;
        while !self.closed.load(Ordering::Acquire) {
            let wait = next.map(|at| at.saturating_duration_since(Instant::now()));
            let mut full = match wait {
                Some(wait) if wait < PRECISE_BELOW => {
                    self.poll_readable(wait) && self.receive(&mut buf, &mut batch)
                }
                wait => {
                    receive_timeout.set(&self.socket, wait);
                    self.receive_blocking(&mut buf, &mut batch);
                    draining && !batch.is_empty() && self.receive(&mut buf, &mut batch)
                }
            };
            if self.closed.load(Ordering::Acquire) {
                break;
            }
            loop {
                draining = batch.len() > 1;
                let now = Instant::now();
                let received = SystemTime::now();
                let mut locked = self.lock();
                for (datagram, from) in batch.drain(..) {
                    if datagram.is_empty() && from == self.wake_to {
                        // A wake-up, not traffic.
                        continue;
                    }
                    locked.core.handle_datagram(now, received, from, datagram);
                }
                next = locked.core.poll_timeout();
                if next.is_some_and(|at| at <= now) {
                    locked.core.handle_timeout(now);
                    next = locked.core.poll_timeout();
                }
                locked.core.take_events(&mut events);
                locked.io_wakes_at = next;
                if locked.ack_waiters > 0 {
                    self.window.notify_all();
                }
                let sent = self.release(locked);
                self.count(&sent);
                self.dispatch(&mut local, &mut events, &mut credits);
                // The buffers just sent go back now if nobody holds the core, rather than
                // when this thread next wakes: a writer meanwhile finds them spare.
                if let Ok(mut locked) = self.locked.try_lock() {
                    self.recycle_sent(&mut locked);
                }
                // More datagrams may wait; and a direct callback's command may have left
                // events or an earlier timer: one more round picks them up (without a
                // receive, which would only find the socket empty).
                let dirty = IO_DIRTY.with(|dirty| dirty.replace(false));
                if !full && !dirty {
                    break;
                }
                if full {
                    full = self.receive(&mut buf, &mut batch);
                }
            }
        }
    }

    /// Waits up to `wait` for the socket to become readable (precisely, with `ppoll`).
    fn poll_readable(&self, wait: Duration) -> bool {
        let mut fd = libc::pollfd {
            fd: self.socket.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        let timeout = libc::timespec {
            tv_sec: libc::time_t::try_from(wait.as_secs()).unwrap_or(libc::time_t::MAX),
            tv_nsec: libc::c_long::from(wait.subsec_nanos() as i32),
        };
        // SAFETY: one valid pollfd, a valid timespec, no signal mask.
        let ready = unsafe { libc::ppoll(&mut fd, 1, &timeout, std::ptr::null()) };
        ready > 0
    }

    /// Waits (with the socket's receive timeout) for one datagram.
    fn receive_blocking(&self, buf: &mut BytesMut, batch: &mut Vec<(BytesMut, SocketAddrV4)>) {
        let _ = self.receive_one(buf, batch, 0);
    }

    /// Receives one datagram into `buf`'s region and `batch`.
    fn receive_one(
        &self,
        buf: &mut BytesMut,
        batch: &mut Vec<(BytesMut, SocketAddrV4)>,
        flags: libc::c_int,
    ) -> io::Result<()> {
        // Room for the largest datagram; a region is reused once every sample cut from it
        // has been dropped.
        if buf.capacity() - buf.len() < RECV_SIZE {
            buf.reserve(RECV_REGION);
        }
        let socket = socket2::SockRef::from(&self.socket);
        let (len, from) =
            socket.recv_from_with_flags(&mut buf.spare_capacity_mut()[..RECV_SIZE], flags)?;
        // SAFETY: `recv_from_with_flags` initialised the first `len` bytes of the spare
        // capacity it was given.
        unsafe { buf.set_len(len) };
        let datagram = buf.split_to(len);
        if let Some(from) = from.as_socket_ipv4() {
            batch.push((datagram, from));
        }
        Ok(())
    }

    /// Receives up to [`RECV_BATCH`] datagrams without waiting; true if it stopped before the
    /// socket was empty (more may wait).
    fn receive(&self, buf: &mut BytesMut, batch: &mut Vec<(BytesMut, SocketAddrV4)>) -> bool {
        let mut errors = 0;
        let mut bytes: usize = batch.iter().map(|(d, _)| d.len()).sum();
        while batch.len() < RECV_BATCH {
            if bytes >= RECV_BATCH_BYTES {
                return true;
            }
            if buf.capacity() - buf.len() < RECV_SIZE && !batch.is_empty() {
                // The datagrams of this batch still hold the region: handle them first, so
                // the region can be reused instead of another one allocated.
                return true;
            }
            match self.receive_one(buf, batch, libc::MSG_DONTWAIT) {
                Ok(()) => bytes += batch.last().map_or(0, |(d, _)| d.len()),
                Err(err) if err.kind() == io::ErrorKind::WouldBlock => return false,
                Err(err) if err.kind() == io::ErrorKind::Interrupted => {}
                Err(err) => {
                    // ICMP errors reported on the socket (a peer's port closed) and the like:
                    // datagrams may still wait behind them.
                    tracing::trace!(%err, "data receive error");
                    errors += 1;
                    if errors > RECV_BATCH {
                        return !batch.is_empty();
                    }
                }
            }
        }
        true
    }

    /// Hands the core's events to the consumers' queues and the producers' waiters, outside
    /// every lock of the core (a direct callback runs here).
    fn dispatch(
        &self,
        local: &mut LocalConsumers,
        events: &mut VecDeque<Event>,
        credits: &mut Vec<(u32, usize)>,
    ) {
        local.refresh(self);
        let mut window = false;
        for event in events.drain(..) {
            let (consumer, event) = match event {
                Event::Sample { consumer, sample } => (consumer, RawEvent::Sample(sample)),
                Event::Notification {
                    consumer,
                    notification,
                } => (consumer, RawEvent::Notification(notification)),
                Event::WindowOpen { .. } => {
                    window = true;
                    continue;
                }
                Event::ReaderSilenced { producer, reader } => {
                    let topic = read(&self.endpoints).producers.get(&producer).cloned();
                    tracing::warn!(
                        topic = topic.as_deref().unwrap_or("?"),
                        consumer = %reader,
                        "a reliable consumer stopped acknowledging: it no longer holds this producer's window (it gets SamplesLost for what it misses if it comes back)"
                    );
                    continue;
                }
            };
            if let Some(delivery) = local.consumers.get(&consumer) {
                delivery.push(event);
                let evicted = delivery.take_evicted();
                if evicted > 0 {
                    credits.push((consumer, evicted));
                }
            }
        }
        if !credits.is_empty() {
            // Samples a full queue pushed out give their credit back (the next round of
            // this thread delivers what that lets through).
            self.command(|core, now| {
                for (consumer, samples) in credits.drain(..) {
                    core.taken(now, consumer, samples);
                }
            });
        }
        // The window changed under the lock, before this: a writer that looked before is
        // waiting by now, one that looks after sees it open.
        if window {
            self.wake_writers();
        }
    }

    /// Stops the I/O thread promptly.
    pub(crate) fn close(&self) {
        self.closed.store(true, Ordering::Release);
        self.wake_io();
        self.wake_writers();
    }
}

/// The wall clock in nanoseconds since the Unix epoch (a sample's source timestamp).
fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// How long the wall clock's offset from the monotonic one is trusted before it is read
/// again: a step of the wall clock (NTP, an operator) shows in timestamps within this.
const WALL_RECHECK_NS: u64 = 1_000_000;

/// The wall clock read through the monotonic one a write reads anyway: the offset between
/// the two is read again at most every [`WALL_RECHECK_NS`], so a write costs one clock read
/// instead of two (a read is tens of nanoseconds in a virtual machine, a few percent of
/// writing a small sample).
#[derive(Debug)]
struct WallClock {
    base: Instant,
    /// Wall-clock ns minus `base`-relative monotonic ns (wrapping).
    offset: AtomicU64,
    /// `base`-relative monotonic ns when `offset` was read (`u64::MAX`: never).
    checked: AtomicU64,
}

impl WallClock {
    fn new() -> Self {
        WallClock {
            base: Instant::now(),
            offset: AtomicU64::new(0),
            checked: AtomicU64::new(u64::MAX),
        }
    }

    /// The wall clock at `now` (an instant just read), in ns since the Unix epoch.
    fn at(&self, now: Instant) -> u64 {
        let mono =
            u64::try_from(now.saturating_duration_since(self.base).as_nanos()).unwrap_or(u64::MAX);
        let checked = self.checked.load(Ordering::Acquire);
        if checked != u64::MAX && mono.wrapping_sub(checked) < WALL_RECHECK_NS {
            return mono.wrapping_add(self.offset.load(Ordering::Relaxed));
        }
        // Two threads may both read it here: either offset is right.
        let wall = now_ns();
        self.offset
            .store(wall.wrapping_sub(mono), Ordering::Relaxed);
        self.checked.store(mono, Ordering::Release);
        wall
    }
}

/// 32 bytes from the operating system's random source, for the core's address tokens; if it
/// cannot be read, the core's own (seeded from the operating system by `fastrand`).
fn os_secret() -> [u8; 32] {
    use std::io::Read;
    let mut secret = [0; 32];
    match std::fs::File::open("/dev/urandom").and_then(|mut f| f.read_exact(&mut secret)) {
        Ok(()) => secret,
        Err(error) => {
            tracing::debug!(%error, "/dev/urandom unreadable: address tokens from fastrand");
            CoreConfig::new(0, 0).secret
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wall_clock_through_the_monotonic_one_follows_both() {
        let clock = WallClock::new();
        let t0 = Instant::now();
        let before = now_ns();
        let first = clock.at(t0);
        let after = now_ns();
        assert!(
            (before..=after).contains(&first),
            "{before} <= {first} <= {after}"
        );
        // Within the recheck time: the monotonic clock's progress, exactly.
        let t1 = t0 + Duration::from_micros(400);
        assert_eq!(clock.at(t1) - first, 400_000);
        // Past it: read again (a wall clock that stepped would show now).
        std::thread::sleep(Duration::from_millis(2));
        let t2 = Instant::now();
        let wall = now_ns();
        let late = clock.at(t2);
        assert!(late.abs_diff(wall) < 1_000_000, "{late} against {wall}");
        assert!(late >= first + 2_000_000);
    }
}

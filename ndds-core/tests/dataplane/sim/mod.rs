//! A simulated network of [`ParticipantCore`]s in virtual time: no sockets, no clock reads,
//! every run replays exactly from its seed.
//!
//! Node `i` is one participant (id [`participant_id`]`(i)`) whose data socket is
//! [`locator`]`(i)` = `10.0.0.(i+1):7400`. A [`Transmit`] goes to the node with that locator;
//! one to any other address is recorded in [`SimNet::outsiders`] (what an attacker's address
//! would have received). Each directed link has a latency, a jitter (which reorders), a loss
//! and a duplication probability; a link can be cut (one way or both), a node can be taken
//! down (it is not driven: it neither receives, runs timers nor writes) and brought back; a
//! datagram larger than the path MTU is dropped. Whether a datagram is lost, duplicated or
//! delayed is drawn from an RNG seeded by the network's seed and the datagram itself (its
//! bytes, its link and how often the same bytes went that way before), so a run does not
//! depend on the order in which a core happens to emit the datagrams of one instant (its maps
//! iterate in a per-process order).
//!
//! [`SimNet::run_until`] drives the cores: deliver every datagram due now, run the timers due
//! now, let the [`WriterApp`]s write and the consumers' applications ([`App`]) take samples
//! (handing the credit back with `taken`), drain every core's transmits into the network and
//! its events into per-endpoint logs; then jump to the earliest instant anything happens next.
//! Discovery is not simulated: matches are applied with [`SimNet::connect`] and
//! [`SimNet::disconnect`], which call `set_producer_matched` / `set_consumer_matched`.

// Not every test uses every helper.
#![allow(dead_code)]

mod apps;
mod check;

pub use apps::{App, ConsumerLog, Got, WriterApp};
pub use check::{Item, covers, exactly, payload, stream_of, tag};

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet, VecDeque};
use std::net::{Ipv4Addr, SocketAddrV4};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use bytes::{Bytes, BytesMut};
use ndds_core::participant::{
    ConsumerSpec, CoreConfig, Event, MatchedConsumer, ParticipantCore, ProducerSpec,
};
use ndds_core::wire::Guid;

/// Domain of every simulated participant.
pub const DOMAIN: u16 = 23;
/// Path MTU (and every core's `max_datagram`) unless a test says otherwise: small, so
/// samples of a few KiB are fragmented.
pub const MTU: usize = 1200;
/// The data socket of node `index`.
pub fn locator(index: usize) -> SocketAddrV4 {
    let host = u8::try_from(index + 1).expect("at most 254 nodes");
    SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, host), 7400)
}

/// An address no node has (an attacker's).
pub fn outsider() -> SocketAddrV4 {
    SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, 200), 7400)
}

/// The participant id of node `index`.
pub fn participant_id(index: usize) -> u64 {
    0x5100_0000_0000 + index as u64
}

/// The id of endpoint `entity` of node `node`.
pub fn guid(node: usize, entity: u32) -> Guid {
    Guid {
        participant: participant_id(node),
        entity,
    }
}

/// Properties of one direction of a link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    /// One-way latency.
    pub latency: Duration,
    /// Extra delay drawn from `0..jitter` per datagram (reorders them).
    pub jitter: Duration,
    /// Probability that a datagram is dropped.
    pub loss: f64,
    /// Probability that a datagram arrives twice.
    pub duplicate: f64,
}

impl Link {
    /// A clean link with 1 ms latency.
    pub fn clean() -> Self {
        Link {
            latency: Duration::from_millis(1),
            jitter: Duration::ZERO,
            loss: 0.0,
            duplicate: 0.0,
        }
    }

    /// A clean link that loses `loss` of its datagrams.
    pub fn lossy(loss: f64) -> Self {
        Link {
            loss,
            ..Link::clean()
        }
    }

    /// A link of 100 µs each way (two hosts on one switch) that loses `loss`.
    pub fn local(loss: f64) -> Self {
        Link {
            latency: Duration::from_micros(100),
            ..Link::lossy(loss)
        }
    }
}

/// One simulated participant.
#[derive(Debug)]
pub struct Node {
    /// Its data plane.
    pub core: ParticipantCore,
    /// Its data socket.
    pub addr: SocketAddrV4,
    /// False while down: not driven, receives nothing.
    pub up: bool,
    /// Its consumers' applications, by entity.
    pub consumers: BTreeMap<u32, ConsumerLog>,
    /// Producer events (`WindowOpen`, `ReaderSilenced`), with their virtual times.
    pub producer_events: Vec<(Duration, Event)>,
}

/// Counters of the network.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NetStats {
    /// Datagrams the cores sent.
    pub sent: u64,
    /// Datagrams handed to a core.
    pub delivered: u64,
    /// Dropped by a link's loss.
    pub lost: u64,
    /// Extra copies made.
    pub duplicated: u64,
    /// Dropped for exceeding the MTU.
    pub too_big: u64,
    /// Dropped on a cut link.
    pub cut: u64,
    /// Arrived at a node that was down.
    pub at_down_node: u64,
    /// Sent to an address no node has.
    pub unroutable: u64,
    /// The largest datagram sent.
    pub largest: usize,
}

#[derive(Debug)]
struct InFlight {
    from: SocketAddrV4,
    to: usize,
    bytes: Bytes,
}

/// The network. See the module docs.
#[derive(Debug)]
pub struct SimNet {
    /// Start of virtual time.
    pub t0: Instant,
    /// Virtual now.
    pub now: Instant,
    seed: u64,
    /// The nodes.
    pub nodes: Vec<Node>,
    /// The producing applications.
    pub writers: Vec<WriterApp>,
    /// Every link's properties unless [`SimNet::set_link`] says otherwise.
    pub link: Link,
    links: HashMap<(usize, usize), Link>,
    cut: HashSet<(usize, usize)>,
    /// The path MTU: a larger datagram is dropped.
    pub mtu: usize,
    /// Matches applied: (producer node, entity) to (consumer node, entity).
    matches: BTreeSet<((usize, u32), (usize, u32))>,
    /// Apply a new match to the consumer before the producer (else the producer first, as
    /// when its daemon tells it first and it sends before the consumer knows).
    pub consumers_first: bool,
    in_flight: BTreeMap<(Instant, u64, u64), InFlight>,
    /// How often the same bytes went the same way (their RNG stream differs each time).
    sent_before: HashMap<u64, u64>,
    /// How often the same bytes were queued for the same node (orders copies).
    queued_before: HashMap<u64, u64>,
    /// Network counters.
    pub stats: NetStats,
    /// Datagrams sent to addresses no node has: (to, bytes).
    pub outsiders: Vec<(SocketAddrV4, usize)>,
    /// Every datagram sent, (from, to, bytes), while it is `Some`.
    pub tap: Option<Vec<(usize, SocketAddrV4, Bytes)>>,
}

impl SimNet {
    /// `nodes` participants with `max_datagram` = [`MTU`], clean links, seeded by `seed`.
    pub fn new(seed: u64, nodes: usize) -> Self {
        let t0 = Instant::now();
        let nodes = (0..nodes)
            .map(|i| Node {
                core: ParticipantCore::new(CoreConfig {
                    domain: DOMAIN,
                    participant: participant_id(i),
                    max_datagram: MTU,
                    max_sample: 1 << 20,
                    // Deterministic from the seed, like everything else here.
                    secret: secret(seed, i),
                }),
                addr: locator(i),
                up: true,
                consumers: BTreeMap::new(),
                producer_events: Vec::new(),
            })
            .collect();
        SimNet {
            t0,
            now: t0,
            seed,
            nodes,
            writers: Vec::new(),
            link: Link::clean(),
            links: HashMap::new(),
            cut: HashSet::new(),
            mtu: MTU,
            matches: BTreeSet::new(),
            consumers_first: false,
            in_flight: BTreeMap::new(),
            sent_before: HashMap::new(),
            queued_before: HashMap::new(),
            stats: NetStats::default(),
            outsiders: Vec::new(),
            tap: None,
        }
    }

    /// Virtual time since the start.
    pub fn elapsed(&self) -> Duration {
        self.now - self.t0
    }

    /// The instant `ms` milliseconds after the start.
    pub fn at_ms(&self, ms: u64) -> Instant {
        self.t0 + Duration::from_millis(ms)
    }

    /// The wall clock of the simulated hosts at `now`.
    pub fn wall(&self, now: Instant) -> SystemTime {
        SystemTime::UNIX_EPOCH + Duration::from_secs(1_700_000_000) + (now - self.t0)
    }

    fn wall_ns(&self) -> u64 {
        let since = self
            .wall(self.now)
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap_or_default();
        u64::try_from(since.as_nanos()).unwrap_or(u64::MAX)
    }

    // ---- topology and faults ----

    /// Sets the link between `a` and `b`, both directions.
    pub fn set_link(&mut self, a: usize, b: usize, link: Link) {
        self.links.insert((a, b), link);
        self.links.insert((b, a), link);
    }

    fn link_of(&self, from: usize, to: usize) -> Link {
        self.links.get(&(from, to)).copied().unwrap_or(self.link)
    }

    /// Cuts the link between `a` and `b`, both directions.
    pub fn cut(&mut self, a: usize, b: usize) {
        self.cut.insert((a, b));
        self.cut.insert((b, a));
    }

    /// Cuts only what `from` sends to `to`.
    pub fn cut_one_way(&mut self, from: usize, to: usize) {
        self.cut.insert((from, to));
    }

    /// Restores the link between `a` and `b`, both directions.
    pub fn heal(&mut self, a: usize, b: usize) {
        self.cut.remove(&(a, b));
        self.cut.remove(&(b, a));
    }

    /// Takes node `node` down (a frozen process or host: it does nothing at all).
    pub fn down(&mut self, node: usize) {
        self.nodes[node].up = false;
    }

    /// Brings node `node` back with its state.
    pub fn up(&mut self, node: usize) {
        self.nodes[node].up = true;
    }

    // ---- endpoints ----

    /// Declares a consumer whose application takes samples as `app` says.
    pub fn add_consumer(&mut self, node: usize, entity: u32, spec: ConsumerSpec, app: App) {
        let now = self.now;
        let n = &mut self.nodes[node];
        n.core.add_consumer(now, entity, spec);
        n.consumers.insert(
            entity,
            ConsumerLog {
                app,
                reliable: spec.reliable.is_some(),
                got: Vec::new(),
                notifications: Vec::new(),
                pending: VecDeque::new(),
                max_pending: 0,
                next_take: now,
            },
        );
    }

    /// Declares a producer.
    pub fn add_producer(&mut self, node: usize, entity: u32, spec: ProducerSpec) {
        self.nodes[node].core.add_producer(entity, spec);
    }

    /// Adds a producing application; returns its index in [`SimNet::writers`].
    pub fn add_writer(&mut self, writer: WriterApp) -> usize {
        let mut writer = writer;
        writer.next_write = Some(self.now.max(self.t0 + writer.start));
        self.writers.push(writer);
        self.writers.len() - 1
    }

    /// Discovery matches producer `producer` with consumer `consumer` (each a node and an
    /// entity): both sides are told.
    pub fn connect(&mut self, producer: (usize, u32), consumer: (usize, u32)) {
        self.matches.insert((producer, consumer));
        if self.consumers_first {
            self.apply_consumer(consumer);
            self.apply_producer(producer);
        } else {
            self.apply_producer(producer);
            self.apply_consumer(consumer);
        }
        self.drain_all();
    }

    /// Only the producer's side hears of the match (the consumer's daemon has not learned of
    /// the producer yet: its announcement was lost); [`SimNet::connect`] later tells both.
    pub fn connect_producer_side(&mut self, producer: (usize, u32), consumer: (usize, u32)) {
        self.matches.insert((producer, consumer));
        self.apply_producer(producer);
        self.drain_all();
    }

    /// Discovery no longer matches them: both sides are told, and the consumer hears that
    /// the producer was lost.
    pub fn disconnect(&mut self, producer: (usize, u32), consumer: (usize, u32)) {
        self.matches.remove(&(producer, consumer));
        self.apply_producer(producer);
        self.apply_consumer(consumer);
        let now = self.now;
        self.nodes[consumer.0]
            .core
            .producer_lost(now, consumer.1, guid(producer.0, producer.1));
        self.drain_all();
    }

    fn apply_producer(&mut self, producer: (usize, u32)) {
        let matched: Vec<MatchedConsumer> = self
            .matches
            .iter()
            .filter(|(p, _)| *p == producer)
            .map(|(_, (node, entity))| MatchedConsumer {
                guid: guid(*node, *entity),
                locator: locator(*node),
                reliable: self.nodes[*node]
                    .consumers
                    .get(entity)
                    .is_some_and(|c| c.reliable),
            })
            .collect();
        let now = self.now;
        self.nodes[producer.0]
            .core
            .set_producer_matched(now, producer.1, &matched);
    }

    fn apply_consumer(&mut self, consumer: (usize, u32)) {
        let matched: Vec<(Guid, SocketAddrV4)> = self
            .matches
            .iter()
            .filter(|(_, c)| *c == consumer)
            .map(|((node, entity), _)| (guid(*node, *entity), locator(*node)))
            .collect();
        let now = self.now;
        self.nodes[consumer.0]
            .core
            .set_consumer_matched(now, consumer.1, matched);
    }

    /// The log of consumer `entity` of `node`.
    pub fn consumer(&self, node: usize, entity: u32) -> &ConsumerLog {
        &self.nodes[node].consumers[&entity]
    }

    /// Sends `bytes` from `from` (any address, say an attacker's) to node `to`, over a clean
    /// link with the default latency.
    pub fn inject(&mut self, from: SocketAddrV4, to: usize, bytes: Vec<u8>) {
        let at = self.now + self.link.latency;
        self.enqueue(at, from, to, Bytes::from(bytes));
    }

    // ---- running ----

    /// Runs for `span` of virtual time.
    pub fn run_for(&mut self, span: Duration) {
        let deadline = self.now + span;
        self.run_until(deadline, |_| false);
    }

    /// Runs until `done` holds (checked after every step) or virtual time reaches
    /// `deadline`; returns whether `done` held.
    pub fn run_until(&mut self, deadline: Instant, mut done: impl FnMut(&SimNet) -> bool) -> bool {
        let mut same_instant = 0;
        loop {
            self.step();
            if done(self) {
                return true;
            }
            let Some(next) = self.next_event() else {
                self.now = deadline;
                return false;
            };
            if next > deadline {
                self.now = deadline;
                return false;
            }
            same_instant = if next <= self.now {
                same_instant + 1
            } else {
                0
            };
            assert!(
                same_instant < 10_000,
                "virtual time does not advance at {:?}",
                self.elapsed()
            );
            self.now = next.max(self.now);
        }
    }

    fn next_event(&self) -> Option<Instant> {
        let datagram = self.in_flight.keys().next().map(|k| k.0);
        let timers = self
            .nodes
            .iter()
            .filter(|n| n.up)
            .filter_map(|n| n.core.poll_timeout());
        let writes = self
            .writers
            .iter()
            .filter(|w| w.active && !w.finished() && self.nodes[w.node].up)
            .filter(|w| !w.respect_window || self.nodes[w.node].core.window_open(w.entity))
            .filter_map(|w| w.next_write);
        let takes = self
            .nodes
            .iter()
            .filter(|n| n.up)
            .flat_map(|n| n.consumers.values())
            .filter(|c| matches!(c.app, App::Slow { .. }) && !c.pending.is_empty())
            .map(|c| c.next_take);
        datagram
            .into_iter()
            .chain(timers)
            .chain(writes)
            .chain(takes)
            .min()
    }

    fn step(&mut self) {
        let now = self.now;
        while let Some(entry) = self.in_flight.first_entry() {
            if entry.key().0 > now {
                break;
            }
            let datagram = entry.remove();
            let wall = self.wall(now);
            let node = &mut self.nodes[datagram.to];
            if node.up {
                self.stats.delivered += 1;
                node.core.handle_datagram(
                    now,
                    wall,
                    datagram.from,
                    BytesMut::from(&datagram.bytes[..]),
                );
            } else {
                self.stats.at_down_node += 1;
            }
        }
        for node in self.nodes.iter_mut().filter(|n| n.up) {
            if node.core.poll_timeout().is_some_and(|due| due <= now) {
                node.core.handle_timeout(now);
            }
        }
        self.drain_all();
        self.produce();
        self.drain_all();
        self.consume();
    }

    fn produce(&mut self) {
        let now = self.now;
        let timestamp = self.wall_ns();
        let elapsed = self.elapsed();
        for writer in &mut self.writers {
            let node = &mut self.nodes[writer.node];
            if !node.up || !writer.active {
                continue;
            }
            while !writer.finished() && writer.next_write.is_some_and(|at| at <= now) {
                if writer.respect_window && !node.core.window_open(writer.entity) {
                    writer.blocked_since.get_or_insert(now);
                    break;
                }
                if let Some(since) = writer.blocked_since.take() {
                    writer.blocked_for += now - since;
                    writer.blocked.push((since - self.t0, elapsed));
                }
                let seq = writer.written() + 1;
                let size = writer.sizes[(seq as usize - 1) % writer.sizes.len()];
                let bytes = Arc::new(payload(tag(writer.node, writer.entity), seq, size));
                match node.core.write(now, timestamp, writer.entity, &bytes) {
                    Ok(written) => {
                        assert_eq!(written, seq, "the core numbers samples 1, 2, ...");
                        writer.written_at.push(elapsed);
                    }
                    Err(refused) => {
                        writer.refused.push(refused);
                        break;
                    }
                }
                // A writer that was late (paused, blocked, down) does not catch up in a burst.
                writer.next_write = Some(now + writer.interval);
            }
        }
    }

    fn consume(&mut self) {
        let now = self.now;
        let elapsed = self.elapsed();
        loop {
            let mut took = false;
            for node in self.nodes.iter_mut().filter(|n| n.up) {
                for (entity, log) in &mut node.consumers {
                    let limit = match log.app {
                        App::Eager => usize::MAX,
                        App::Never => 0,
                        App::Slow { every, batch } if log.next_take <= now => {
                            if !log.pending.is_empty() {
                                log.next_take = now + every;
                            }
                            batch
                        }
                        App::Slow { .. } => 0,
                    };
                    let n = limit.min(log.pending.len());
                    if n == 0 {
                        continue;
                    }
                    for mut got in log.pending.drain(..n) {
                        got.taken = elapsed;
                        log.got.push(got);
                    }
                    node.core.taken(now, *entity, n);
                    took = true;
                }
            }
            self.drain_all();
            if !took {
                return;
            }
        }
    }

    /// Moves every core's events to the logs and its datagrams into the network.
    fn drain_all(&mut self) {
        let elapsed = self.elapsed();
        for index in 0..self.nodes.len() {
            let node = &mut self.nodes[index];
            while let Some(event) = node.core.poll_event() {
                log_event(node, elapsed, event);
            }
            while let Some(transmit) = self.nodes[index].core.poll_transmit() {
                let bytes = Bytes::from(transmit.to_vec());
                let to = transmit.to;
                self.nodes[index].core.recycle(transmit);
                self.send(index, to, bytes);
            }
        }
    }

    fn send(&mut self, from: usize, to: SocketAddrV4, bytes: Bytes) {
        self.stats.sent += 1;
        if let Some(tap) = &mut self.tap {
            tap.push((from, to, bytes.clone()));
        }
        self.stats.largest = self.stats.largest.max(bytes.len());
        let Some(dest) = self.nodes.iter().position(|n| n.addr == to) else {
            self.stats.unroutable += 1;
            self.outsiders.push((to, bytes.len()));
            return;
        };
        if bytes.len() > self.mtu {
            self.stats.too_big += 1;
            return;
        }
        if self.cut.contains(&(from, dest)) {
            self.stats.cut += 1;
            return;
        }
        let link = self.link_of(from, dest);
        let mut rng = self.datagram_rng(from, dest, &bytes);
        if rng.f64() < link.loss {
            self.stats.lost += 1;
            return;
        }
        let copies = if rng.f64() < link.duplicate { 2 } else { 1 };
        self.stats.duplicated += copies - 1;
        for _ in 0..copies {
            let at = self.now + link.latency + link.jitter.mul_f64(rng.f64());
            self.enqueue(at, locator(from), dest, bytes.clone());
        }
    }

    fn enqueue(&mut self, at: Instant, from: SocketAddrV4, to: usize, bytes: Bytes) {
        // Ordered by arrival, then by content, then by how often the same bytes were
        // queued: independent of the order a core emitted them in.
        let key = fnv(self.seed, &bytes) ^ (to as u64).rotate_left(17);
        let count = self.queued_before.entry(key).or_insert(0);
        *count += 1;
        self.in_flight
            .insert((at, key, *count), InFlight { from, to, bytes });
    }

    /// The random choices for one datagram: seeded by the network's seed, its link, its
    /// bytes and how often those bytes went that way before.
    fn datagram_rng(&mut self, from: usize, to: usize, bytes: &[u8]) -> fastrand::Rng {
        let key = fnv(self.seed, bytes) ^ ((from as u64) << 40 | (to as u64) << 20);
        let count = self.sent_before.entry(key).or_insert(0);
        *count += 1;
        fastrand::Rng::with_seed(key.wrapping_add(count.wrapping_mul(0x9e37_79b9_7f4a_7c15)))
    }
}

fn log_event(node: &mut Node, elapsed: Duration, event: Event) {
    match event {
        Event::Sample { consumer, sample } => {
            let Some(log) = node.consumers.get_mut(&consumer) else {
                panic!("a sample for consumer {consumer}, never declared");
            };
            log.pending.push_back(apps::describe(elapsed, &sample));
            log.max_pending = log.max_pending.max(log.pending.len());
        }
        Event::Notification {
            consumer,
            notification,
        } => {
            if let Some(log) = node.consumers.get_mut(&consumer) {
                log.notifications.push((elapsed, notification));
            }
        }
        other => node.producer_events.push((elapsed, other)),
    }
}

/// FNV-1a over `bytes`, started from `seed`.
fn fnv(seed: u64, bytes: &[u8]) -> u64 {
    let mut hash = 0xcbf2_9ce4_8422_2325 ^ seed;
    for b in bytes {
        hash ^= u64::from(*b);
        hash = hash.wrapping_mul(0x0100_0000_01b3);
    }
    hash
}

/// Participant `index`'s secret in a network seeded by `seed`.
fn secret(seed: u64, index: usize) -> [u8; 32] {
    let mut rng =
        fastrand::Rng::with_seed(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    std::array::from_fn(|_| rng.u8(..))
}

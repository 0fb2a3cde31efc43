//! A simulated network of discovery engines with virtual time, loss, latency, partitions,
//! crashes and restarts — no sockets, no clock reads, every run replays exactly from its seed.
//!
//! Nodes are numbered `0..n` in the order they were added. Node `i` receives unicast at
//! `10.0.0.(i+1):7400`. A multicast `Transmit` reaches every other running node that has
//! multicast on (`DiscoveryConfig::multicast`) and whose multicast is not cut
//! ([`SimNet::cut_multicast`]); a unicast one reaches the running node whose configured unicast
//! locator matches. Each delivery to one node is lost with that link's probability, drawn from
//! the network's seeded RNG. A node with multicast off that sends to the group fails the test.
//!
//! [`SimNet::run_for`] drives the engines: deliver every datagram due now, then jump virtual time
//! to the earliest instant anything happens next (an engine's `poll_timeout()` or a datagram in
//! flight) and run the engines' timers due then. Every event an engine emits is recorded with the
//! virtual time it was taken, and so is every datagram delivered.

// Each test binary that includes this module uses a different subset of it.
#![allow(dead_code)]

use std::collections::{BTreeMap, HashSet};
use std::net::{SocketAddr, SocketAddrV4};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ndds_core::discovery::{Destination, DiscoveryConfig, Engine, Event, Via};
use ndds_core::wire::{self, EndpointInfo, Guid, Locator, MessageKind};

/// Domain of every simulated engine.
pub const DOMAIN: u16 = 17;

/// The unicast locator of node `index`.
pub fn locator(index: usize) -> Locator {
    Locator {
        addr: [
            10,
            0,
            0,
            u8::try_from(index + 1).expect("at most 254 nodes"),
        ],
        port: 7400,
    }
}

/// A configuration for node `index` with the given timers and seed.
pub fn config(index: usize, seed: u64, period: Duration, lease: Duration) -> DiscoveryConfig {
    let mut config = DiscoveryConfig::new(DOMAIN, locator(index));
    config.seed = seed;
    config.hostname = format!("host{index}");
    config.announce_period = period;
    config.lease = lease;
    config
}

/// `config` with multicast on or off and the unicast locators of `peers` as its peer list.
pub fn with_peers(
    mut config: DiscoveryConfig,
    multicast: bool,
    peers: &[usize],
) -> DiscoveryConfig {
    config.multicast = multicast;
    config.peers = peers.iter().map(|&p| locator(p)).collect();
    config
}

/// A datagram that reached an engine.
#[derive(Clone, Debug)]
pub struct Delivery {
    /// Virtual time of arrival.
    pub at: Duration,
    /// Sending node.
    pub from: usize,
    /// Receiving node.
    pub to: usize,
    /// Message kind from the header.
    pub kind: MessageKind,
    /// Sent to one node's locator rather than to the group.
    pub unicast: bool,
}

/// One simulated node.
pub struct SimNode {
    /// Its engine (replaced on restart).
    pub engine: Engine,
    /// Every event it emitted, with the virtual time it was taken.
    pub events: Vec<(Duration, Event)>,
    /// False after `crash` or `close`: not driven, receives and sends nothing.
    pub running: bool,
}

struct InFlight {
    from: usize,
    to: usize,
    kind: MessageKind,
    unicast: bool,
    payload: Arc<[u8]>,
}

/// The network. See the module docs.
pub struct SimNet {
    start: Instant,
    now: Instant,
    nodes: Vec<SimNode>,
    rng: fastrand::Rng,
    loss: f64,
    link_loss: BTreeMap<(usize, usize), f64>,
    latency: Duration,
    cut: HashSet<(usize, usize)>,
    no_multicast: HashSet<usize>,
    /// Datagrams in flight by arrival time, in sending order within one instant.
    in_flight: BTreeMap<(Instant, u64), InFlight>,
    sent: u64,
    /// Every datagram delivered so far.
    pub deliveries: Vec<Delivery>,
    /// Nodes whose datagrams are kept in `recorded` (a recording attacker's view).
    recording: HashSet<usize>,
    /// What the recorded nodes sent, in order: sender, kind, bytes as sent.
    pub recorded: Vec<(usize, MessageKind, Arc<[u8]>)>,
}

impl SimNet {
    /// An empty network with no loss, 1 ms latency and its own RNG seed.
    pub fn new(seed: u64) -> Self {
        let start = Instant::now();
        SimNet {
            start,
            now: start,
            nodes: Vec::new(),
            rng: fastrand::Rng::with_seed(seed),
            loss: 0.0,
            link_loss: BTreeMap::new(),
            latency: Duration::from_millis(1),
            cut: HashSet::new(),
            no_multicast: HashSet::new(),
            in_flight: BTreeMap::new(),
            sent: 0,
            deliveries: Vec::new(),
            recording: HashSet::new(),
            recorded: Vec::new(),
        }
    }

    /// Starts an engine now; returns its index. `config.unicast` must be `locator(index)`.
    pub fn add_node(&mut self, config: DiscoveryConfig) -> usize {
        self.add_node_with(config, |_| {})
    }

    /// Starts an engine now after `prepare` (sealing, say) had it; returns its index.
    pub fn add_node_with(
        &mut self,
        config: DiscoveryConfig,
        prepare: impl FnOnce(&mut Engine),
    ) -> usize {
        let index = self.nodes.len();
        assert_eq!(
            config.unicast,
            locator(index),
            "node {index} has the wrong locator"
        );
        let mut engine = Engine::new(config, self.now).expect("valid configuration");
        prepare(&mut engine);
        self.nodes.push(SimNode {
            engine,
            events: Vec::new(),
            running: true,
        });
        self.flush();
        index
    }

    // ----- faults --------------------------------------------------------------------------

    /// Loss probability of every link without its own setting.
    pub fn set_loss(&mut self, probability: f64) {
        self.loss = probability;
    }

    /// Loss probability of the one-way link `from → to`.
    pub fn set_link_loss(&mut self, from: usize, to: usize, probability: f64) {
        self.link_loss.insert((from, to), probability);
    }

    /// One-way latency of every datagram.
    pub fn set_latency(&mut self, latency: Duration) {
        self.latency = latency;
    }

    /// Cuts every link between a node of `a` and a node of `b`, both ways.
    pub fn partition(&mut self, a: &[usize], b: &[usize]) {
        for &x in a {
            for &y in b {
                self.cut.insert((x, y));
                self.cut.insert((y, x));
            }
        }
    }

    /// Cuts every link of node `n`.
    pub fn isolate(&mut self, n: usize) {
        let others: Vec<usize> = (0..self.nodes.len()).filter(|&i| i != n).collect();
        self.partition(&[n], &others);
    }

    /// Multicast no longer reaches nodes `nodes`, nor leaves them; unicast still flows (a
    /// network segment without multicast).
    pub fn cut_multicast(&mut self, nodes: &[usize]) {
        self.no_multicast.extend(nodes);
    }

    /// Restores every cut link and multicast everywhere (loss settings stay).
    pub fn heal(&mut self) {
        self.cut.clear();
        self.no_multicast.clear();
    }

    /// Stops node `n` dead: no `Bye`, nothing delivered to or from it, not driven.
    pub fn crash(&mut self, n: usize) {
        self.nodes[n].running = false;
        self.in_flight.retain(|_, d| d.to != n);
    }

    /// Replaces node `n` by a fresh engine (same configuration, new `seed`), started now.
    pub fn restart(&mut self, n: usize, seed: u64) {
        let mut config = self.nodes[n].engine.config().clone();
        config.seed = seed;
        self.nodes[n].engine = Engine::new(config, self.now).expect("valid configuration");
        self.nodes[n].running = true;
        self.flush();
    }

    // ----- commands ------------------------------------------------------------------------

    /// Declares a local endpoint on node `n`.
    pub fn add_local(&mut self, n: usize, info: EndpointInfo) {
        let now = self.now;
        self.nodes[n]
            .engine
            .add_local(now, info)
            .expect("endpoint accepted");
        self.flush();
    }

    /// Declares a local endpoint on node `n`, which may refuse it.
    pub fn try_add_local(
        &mut self,
        n: usize,
        info: EndpointInfo,
    ) -> Result<(), ndds_core::discovery::LocalError> {
        let now = self.now;
        let result = self.nodes[n].engine.add_local(now, info);
        self.flush();
        result
    }

    /// Runs `change` on node `n`'s engine now (a command such as a new permissions document).
    pub fn command(&mut self, n: usize, change: impl FnOnce(&mut Engine)) {
        change(&mut self.nodes[n].engine);
        self.flush();
    }

    /// Removes local endpoints of node `n`.
    pub fn remove_locals(&mut self, n: usize, guids: &[Guid]) {
        self.nodes[n].engine.remove_locals(guids);
        self.flush();
    }

    /// Closes node `n` (it says `Bye`) and stops driving it.
    pub fn close(&mut self, n: usize) {
        self.nodes[n].engine.close();
        self.flush();
        self.nodes[n].running = false;
    }

    // ----- driving -------------------------------------------------------------------------

    /// Runs for `duration` of virtual time.
    pub fn run_for(&mut self, duration: Duration) {
        self.run_for_checked(duration, |_| {});
    }

    /// Runs for `duration`, calling `check` after every step (each instant at which a timer
    /// fired or a datagram arrived), so an invariant can be asserted at every state.
    pub fn run_for_checked(&mut self, duration: Duration, mut check: impl FnMut(&SimNet)) {
        let deadline = self.now + duration;
        for _ in 0..10_000_000 {
            self.deliver_due();
            check(self);
            let next = self.next_instant().filter(|t| *t <= deadline);
            let Some(next) = next else {
                self.now = deadline;
                return;
            };
            self.now = self.now.max(next);
            self.fire_timers();
        }
        panic!("simulation made no progress");
    }

    /// Runs until `done` holds (checked after every step) or `limit` passes; returns the
    /// virtual time at which it held.
    pub fn run_until(
        &mut self,
        limit: Duration,
        mut done: impl FnMut(&SimNet) -> bool,
    ) -> Option<Duration> {
        let deadline = self.now + limit;
        let mut reached = None;
        while reached.is_none() && self.now < deadline {
            let step = (deadline - self.now).min(Duration::from_millis(1));
            self.run_for_checked(step, |net| {
                if reached.is_none() && done(net) {
                    reached = Some(net.elapsed());
                }
            });
        }
        reached
    }

    fn next_instant(&self) -> Option<Instant> {
        let timers = self
            .nodes
            .iter()
            .filter(|node| node.running)
            .filter_map(|node| node.engine.poll_timeout());
        let arrivals = self.in_flight.keys().next().map(|(at, _)| *at);
        timers.chain(arrivals).min()
    }

    fn fire_timers(&mut self) {
        let now = self.now;
        for node in self.nodes.iter_mut().filter(|node| node.running) {
            if node.engine.poll_timeout().is_some_and(|t| t <= now) {
                node.engine.handle_timeout(now);
            }
        }
        self.flush();
    }

    fn deliver_due(&mut self) {
        while let Some(entry) = self.in_flight.first_entry() {
            if entry.key().0 > self.now {
                break;
            }
            let datagram = entry.remove();
            if !self.nodes[datagram.to].running {
                continue;
            }
            let now = self.now;
            let from = SocketAddr::V4(SocketAddrV4::from(locator(datagram.from)));
            let via = if datagram.unicast {
                Via::Unicast
            } else {
                Via::Multicast
            };
            self.nodes[datagram.to]
                .engine
                .handle_datagram(now, from, via, &datagram.payload);
            self.deliveries.push(Delivery {
                at: self.elapsed(),
                from: datagram.from,
                to: datagram.to,
                kind: datagram.kind,
                unicast: datagram.unicast,
            });
            self.flush();
        }
    }

    /// Takes every node's transmits into the network and its events into its log.
    fn flush(&mut self) {
        let at = self.elapsed();
        for from in 0..self.nodes.len() {
            while let Some(event) = self.nodes[from].engine.poll_event() {
                self.nodes[from].events.push((at, event));
            }
            while let Some(transmit) = self.nodes[from].engine.poll_transmit() {
                if self.nodes[from].running {
                    self.send(from, transmit.destination, transmit.payload);
                }
            }
        }
    }

    fn send(&mut self, from: usize, destination: Destination, payload: Arc<[u8]>) {
        let kind = if ndds_core::seal::is_sealed(&payload) {
            // Sealed: only the header is in clear.
            let flags = ndds_core::seal::SEALED | ndds_core::seal::CLEAR;
            MessageKind::from_u8(payload[5] & !flags).expect("engines send valid datagrams")
        } else if payload[5] == MessageKind::Signed as u8 {
            // Signed: the kind of the datagram inside.
            let view = wire::signed::parse(&payload).expect("engines send valid datagrams");
            wire::decode(view.inner)
                .expect("engines send valid datagrams")
                .0
                .kind
        } else {
            wire::decode(&payload)
                .expect("engines send valid datagrams")
                .0
                .kind
        };
        if self.recording.contains(&from) {
            self.recorded.push((from, kind, payload.clone()));
        }
        let targets: Vec<usize> = match destination {
            Destination::Multicast => {
                assert!(
                    self.nodes[from].engine.config().multicast,
                    "node {from} has multicast off but sent {kind:?} to the group"
                );
                if self.no_multicast.contains(&from) {
                    Vec::new()
                } else {
                    (0..self.nodes.len())
                        .filter(|&i| i != from && !self.no_multicast.contains(&i))
                        .filter(|&i| self.nodes[i].engine.config().multicast)
                        .collect()
                }
            }
            Destination::Unicast(to) => (0..self.nodes.len())
                .filter(|&i| self.nodes[i].engine.config().unicast == to)
                .collect(),
        };
        for to in targets {
            let loss = self
                .link_loss
                .get(&(from, to))
                .copied()
                .unwrap_or(self.loss);
            let lost = self.rng.f64() < loss;
            if lost || self.cut.contains(&(from, to)) || !self.nodes[to].running {
                continue;
            }
            self.sent += 1;
            self.in_flight.insert(
                (self.now + self.latency, self.sent),
                InFlight {
                    from,
                    to,
                    kind,
                    unicast: matches!(destination, Destination::Unicast(_)),
                    payload: payload.clone(),
                },
            );
        }
    }

    // ----- inspection ----------------------------------------------------------------------
    /// Keeps every datagram node `n` sends from now on in [`SimNet::recorded`].
    pub fn record(&mut self, n: usize) {
        self.recording.insert(n);
    }

    /// Hands `bytes` to node `to` now, as if unicast from `from` (a forger's datagram).
    pub fn inject(&mut self, to: usize, from: Locator, bytes: &[u8]) {
        let from = SocketAddr::V4(SocketAddrV4::from(from));
        let now = self.now;
        self.nodes[to]
            .engine
            .handle_datagram(now, from, Via::Unicast, bytes);
        self.flush();
    }

    /// The virtual clock's instant now.
    pub fn now(&self) -> Instant {
        self.now
    }

    /// Virtual time since the network was created.
    pub fn elapsed(&self) -> Duration {
        self.now - self.start
    }

    /// Node `n`.
    pub fn node(&self, n: usize) -> &SimNode {
        &self.nodes[n]
    }

    /// Node `n`'s engine.
    pub fn engine(&self, n: usize) -> &Engine {
        &self.nodes[n].engine
    }

    /// Node `n`'s events taken at or after `since`.
    pub fn events_since(
        &self,
        n: usize,
        since: Duration,
    ) -> impl Iterator<Item = &(Duration, Event)> {
        self.nodes[n]
            .events
            .iter()
            .filter(move |(at, _)| *at >= since)
    }

    /// Whether node `n` currently knows the endpoint `guid` (local or remote).
    pub fn knows(&self, n: usize, guid: Guid) -> bool {
        self.nodes[n].engine.endpoint(&guid).is_some()
    }

    /// Whether node `n` currently knows the node with id `node_id`.
    pub fn knows_node(&self, n: usize, node_id: u64) -> bool {
        self.nodes[n].engine.nodes().any(|(id, _)| id == node_id)
    }
}

//! The driver: one task that owns the discovery engine and the table of connected clients.
//!
//! Every input (a datagram, a client frame, a connection opening or closing, the engine's
//! timer) is handled here in order, then the engine's transmits are sent and its events routed
//! to the clients that own the local endpoints they name.

use std::collections::VecDeque;
use std::collections::{BTreeSet, HashMap, HashSet};
use std::net::{SocketAddr, SocketAddrV4};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use ndds_core::discovery::{Destination, Engine, Event, Origin, Transmit, Via};
use ndds_core::ipc::{
    ClientMessage, ClientSummary, DaemonMessage, EndpointDecl, EndpointSummary, Graph, Hello,
    IPC_VERSION, NodeSummary, PeerSummary, Role, Welcome,
};
use ndds_core::seal::OpenError;
use ndds_core::wire::{DropReason, EndpointInfo, Guid, Locator};
use tokio::net::UdpSocket;
use tokio::sync::mpsc;

use crate::connection::ClientLink;
use crate::local::PeerCred;
use crate::log_budget::{LogBudget, Verdict};
use crate::peers::Peer;

/// Daemon-local number of a connection.
pub type ClientId = u64;

/// Inputs of the driver.
#[derive(Debug)]
pub enum Input {
    /// A discovery datagram arrived.
    Datagram {
        /// Its source.
        from: SocketAddr,
        /// The socket that received it: multicast or unicast.
        via: Via,
        /// Its bytes.
        bytes: Vec<u8>,
    },
    /// A connection was accepted.
    Opened {
        /// Its number.
        client: ClientId,
        /// How to reach it.
        link: ClientLink,
        /// Who it is, from the kernel.
        cred: PeerCred,
    },
    /// A connection sent a frame.
    Frame {
        /// Its number.
        client: ClientId,
        /// The frame.
        message: ClientMessage,
    },
    /// A connection ended.
    Closed {
        /// Its number.
        client: ClientId,
        /// Why.
        reason: String,
    },
}

/// Counters kept outside the engine; shared with the socket tasks.
#[derive(Debug, Default)]
pub struct Counters {
    /// Datagrams dropped because the driver's input queue was full.
    pub input_overflow: AtomicU64,
    /// Sessions refused (bad version, duplicate participant, frame before Hello, ...).
    pub sessions_refused: AtomicU64,
    /// Connections dropped because the client stopped reading.
    pub slow_clients: AtomicU64,
    /// Connections that ended with a protocol error.
    pub protocol_errors: AtomicU64,
    /// Datagrams the OS refused to send.
    pub send_errors: AtomicU64,
    /// Connections closed at once because [`crate::local::MAX_CLIENTS`] were open.
    pub connections_refused: AtomicU64,
}

/// What waits for a client whose outbox is full: its answers in order, then the pairs whose
/// state changed, coalesced (a pair is sent once, in its state at the time of sending), so a
/// burst larger than the outbox costs a few bytes per pair and never disconnects a client
/// that reads.
#[derive(Debug, Default)]
struct Backlog {
    answers: VecDeque<DaemonMessage>,
    /// (local entity, remote endpoint) of the changed pairs.
    pairs: BTreeSet<(u32, Guid)>,
    /// Since when nothing could be sent (reset by every frame that goes out).
    stalled_since: Option<Instant>,
}

impl Backlog {
    fn is_empty(&self) -> bool {
        self.answers.is_empty() && self.pairs.is_empty()
    }
}

/// Most endpoints in one page of the graph (`QueryGraph`).
pub const GRAPH_PAGE: usize = 1024;
/// Estimated bytes of endpoints after which a page of the graph ends.
pub const GRAPH_PAGE_BYTES: usize = 2 << 20;
/// Answers a client may leave unread beyond its outbox before it counts as not reading.
pub const MAX_BACKLOG_ANSWERS: usize = 1024;
/// Pairs whose news all clients' backlogs may hold together (about 64 bytes each, so about
/// 64 MiB); beyond it the client holding the most is disconnected as not reading. Only a
/// client that stops reading while it or others declare thousands of endpoints on its topics
/// comes near it: a pair waits once however often it changes.
pub const MAX_BACKLOG_PAIRS: usize = 1 << 20;
/// How long a client may read nothing while frames wait before it is disconnected.
pub const SLOW_CLIENT: Duration = Duration::from_secs(10);
/// How often a backlog is retried.
const BACKLOG_RETRY: Duration = Duration::from_millis(10);

#[derive(Debug)]
struct Client {
    link: ClientLink,
    cred: PeerCred,
    backlog: Backlog,
    hello: Option<Hello>,
    entities: BTreeSet<u32>,
}

/// The driver's state.
#[derive(Debug)]
pub struct Driver {
    engine: Engine,
    socket: Arc<UdpSocket>,
    group: Option<SocketAddrV4>,
    peers: Vec<Peer>,
    clients: HashMap<ClientId, Client>,
    by_participant: HashMap<u64, ClientId>,
    counters: Arc<Counters>,
    slow_client: Duration,
    /// Pairs waiting in all clients' backlogs, and the most that may.
    backlog_pairs: usize,
    max_backlog_pairs: usize,
    /// The log lines of incompatible and of refused pairs (see [`crate::log_budget`]).
    incompatible_log: LogBudget,
    refused_log: LogBudget,
}

impl Driver {
    /// A driver around `engine`, sending through `socket` to `group` (`None`: multicast off);
    /// `peers` are the configured peers the engine was given, for the graph.
    pub fn new(
        engine: Engine,
        socket: Arc<UdpSocket>,
        group: Option<SocketAddrV4>,
        peers: Vec<Peer>,
        counters: Arc<Counters>,
    ) -> Self {
        Driver {
            engine,
            socket,
            group,
            peers,
            clients: HashMap::new(),
            by_participant: HashMap::new(),
            counters,
            slow_client: SLOW_CLIENT,
            backlog_pairs: 0,
            max_backlog_pairs: MAX_BACKLOG_PAIRS,
            incompatible_log: LogBudget::default(),
            refused_log: LogBudget::default(),
        }
    }

    /// The most pairs all clients' backlogs may hold together ([`MAX_BACKLOG_PAIRS`]).
    pub fn set_max_backlog_pairs(&mut self, pairs: usize) {
        self.max_backlog_pairs = pairs;
    }

    /// Pairs waiting in all clients' backlogs now.
    pub fn backlog_pairs(&self) -> usize {
        self.backlog_pairs
    }

    /// How long a client may read nothing while frames wait for it ([`SLOW_CLIENT`]).
    pub fn set_slow_client(&mut self, after: Duration) {
        self.slow_client = after;
    }

    /// When the engine's timer must fire next, or a client's backlog be retried.
    pub fn deadline(&self) -> Option<Instant> {
        let engine = self.engine.poll_timeout();
        if self.clients.values().any(|c| !c.backlog.is_empty()) {
            let retry = Instant::now() + BACKLOG_RETRY;
            return Some(engine.map_or(retry, |at| at.min(retry)));
        }
        engine
    }

    /// Runs the engine's due timers.
    pub fn on_timer(&mut self) {
        let now = Instant::now();
        self.engine.handle_timeout(now);
        // The engine's timer fires at least once per announce period.
        if let Some(held_back) = self.incompatible_log.ended(now) {
            held_back_incompatible(held_back, self.incompatible_log.window());
        }
        if let Some(held_back) = self.refused_log.ended(now) {
            held_back_refused(held_back, self.refused_log.window());
        }
    }

    /// Handles one input.
    pub fn on_input(&mut self, input: Input) {
        match input {
            Input::Datagram { from, via, bytes } => {
                self.engine
                    .handle_datagram(Instant::now(), from, via, &bytes);
            }
            Input::Opened { client, link, cred } => {
                self.clients.insert(
                    client,
                    Client {
                        link,
                        cred,
                        backlog: Backlog::default(),
                        hello: None,
                        entities: BTreeSet::new(),
                    },
                );
            }
            Input::Frame { client, message } => self.on_frame(client, message),
            Input::Closed { client, reason } => self.on_closed(client, &reason),
        }
    }

    /// Seals with `keyring`'s sending key and accepts its keys only (a rotation step).
    pub fn set_keyring(&mut self, keyring: ndds_core::seal::Keyring) {
        self.engine.set_keyring(keyring);
    }

    /// A new version of the permissions document: every remote endpoint is judged again.
    pub fn set_permissions(
        &mut self,
        permissions: std::sync::Arc<ndds_core::security::Permissions>,
    ) {
        let until = crate::security::valid_until(&permissions);
        self.engine.set_permissions(permissions, until);
    }

    /// Says `Bye` and stops discovery.
    pub fn close(&mut self) {
        self.engine.close();
    }

    /// Sends the engine's pending datagrams and routes its events, until neither is left
    /// (routing an event can drop a slow client, whose withdrawal must go out now).
    pub async fn flush(&mut self) {
        loop {
            let mut idle = true;
            while let Some(transmit) = self.engine.poll_transmit() {
                idle = false;
                self.transmit(transmit).await;
            }
            while let Some(event) = self.engine.poll_event() {
                idle = false;
                self.route(event);
            }
            if idle && self.drain_backlogs() {
                return;
            }
        }
    }

    async fn transmit(&mut self, transmit: Transmit) {
        let to = match (transmit.destination, self.group) {
            (Destination::Multicast, Some(group)) => group,
            // The engine never addresses the group when multicast is off.
            (Destination::Multicast, None) => return,
            (Destination::Unicast(locator), _) => SocketAddrV4::from(locator),
        };
        if let Err(err) = self.socket.send_to(&transmit.payload, to).await {
            self.counters.send_errors.fetch_add(1, Ordering::Relaxed);
            tracing::warn!(%to, %err, "discovery send failed");
        }
    }

    fn route(&mut self, event: Event) {
        let (local, message) = match event {
            Event::Matched { local, remote } => {
                if let Some(keys) = self.pair_keys(local, &remote) {
                    self.send_to_owner(local, keys);
                }
                (
                    local,
                    DaemonMessage::Matched {
                        local: local.entity,
                        remote,
                    },
                )
            }
            Event::Incompatible { local, remote } => {
                let budget = &mut self.incompatible_log;
                if let Verdict::Log { held_back } = budget.ask(Instant::now()) {
                    held_back_incompatible(held_back, budget.window());
                    tracing::warn!(
                        topic = remote.topic,
                        local = %local,
                        remote = %remote.guid,
                        remote_type = remote.type_desc.short_name(),
                        "incompatible types on one topic"
                    );
                }
                (
                    local,
                    DaemonMessage::Incompatible {
                        local: local.entity,
                        remote,
                    },
                )
            }
            Event::Refused {
                local,
                remote,
                reason,
            } => {
                let budget = &mut self.refused_log;
                if let Verdict::Log { held_back } = budget.ask(Instant::now()) {
                    held_back_refused(held_back, budget.window());
                    tracing::info!(
                        topic = remote.topic,
                        local = %local,
                        remote = %remote.guid,
                        %reason,
                        "pair refused by the permissions document"
                    );
                }
                (
                    local,
                    DaemonMessage::NotPermitted {
                        local: local.entity,
                        remote,
                        reason,
                    },
                )
            }
            Event::Unmatched { local, remote } => (
                local,
                DaemonMessage::Unmatched {
                    local: local.entity,
                    remote,
                },
            ),
            Event::NodeDiscovered { node, info } => {
                tracing::info!(node = %hex(node), host = info.hostname, at = %info.unicast, "node discovered");
                return;
            }
            Event::NodeLost { node, reason } => {
                tracing::info!(node = %hex(node), ?reason, "node lost");
                return;
            }
        };
        self.send_to_owner(local, message);
    }

    /// Sends `message` to the client that owns `local`.
    fn send_to_owner(&mut self, local: Guid, message: DaemonMessage) {
        if let Some(client) = self.by_participant.get(&local.participant).copied() {
            self.send(client, message);
        }
    }

    /// The data keys of `local`'s pair with `remote`, in a domain with permissions.
    fn pair_keys(&self, local: Guid, remote: &EndpointInfo) -> Option<DaemonMessage> {
        let keys = self.engine.data_keys(&local, &remote.guid)?;
        Some(DaemonMessage::PairKeys {
            local: local.entity,
            participant: remote.guid.participant,
            locator: remote.locator,
            keys,
        })
    }

    fn send(&mut self, client: ClientId, message: DaemonMessage) {
        let Some(entry) = self.clients.get_mut(&client) else {
            return;
        };
        let message = if entry.backlog.is_empty() {
            match entry.link.outbox.try_send(message) {
                Ok(()) => return,
                // The connection already ended (a client that just exited); its `Closed` input
                // is on its way and cleans up. Nothing to report.
                Err(mpsc::error::TrySendError::Closed(_)) => return,
                Err(mpsc::error::TrySendError::Full(message)) => {
                    entry.backlog.stalled_since = Some(Instant::now());
                    message
                }
            }
        } else {
            message
        };
        // Behind what already waits, to keep the order.
        match message {
            // The pair's `Matched` waits among the pairs, and its keys are sent again with it.
            DaemonMessage::PairKeys { .. } => {}
            DaemonMessage::Matched { local, remote }
            | DaemonMessage::Incompatible { local, remote }
            | DaemonMessage::NotPermitted { local, remote, .. } => {
                self.backlog_pairs += usize::from(entry.backlog.pairs.insert((local, remote.guid)));
            }
            DaemonMessage::Unmatched { local, remote } => {
                self.backlog_pairs += usize::from(entry.backlog.pairs.insert((local, remote)));
            }
            answer if entry.backlog.answers.len() < MAX_BACKLOG_ANSWERS => {
                entry.backlog.answers.push_back(answer);
            }
            _ => self.drop_slow(client),
        }
        if self.backlog_pairs > self.max_backlog_pairs {
            self.drop_hoarder();
        }
    }

    /// Disconnects the client whose backlog holds the most pairs, when all together hold
    /// more than the bound.
    fn drop_hoarder(&mut self) {
        let hoarder = self
            .clients
            .iter()
            .max_by_key(|(_, c)| c.backlog.pairs.len())
            .map(|(id, c)| (*id, c.backlog.pairs.len()));
        if let Some((client, pairs)) = hoarder {
            tracing::warn!(
                client,
                pairs,
                bound = self.max_backlog_pairs,
                "the match news waiting for clients that do not read passed the daemon's bound"
            );
            self.drop_slow(client);
        }
    }

    fn drop_slow(&mut self, client: ClientId) {
        self.counters.slow_clients.fetch_add(1, Ordering::Relaxed);
        tracing::warn!(client, "client is not reading its socket; disconnecting it");
        if let Some(entry) = self.clients.get(&client) {
            entry.link.cancel.cancel();
        }
        self.on_closed(client, "not reading");
    }

    /// Sends what waits in the clients' backlogs, as far as their outboxes take it; drops a
    /// client that read nothing for [`SLOW_CLIENT`]. True when nothing new happened in the
    /// engine (dropping a client withdraws its endpoints, which the caller must flush).
    fn drain_backlogs(&mut self) -> bool {
        let waiting: Vec<ClientId> = self
            .clients
            .iter()
            .filter(|(_, c)| !c.backlog.is_empty())
            .map(|(id, _)| *id)
            .collect();
        let mut quiet = true;
        for client in waiting {
            self.drain(client);
            let now = Instant::now();
            let stalled = self
                .clients
                .get(&client)
                .and_then(|c| c.backlog.stalled_since);
            if stalled.is_some_and(|since| now.duration_since(since) >= self.slow_client) {
                self.drop_slow(client);
                quiet = false;
            }
        }
        quiet
    }

    fn drain(&mut self, client: ClientId) {
        let Some(entry) = self.clients.get(&client) else {
            return;
        };
        let Some(participant) = entry.hello.as_ref().map(|h| h.participant) else {
            return;
        };
        loop {
            let Some(entry) = self.clients.get_mut(&client) else {
                return;
            };
            let Ok(permit) = entry.link.outbox.try_reserve() else {
                return;
            };
            let message = if let Some(answer) = entry.backlog.answers.pop_front() {
                answer
            } else if let Some((entity, remote)) = entry.backlog.pairs.pop_first() {
                self.backlog_pairs -= 1;
                let local = Guid {
                    participant,
                    entity,
                };
                let now = pair_now(&self.engine, local, remote);
                match &now {
                    DaemonMessage::Matched { remote, .. } => {
                        let keys = self.engine.data_keys(&local, &remote.guid).map(|keys| {
                            DaemonMessage::PairKeys {
                                local: local.entity,
                                participant: remote.guid.participant,
                                locator: remote.locator,
                                keys,
                            }
                        });
                        match keys {
                            Some(keys) => {
                                entry.backlog.answers.push_front(now);
                                keys
                            }
                            None => now,
                        }
                    }
                    _ => now,
                }
            } else {
                entry.backlog.stalled_since = None;
                return;
            };
            permit.send(message);
            entry.backlog.stalled_since = Some(Instant::now());
        }
    }

    fn on_frame(&mut self, client: ClientId, message: ClientMessage) {
        // Frames still queued from a connection that was refused or dropped are ignored.
        if !self.clients.contains_key(&client) {
            return;
        }
        let has_session = self.clients.get(&client).is_some_and(|c| c.hello.is_some());
        match message {
            ClientMessage::Hello(hello) if !has_session => self.on_hello(client, hello),
            ClientMessage::Hello(_) => self.protocol_error(client, "second Hello"),
            _ if !has_session => self.refuse(client, "the first frame must be Hello".into()),
            ClientMessage::Declare(decl) => self.on_declare(client, decl),
            ClientMessage::Undeclare { entity } => self.on_undeclare(client, entity),
            ClientMessage::QueryGraph { request, after } => {
                let (graph, next) = self.graph_page(after);
                self.send(
                    client,
                    DaemonMessage::Graph {
                        request,
                        graph,
                        next,
                    },
                );
            }
        }
    }

    fn on_hello(&mut self, client: ClientId, mut hello: Hello) {
        if hello.ipc_version != IPC_VERSION {
            let reason = format!(
                "client speaks ipc version {}, this daemon speaks {IPC_VERSION}",
                hello.ipc_version
            );
            return self.refuse(client, reason);
        }
        let identity = self.engine.identity();
        if hello.participant == 0 {
            hello.participant = self.new_participant_id();
        } else if self.by_participant.contains_key(&hello.participant) {
            let reason = format!("participant id {} is in use", hex(hello.participant));
            return self.refuse(client, reason);
        } else if let Some(identity) = identity
            && !ndds_core::security::owns_node_id(&identity, hello.participant)
        {
            // A client coming back after a restart of this daemon keeps its id: the identity
            // is the same. Another daemon's client is not let in under its old id.
            let reason = format!(
                "participant id {} is not one of this daemon's identity ({identity}); in a \
                 domain with permissions the daemon gives each client its id: reconnect \
                 without one",
                hex(hello.participant)
            );
            return self.refuse(client, reason);
        }
        // Who connected is the kernel's word; the pid in Hello is the client's own (it differs
        // across pid namespaces) and only logged.
        let cred = self.clients.get(&client).map(|c| c.cred);
        tracing::info!(
            client,
            uid = cred.map(|c| c.uid),
            pid = cred.map(|c| c.pid),
            hello_pid = hello.pid,
            name = hello.name,
            role = ?hello.role,
            "client connected"
        );
        let participant = hello.participant;
        self.by_participant.insert(participant, client);
        if let Some(entry) = self.clients.get_mut(&client) {
            entry.hello = Some(hello);
        }
        let welcome = self.welcome(participant);
        self.send(client, DaemonMessage::Welcome(welcome));
    }

    /// A participant id for a client that asked for one: unused here, and in a domain with
    /// permissions one of this daemon's identity (as its node id is), so that other daemons
    /// believe only this one about the client's endpoints.
    fn new_participant_id(&self) -> u64 {
        let identity = self.engine.identity();
        loop {
            let drawn = fastrand::u64(..);
            let id = match &identity {
                Some(identity) => ndds_core::security::node_id_for(identity, drawn),
                None => drawn,
            };
            if id != 0 && id != self.engine.node_id() && !self.by_participant.contains_key(&id) {
                return id;
            }
        }
    }

    fn welcome(&self, participant: u64) -> Welcome {
        let config = self.engine.config();
        Welcome {
            ipc_version: IPC_VERSION,
            node: self.engine.node_id(),
            participant,
            domain: config.domain,
            hostname: config.hostname.clone(),
            interface: config.unicast.addr,
            pid: config.pid,
            version: config.version.clone(),
            pairwise: self.engine.identity().is_some(),
        }
    }

    fn refuse(&mut self, client: ClientId, reason: String) {
        self.counters
            .sessions_refused
            .fetch_add(1, Ordering::Relaxed);
        tracing::warn!(client, %reason, "session refused");
        self.send(client, DaemonMessage::Refused { reason });
        // Dropping the link ends the connection once `Refused` is written.
        if let Some(entry) = self.clients.remove(&client) {
            self.backlog_pairs -= entry.backlog.pairs.len();
        }
    }

    fn protocol_error(&mut self, client: ClientId, what: &str) {
        self.counters
            .protocol_errors
            .fetch_add(1, Ordering::Relaxed);
        tracing::warn!(client, what, "protocol error; disconnecting client");
        if let Some(entry) = self.clients.get(&client) {
            entry.link.cancel.cancel();
        }
        self.on_closed(client, what);
    }

    fn on_declare(&mut self, client: ClientId, decl: EndpointDecl) {
        let Some(entry) = self.clients.get(&client) else {
            return;
        };
        let Some(hello) = entry.hello.as_ref() else {
            return;
        };
        let entity = decl.entity;
        let info = EndpointInfo {
            guid: Guid {
                participant: hello.participant,
                entity,
            },
            topic: decl.topic,
            type_desc: decl.type_desc,
            fingerprint: decl.fingerprint,
            qos: decl.qos,
            locator: decl.locator,
            pid: hello.pid,
            process: hello.name.clone(),
        };
        let result = self
            .engine
            .add_local(Instant::now(), info)
            .map_err(|err| err.to_string());
        if result.is_ok()
            && let Some(entry) = self.clients.get_mut(&client)
        {
            entry.entities.insert(entity);
        }
        // `Declared` goes out before the match events the declaration caused.
        self.send(client, DaemonMessage::Declared { entity, result });
    }

    fn on_undeclare(&mut self, client: ClientId, entity: u32) {
        let Some(entry) = self.clients.get_mut(&client) else {
            return;
        };
        let Some(hello) = entry.hello.as_ref() else {
            return;
        };
        if entry.entities.remove(&entity) {
            let guid = Guid {
                participant: hello.participant,
                entity,
            };
            self.engine.remove_locals(&[guid]);
        }
    }

    fn on_closed(&mut self, client: ClientId, reason: &str) {
        let Some(entry) = self.clients.remove(&client) else {
            return;
        };
        self.backlog_pairs -= entry.backlog.pairs.len();
        let Some(hello) = entry.hello else {
            return;
        };
        tracing::info!(
            client,
            pid = hello.pid,
            name = hello.name,
            reason,
            "client disconnected"
        );
        self.by_participant.remove(&hello.participant);
        let guids: Vec<Guid> = entry
            .entities
            .iter()
            .map(|entity| Guid {
                participant: hello.participant,
                entity: *entity,
            })
            .collect();
        self.engine.remove_locals(&guids);
    }

    /// The daemon's current view, as `ndds topics` and `ndds nodes` show it, whole.
    pub fn graph(&self) -> Graph {
        let (mut graph, mut next) = self.graph_page(None);
        while let Some(after) = next {
            let (page, more) = self.graph_page(Some(after));
            graph.endpoints.extend(page.endpoints);
            next = more;
        }
        graph.endpoints.sort_by(|a, b| {
            (a.info.topic.as_str(), a.info.guid).cmp(&(b.info.topic.as_str(), b.info.guid))
        });
        graph
    }

    /// One page of the view: the endpoints with guids after `after`, in guid order, at most
    /// [`GRAPH_PAGE`] of them or [`GRAPH_PAGE_BYTES`] (at least one); with the guid to
    /// continue after, if more remain. The first page (`after` is `None`) also carries the
    /// nodes and clients; a later one only its endpoints (with the local summary and the
    /// counters), and costs its own length, not the table's.
    pub fn graph_page(&self, after: Option<Guid>) -> (Graph, Option<Guid>) {
        let now = Instant::now();
        let millis_until = |t: Instant| t.saturating_duration_since(now).as_millis() as u64;
        let millis_since = |t: Instant| now.saturating_duration_since(t).as_millis() as u64;
        let local_info = self.engine.node_info();
        let local = NodeSummary {
            node: self.engine.node_id(),
            interface: local_info.unicast.addr,
            info: local_info,
            multicast: self.group.map(Locator::from),
            last_seen_ms: 0,
            expires_in_ms: None,
            peers: self.peer_summaries(),
            multicast_seen_ms: None,
            unicast_copies: false,
            identity: self.engine.identity().map(|id| id.to_string()),
            subject: (self.engine.identity())
                .and_then(|id| self.engine.subject_of(&id).map(str::to_owned)),
            authenticated: self.engine.identity().is_some(),
            refused_endpoints: 0,
        };
        let copies: HashSet<Locator> = (self.engine.fanout().into_iter())
            .filter_map(|d| match d {
                Destination::Unicast(locator) => Some(locator),
                Destination::Multicast => None,
            })
            .collect();
        let mut refused: std::collections::HashMap<u64, u32> = std::collections::HashMap::new();
        let first = after.is_none();
        for entry in self.engine.endpoints().filter(|_| first) {
            if let (Origin::Remote(node), Some(_)) = (entry.origin, &entry.refused) {
                *refused.entry(node).or_default() += 1;
            }
        }
        let hostnames: std::collections::HashMap<u64, &str> = self
            .engine
            .nodes()
            .map(|(node, remote)| (node, remote.info.hostname.as_str()))
            .collect();
        let mut nodes: Vec<NodeSummary> = self
            .engine
            .nodes()
            .filter(|_| first)
            .map(|(node, remote)| NodeSummary {
                node,
                interface: remote.info.unicast.addr,
                info: remote.info.clone(),
                multicast: None,
                last_seen_ms: millis_since(remote.last_seen),
                expires_in_ms: Some(millis_until(remote.expires)),
                peers: Vec::new(),
                multicast_seen_ms: remote.last_multicast.map(millis_since),
                unicast_copies: copies.contains(&remote.info.unicast),
                identity: remote.identity.map(|id| id.to_string()),
                subject: (remote.identity.as_ref())
                    .and_then(|id| self.engine.subject_of(id).map(str::to_owned)),
                authenticated: remote.identity.is_some(),
                refused_endpoints: refused.get(&node).copied().unwrap_or(0),
            })
            .collect();
        nodes.sort_by(|a, b| {
            a.info
                .hostname
                .cmp(&b.info.hostname)
                .then(a.node.cmp(&b.node))
        });
        let hostname_of = |origin: Origin| match origin {
            Origin::Local => (self.engine.node_id(), local.info.hostname.clone()),
            Origin::Remote(node) => (
                node,
                hostnames.get(&node).copied().unwrap_or_default().to_owned(),
            ),
        };
        let mut listed = self.engine.endpoints_after(after).peekable();
        let mut page: Vec<&ndds_core::discovery::Entry> = Vec::new();
        let mut bytes = 0;
        while let Some(entry) = listed
            .next_if(|_| page.len() < GRAPH_PAGE && (page.is_empty() || bytes < GRAPH_PAGE_BYTES))
        {
            bytes += ndds_core::discovery::table::entry_cost(&entry.info);
            page.push(entry);
        }
        let next = listed
            .peek()
            .is_some()
            .then(|| page.last().map(|entry| entry.info.guid))
            .flatten();
        let endpoints: Vec<EndpointSummary> = page
            .into_iter()
            .map(|entry| {
                let (node, hostname) = hostname_of(entry.origin);
                EndpointSummary {
                    info: entry.info.clone(),
                    node,
                    hostname,
                    expires_in_ms: entry.expires.map(millis_until),
                }
            })
            .collect();
        let graph = Graph {
            local,
            nodes,
            clients: if first {
                self.client_summaries()
            } else {
                Vec::new()
            },
            endpoints,
            counters: self.counters(),
        };
        (graph, next)
    }

    /// The configured peers, each with the node currently known at its locator.
    fn peer_summaries(&self) -> Vec<PeerSummary> {
        self.peers
            .iter()
            .map(|peer| PeerSummary {
                name: peer.spec.to_string(),
                locator: peer.locator,
                node: self
                    .engine
                    .nodes()
                    .find(|(_, remote)| remote.info.unicast == peer.locator)
                    .map(|(id, _)| id),
            })
            .collect()
    }

    fn client_summaries(&self) -> Vec<ClientSummary> {
        let mut clients: Vec<ClientSummary> = self
            .clients
            .values()
            .filter_map(|c| {
                let hello = c.hello.as_ref()?;
                Some(ClientSummary {
                    participant: hello.participant,
                    pid: c.cred.pid,
                    uid: c.cred.uid,
                    name: hello.name.clone(),
                    role: hello.role,
                    endpoints: c.entities.len() as u32,
                })
            })
            .collect();
        clients.sort_by_key(|c| (c.role == Role::Tool, c.pid, c.participant));
        clients
    }

    fn counters(&self) -> Vec<(String, u64)> {
        let stats = self.engine.stats();
        let mut out = vec![
            ("datagrams_received".to_owned(), stats.received),
            ("datagrams_accepted".to_owned(), stats.accepted),
            ("datagrams_sent".to_owned(), stats.sent),
            ("bytes_received".to_owned(), stats.bytes_received),
            ("bytes_sent".to_owned(), stats.bytes_sent),
            ("invalid_endpoints".to_owned(), stats.invalid_endpoints),
            ("evicted_nodes".to_owned(), stats.evicted_nodes),
            ("refused_full".to_owned(), stats.refused_full),
        ];
        for reason in DropReason::ALL {
            out.push((format!("dropped_{}", reason.name()), stats.dropped(reason)));
        }
        let c = &self.counters;
        for (name, value) in [
            ("input_overflow", &c.input_overflow),
            ("sessions_refused", &c.sessions_refused),
            ("slow_clients", &c.slow_clients),
            ("protocol_errors", &c.protocol_errors),
            ("send_errors", &c.send_errors),
            ("connections_refused", &c.connections_refused),
        ] {
            out.push((name.to_owned(), value.load(Ordering::Relaxed)));
        }
        // A sealed domain's (all 0 in an open one but `sealed_without_key`).
        out.push(("sealed_without_key".to_owned(), stats.sealed_without_key));
        out.push(("seal_opened".to_owned(), stats.seal.opened));
        for reason in OpenError::ALL {
            out.push((
                format!("seal_dropped_{}", reason.name()),
                stats.seal.dropped(reason),
            ));
        }
        out.push(("unsealable".to_owned(), stats.unsealable));
        out
    }
}

/// Says how many incompatible pairs were not logged (none: says nothing).
fn held_back_incompatible(held_back: u64, window: Duration) {
    if held_back > 0 {
        tracing::warn!(
            held_back,
            window_s = window.as_secs(),
            "more pairs with incompatible types than the log takes in a window: these were not \
             logged; each was still sent to its client (`ndds topics` lists the types on a topic)"
        );
    }
}

/// Says how many refused pairs were not logged (none: says nothing).
fn held_back_refused(held_back: u64, window: Duration) {
    if held_back > 0 {
        tracing::info!(
            held_back,
            window_s = window.as_secs(),
            "more pairs refused by the permissions document than the log takes in a window: \
             these were not logged; each was still sent to its client"
        );
    }
}

/// A node or participant id as tools print it.
pub fn hex(id: u64) -> String {
    format!("{id:016x}")
}

/// The message that tells the owner of `local` the current state of its pair with `remote`.
fn pair_now(engine: &Engine, local: Guid, remote: Guid) -> DaemonMessage {
    let local_entry = engine.endpoint(&local);
    let remote_entry = engine.endpoint(&remote);
    match (local_entry, remote_entry) {
        (Some(l), Some(r)) if l.info.topic == r.info.topic && l.info.kind() != r.info.kind() => {
            let refused = r.refused.as_ref().or(l.refused.as_ref());
            let (l, r) = (&l.info, &r.info);
            if let Some(refusal) = refused {
                DaemonMessage::NotPermitted {
                    local: local.entity,
                    remote: r.clone(),
                    reason: refusal.to_string(),
                }
            } else if ndds_core::discovery::incompatibility(l, r).is_none() {
                DaemonMessage::Matched {
                    local: local.entity,
                    remote: r.clone(),
                }
            } else {
                DaemonMessage::Incompatible {
                    local: local.entity,
                    remote: r.clone(),
                }
            }
        }
        _ => DaemonMessage::Unmatched {
            local: local.entity,
            remote,
        },
    }
}

//! The discovery engine of one node (daemon).
//!
//! # Call order
//! The driver owns one [`Engine`] and loops:
//! 1. feed input: [`Engine::handle_datagram`] for each received datagram, saying whether it
//!    came through the multicast group or to the unicast locator ([`Via`]),
//!    [`Engine::add_local`] / [`Engine::remove_locals`] for client requests, and
//!    [`Engine::handle_timeout`] when the instant named by [`Engine::poll_timeout`] is reached;
//! 2. drain output: send every [`Engine::poll_transmit`], deliver every [`Engine::poll_event`];
//! 3. re-arm its single timer to [`Engine::poll_timeout`].
//!
//! # Behaviour
//! At creation the engine schedules `Solicit`s (see [`DiscoveryConfig::solicit_delays`]) and an
//! immediate full announcement. Every `announce_period` (± jitter) it sends a full
//! announcement to the domain. A new local endpoint is announced at once; removed ones are
//! withdrawn at once and repeated in the next announcements. Remote nodes and endpoints decay
//! when not refreshed within the lease their node announced. [`Engine::close`] says `Bye`.
//!
//! "To the domain" means the multicast group plus unicast copies to configured peers and to
//! nodes not heard by multicast lately: see [`super::fanout`] for the rule. Commands
//! ([`Engine::add_local`], [`Engine::remove_locals`], [`Engine::close`]) take no time; the
//! fan-out they need is judged at the instant of the latest input.

use std::collections::{BTreeSet, HashMap, HashSet, VecDeque};
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::config::{ConfigError, DiscoveryConfig, MAX_PEERS};
use super::event::{Destination, Event, LossReason, Transmit};
use super::fanout::{Fanout, Via};
use super::freshness::{Counts, Gone};
use super::sources::Sources;
use super::table::{Entry, Origin, Table, entry_cost};
use crate::seal::{self, Keyring, OpenError, OpenStats, Opener, Route, SealSetup, Sealer};
use crate::security::{DataKeys, Guard, Permissions, PublicId, Refusal};
use crate::wire::signed::{self, SIGNED_OVERHEAD};
use crate::wire::{
    self, Announce, Bye, DropReason, EndpointInfo, Guid, Header, Locator, MAX_DATAGRAM, Message,
    NodeInfo, Probe, ProbeReply, Solicit, Withdraw,
};

/// Longest topic name accepted, in bytes.
pub const MAX_TOPIC_LEN: usize = 256;
/// Most remote nodes remembered; beyond it, nodes are evicted (see [`super::sources`]).
pub const MAX_NODES: usize = 4096;
/// Most endpoints remembered per remote node; further new ones are ignored and counted.
pub const MAX_ENDPOINTS_PER_NODE: usize = 16_384;
/// Most remote endpoints remembered in all; beyond it, nodes are evicted (see
/// [`super::sources`]).
pub const MAX_REMOTE_ENDPOINTS: usize = 262_144;
/// Most bytes (estimated: [`super::table::entry_cost`], [`NODE_OVERHEAD`]) the remote nodes
/// and their endpoints may hold; beyond it, nodes are evicted (see [`super::sources`]).
pub const MAX_REMOTE_BYTES: usize = 32 << 20;
/// Bytes a remote node's own entry is estimated to hold, beyond its host name and version.
pub const NODE_OVERHEAD: usize = 512;
/// Most answers to solicitations waiting for their jitter delay.
pub const MAX_PENDING_REPLIES: usize = 1024;
/// Longest lease accepted from a remote node; longer ones are shortened to this.
pub const MAX_LEASE: Duration = Duration::from_secs(60);
/// How often an address that has not answered is probed again (at most).
pub const PROBE_INTERVAL: Duration = Duration::from_millis(500);
/// Withdrawn guids carried per announcement datagram.
const WITHDRAWN_PER_DATAGRAM: usize = 1024;

/// A remote node as this engine knows it.
#[derive(Clone, Debug)]
pub struct RemoteNode {
    /// What it last said about itself.
    pub info: NodeInfo,
    /// Source address of its last datagram.
    pub last_from: SocketAddr,
    /// When it was last heard from.
    pub last_seen: Instant,
    /// When a `Solicit` or `Announce` of it last arrived through the multicast group (`None`:
    /// never).
    pub last_multicast: Option<Instant>,
    /// When it is forgotten unless refreshed.
    pub expires: Instant,
    /// The address it is charged to (the source address of its datagrams).
    pub source: IpAddr,
    /// Estimated bytes it holds here: its own entry and its endpoints.
    pub charged: usize,
    /// The identity that signs its datagrams (domains with permissions; `None`: it signs
    /// nothing, or this engine checks no signatures).
    pub identity: Option<PublicId>,
    /// The secret this node's daemon and this one share (from their agreement keys), from
    /// which the data keys of their participants' pairs derive.
    shared: Option<Shared>,
    /// The agreement key `shared` was computed with (computed again only when it changes).
    agreement: Option<[u8; 32]>,
    /// The numbers its signed datagrams were taken with (domains with permissions).
    counts: Option<Counts>,
}

/// A shared secret, never printed.
#[derive(Clone, Copy)]
struct Shared([u8; 32]);

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Shared(..)")
    }
}

/// A signing identity and its agreement key, as a `Signed` datagram names them.
type Speaker = (PublicId, [u8; 32]);

impl RemoteNode {
    /// Whether its datagrams come from the locator it announces, as a daemon's do (it sends
    /// everything from its unicast socket). Only such a node is ever sent anything unasked.
    pub fn speaks_from_its_locator(&self) -> bool {
        self.last_from == SocketAddr::V4(self.info.unicast.into())
    }
}

/// Counters kept by the engine.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Datagrams handed to [`Engine::handle_datagram`].
    pub received: u64,
    /// Datagrams accepted and processed.
    pub accepted: u64,
    /// Datagrams produced for sending (one per destination).
    pub sent: u64,
    /// Bytes of the datagrams handed to [`Engine::handle_datagram`].
    pub bytes_received: u64,
    /// Bytes of the datagrams produced for sending (one copy per destination).
    pub bytes_sent: u64,
    /// Dropped datagrams by reason, indexed by [`DropReason::index`].
    pub dropped: [u64; DropReason::ALL.len()],
    /// Announced endpoints ignored because they broke a rule: bad layout or topic, wrong
    /// fingerprint, a guid of one of our own endpoints, or more than
    /// [`MAX_ENDPOINTS_PER_NODE`] endpoints for one node.
    pub invalid_endpoints: u64,
    /// Sealed datagrams that arrived while this node holds no domain key.
    pub sealed_without_key: u64,
    /// What opening sealed datagrams came to (a domain with a key; see [`crate::seal`]).
    pub seal: OpenStats,
    /// Datagrams not sent because they could not be sealed or grew too large sealed.
    pub unsealable: u64,
    /// Remote nodes evicted (with their endpoints) to make room in full tables.
    pub evicted_nodes: u64,
    /// New remote nodes or endpoints refused because the tables were full and their own
    /// source was the busiest (nobody else's entries are evicted for it).
    pub refused_full: u64,
    /// Remote endpoints the permissions document does not allow (each time one is announced
    /// new or changed, or refused again after the document or the node's identity changed).
    pub refused_endpoints: u64,
    /// Local declarations the permissions document does not allow this node's subject (at
    /// declaration, or when a new document no longer allows them).
    pub refused_local: u64,
    /// Announced endpoints ignored because their participant id is not one of the announcing
    /// node's identity (domains with permissions: a daemon speaking for another's clients).
    pub foreign_participants: u64,
}

impl Stats {
    /// The count for one drop reason.
    pub fn dropped(&self, reason: DropReason) -> u64 {
        self.dropped[reason.index()]
    }
}

/// Why a local endpoint was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LocalError {
    /// An endpoint with this guid exists already.
    #[error("endpoint {0} is already declared")]
    Duplicate(Guid),
    /// Empty or overlong topic name.
    #[error("topic name must be 1 to {MAX_TOPIC_LEN} bytes, got {0}")]
    TopicName(usize),
    /// The type layout breaks a protocol limit.
    #[error("type description rejected: {0}")]
    Layout(#[from] crate::types::LayoutError),
    /// The declared fingerprint is not the fingerprint of the declared type.
    #[error("fingerprint {declared:016x} does not match the type description ({computed:016x})")]
    Fingerprint {
        /// As declared.
        declared: u64,
        /// As computed from the description.
        computed: u64,
    },
    /// The declaration cannot be announced in one datagram.
    #[error("declaration of {size} bytes does not fit in one datagram ({MAX_DATAGRAM} bytes)")]
    TooLarge {
        /// Encoded size of an announcement carrying only this endpoint.
        size: usize,
    },
    /// The permissions document does not allow this node's subject the endpoint.
    #[error("not permitted: {0}")]
    NotPermitted(Refusal),
    /// In a domain with permissions, the endpoint's participant id is not one of this
    /// daemon's identity ([`crate::security::node_id_for`]): other daemons would refuse it.
    #[error(
        "participant id {0:016x} is not one of this daemon's identity (in a domain with \
         permissions the daemon gives each client its participant id)"
    )]
    ForeignParticipant(u64),
    /// The node declares [`MAX_ENDPOINTS_PER_NODE`] endpoints already: other daemons would
    /// ignore any more.
    #[error(
        "this daemon declares {MAX_ENDPOINTS_PER_NODE} endpoints already, the most other daemons \
         take from one node: withdraw some, or spread the programs over more hosts"
    )]
    TooMany,
    /// The engine was closed.
    #[error("the discovery engine is closed")]
    Closed,
}

/// The sans-IO discovery engine. See the module docs for the call order.
#[derive(Debug)]
pub struct Engine {
    config: DiscoveryConfig,
    node_id: u64,
    rng: fastrand::Rng,
    table: Table,
    nodes: HashMap<u64, RemoteNode>,
    node_expiry: BTreeSet<(Instant, u64)>,
    /// What each source address holds, for eviction when the tables are full.
    sources: Sources,
    /// Unicast locators that answered a probe: only they get replies and unicast copies.
    validated: HashSet<Locator>,
    /// When each locator was last probed.
    probed: HashMap<Locator, Instant>,
    /// Locators owed a full announcement once they answer their probe.
    reply_wanted: HashSet<Locator>,
    /// Keys the probe tokens.
    probe_secret: [u8; 32],
    withdrawn: VecDeque<(Guid, u8)>,
    solicits: VecDeque<Instant>,
    replies: Vec<(Instant, Locator)>,
    next_announce: Instant,
    next_expiry: Option<Instant>,
    fanout: Fanout,
    /// The instant of the latest input: the "now" of commands.
    now: Instant,
    transmits: VecDeque<Transmit>,
    events: VecDeque<Event>,
    stats: Stats,
    closed: bool,
    id_clash_reported: bool,
    /// Seals what is sent and opens what arrives, in a domain with a key.
    seal: Option<(Sealer, Opener)>,
    /// A received datagram's copy, opened in place (reused).
    opened: Vec<u8>,
    /// What was said in the log once already: (keyless traffic seen, sealed traffic seen).
    warned: (bool, bool),
    /// Unsigned traffic was reported once, in a domain with permissions.
    warned_unsigned: bool,
    /// The number of the last signed datagram sent.
    signed_count: u64,
    /// The highest datagram numbers of nodes that are gone.
    gone: Gone,
    /// Local endpoints declared within `declare_coalesce` of an announced declaration, to be
    /// announced together at `declared_hold`.
    declared: Vec<Guid>,
    /// Until when declarations are held after one was announced.
    declared_hold: Option<Instant>,
    /// Identity and permissions, in a domain with a permissions document.
    guard: Option<Guard>,
    /// The permissions document's validity ended.
    permissions_expired: bool,
}

impl Engine {
    /// Creates an engine that starts discovering at `now`.
    pub fn new(config: DiscoveryConfig, now: Instant) -> Result<Self, ConfigError> {
        config.validate()?;
        let mut rng = fastrand::Rng::with_seed(config.seed);
        let drawn = loop {
            let id = rng.u64(..);
            if id != 0 {
                break id;
            }
        };
        let node_id = config.node_id.filter(|id| *id != 0).unwrap_or(drawn);
        let solicits = config.solicit_delays.iter().map(|d| now + *d).collect();
        let fanout = Fanout::new(&config);
        let probe_secret = config
            .probe_secret
            .unwrap_or_else(|| probe_secret(config.seed, node_id));
        Ok(Engine {
            config,
            node_id,
            rng,
            table: Table::default(),
            nodes: HashMap::new(),
            node_expiry: BTreeSet::new(),
            sources: Sources::default(),
            validated: HashSet::new(),
            probed: HashMap::new(),
            reply_wanted: HashSet::new(),
            probe_secret,
            withdrawn: VecDeque::new(),
            solicits,
            replies: Vec::new(),
            next_announce: now,
            next_expiry: None,
            fanout,
            now,
            transmits: VecDeque::new(),
            events: VecDeque::new(),
            stats: Stats::default(),
            closed: false,
            id_clash_reported: false,
            seal: None,
            opened: Vec::new(),
            warned: (false, false),
            warned_unsigned: false,
            signed_count: 0,
            gone: Gone::default(),
            declared: Vec::new(),
            declared_hold: None,
            guard: None,
            permissions_expired: false,
        })
    }

    /// Signs every datagram sent from now on with `guard`'s identity, binds each remote node to
    /// the identity that signs its datagrams, and lets only the endpoints `guard`'s document
    /// allows match (see [`crate::security`]). Called right after [`Engine::new`], before any
    /// traffic; [`Engine::set_permissions`] replaces the document later.
    pub fn guard_with(&mut self, guard: Guard) {
        if !crate::security::owns_node_id(&guard.identity.public(), self.node_id) {
            tracing::error!(
                node = format_args!("{:016x}", self.node_id),
                "this node id is not one of this identity's (security::node_id_for): other \
                 daemons will refuse everything this one says"
            );
        }
        self.guard = Some(guard);
        self.permissions_expired = false;
    }

    /// Replaces the permissions document (a new version was installed): every endpoint, local
    /// and remote, is judged again, and matches come and go accordingly (a local endpoint the
    /// new document refuses stays declared but matches nothing; its pairs are told why). Does
    /// nothing without [`Engine::guard_with`].
    pub fn set_permissions(&mut self, permissions: Arc<Permissions>, valid_until: Option<Instant>) {
        let Some(guard) = &mut self.guard else {
            return;
        };
        guard.permissions = permissions;
        guard.valid_until = valid_until;
        self.permissions_expired = valid_until.is_some_and(|at| at <= self.now);
        let permissions = Arc::clone(&guard.permissions);
        self.gone
            .retain(|identity| permissions.subject(identity).is_some());
        self.judge_all();
    }

    /// The permissions document in force, if any.
    pub fn permissions(&self) -> Option<&Arc<Permissions>> {
        self.guard.as_ref().map(|g| &g.permissions)
    }

    /// This node's identity, in a domain with permissions.
    pub fn identity(&self) -> Option<PublicId> {
        self.guard.as_ref().map(|g| g.identity.public())
    }

    /// The subject name the document gives `identity`.
    pub fn subject_of(&self, identity: &PublicId) -> Option<&str> {
        let guard = self.guard.as_ref()?;
        guard.permissions.subject(identity).map(|s| s.name.as_str())
    }

    /// Seals every datagram sent from now on and accepts only sealed ones (a domain with a
    /// key). Called right after [`Engine::new`], before any traffic.
    pub fn seal_with(&mut self, setup: SealSetup) {
        let sealer = Sealer::new(
            &setup.keyring,
            self.config.domain,
            self.node_id,
            setup.session,
            setup.mode,
        );
        let opener = Opener::new(setup.keyring, self.config.domain, setup.require_encryption);
        self.seal = Some((sealer, opener));
    }

    /// A rotation step: seals with `keyring`'s sending key and accepts its keys only.
    pub fn set_keyring(&mut self, keyring: Keyring) {
        if let Some((sealer, opener)) = &mut self.seal {
            sealer.rekey(&keyring);
            opener.set_keyring(keyring);
        }
    }

    /// This node's id (the sender id of its datagrams).
    pub fn node_id(&self) -> u64 {
        self.node_id
    }

    /// The configuration in use.
    pub fn config(&self) -> &DiscoveryConfig {
        &self.config
    }

    /// What this node says about itself.
    pub fn node_info(&self) -> NodeInfo {
        NodeInfo {
            hostname: self.config.hostname.clone(),
            pid: self.config.pid,
            unicast: self.config.unicast,
            lease_ms: u32::try_from(self.config.lease.as_millis()).unwrap_or(u32::MAX),
            announce_period_ms: u32::try_from(self.config.announce_period.as_millis())
                .unwrap_or(u32::MAX),
            version: self.config.version.clone(),
        }
    }

    /// Counters.
    pub fn stats(&self) -> &Stats {
        &self.stats
    }

    /// Estimated bytes held by remote nodes and their endpoints (at most [`MAX_REMOTE_BYTES`]).
    pub fn remote_bytes(&self) -> usize {
        self.sources.total()
    }

    /// Known remote nodes.
    pub fn nodes(&self) -> impl Iterator<Item = (u64, &RemoteNode)> {
        self.nodes.iter().map(|(id, node)| (*id, node))
    }

    /// The configured peers in use: sorted, without duplicates or this node's own locator.
    pub fn peers(&self) -> &[Locator] {
        self.fanout.peers()
    }

    /// Where a datagram for the whole domain would go now (see [`super::fanout`]).
    pub fn fanout(&self) -> Vec<Destination> {
        let stale = self
            .nodes
            .values()
            .filter(|node| node.speaks_from_its_locator())
            .filter(|node| self.is_validated(node.info.unicast))
            .filter(|node| self.fanout.multicast_stale(node.last_multicast, self.now))
            .map(|node| node.info.unicast);
        self.fanout.destinations(stale)
    }

    /// Every known endpoint, local and remote.
    pub fn endpoints(&self) -> impl Iterator<Item = &Entry> {
        self.table.iter()
    }

    /// The endpoints with guids after `after` (all for `None`), in guid order: a page of a
    /// listing costs its own length, not the table's.
    pub fn endpoints_after(&self, after: Option<Guid>) -> impl Iterator<Item = &Entry> {
        self.table.after(after)
    }

    /// The entry of one endpoint.
    pub fn endpoint(&self, guid: &Guid) -> Option<&Entry> {
        self.table.get(guid)
    }

    // ----- input -------------------------------------------------------------------------

    /// Processes one received datagram, which arrived from `from` through `via`.
    pub fn handle_datagram(&mut self, now: Instant, from: SocketAddr, via: Via, bytes: &[u8]) {
        self.now = self.now.max(now);
        self.stats.received += 1;
        self.stats.bytes_received += bytes.len() as u64;
        let mut opened = std::mem::take(&mut self.opened);
        let Some(plain) = self.unseal(now, from, bytes, &mut opened) else {
            self.opened = opened;
            return;
        };
        let result = self.accept(now, from, via, plain);
        self.opened = opened;
        match result {
            Ok(()) => self.stats.accepted += 1,
            Err(reason) => {
                self.stats.dropped[reason.index()] += 1;
                tracing::trace!(%from, reason = reason.name(), "dropped discovery datagram");
            }
        }
        self.update_expiry();
    }

    /// The plain datagram: opened (into `scratch`) in a domain with a key, as it came
    /// otherwise; `None`, counted (and said once in the log, naming the sender's address),
    /// when it must be dropped.
    fn unseal<'a>(
        &mut self,
        now: Instant,
        from: SocketAddr,
        bytes: &'a [u8],
        scratch: &'a mut Vec<u8>,
    ) -> Option<&'a [u8]> {
        match seal::route(bytes, self.seal.is_some()) {
            Route::Plain => return Some(bytes),
            Route::Junk(reason) => {
                self.stats.dropped[reason.index()] += 1;
                return None;
            }
            Route::SealedWithoutKey => {
                self.stats.sealed_without_key += 1;
                if !std::mem::replace(&mut self.warned.1, true) {
                    tracing::warn!(
                        %from,
                        "sealed discovery traffic arrives and this daemon has no domain key: give \
                         it the domain's key file (--key-file or NDDS_KEY_FILE), or unseal the \
                         sender"
                    );
                }
                return None;
            }
            Route::Open => {}
        }
        let (_, opener) = self.seal.as_mut()?;
        scratch.clear();
        scratch.extend_from_slice(bytes);
        let opened = opener.open(now, scratch);
        self.stats.seal.clone_from(opener.stats());
        match opened {
            Ok(plain) => Some(plain),
            Err(error) => {
                if error == OpenError::NotSealed && !std::mem::replace(&mut self.warned.0, true) {
                    tracing::warn!(
                        %from,
                        "unsealed discovery traffic arrives in a domain with a key: dropped; give \
                         the sender the domain's key file (--key-file), or remove the key here"
                    );
                }
                None
            }
        }
    }

    fn accept(
        &mut self,
        now: Instant,
        from: SocketAddr,
        via: Via,
        bytes: &[u8],
    ) -> Result<(), DropReason> {
        if self.closed {
            return Err(DropReason::Unexpected);
        }
        let (outer, _) = Header::parse(bytes)?;
        if outer.domain != self.config.domain {
            return Err(DropReason::OtherDomain);
        }
        let (bytes, identity, count) = if outer.kind == wire::MessageKind::Signed {
            let view = signed::parse(bytes)?;
            if outer.sender == self.node_id {
                self.check_id_clash(from);
                return Err(DropReason::Own);
            }
            // Only an engine that enforces permissions checks signatures (and believes them).
            if self.guard.is_some() {
                view.verify()?;
                // A node id is its identity's: nobody takes another daemon's id first.
                if !crate::security::owns_node_id(&view.identity, outer.sender) {
                    return Err(DropReason::Unverified);
                }
                (
                    view.inner,
                    Some((view.identity, view.agreement)),
                    view.count,
                )
            } else {
                (view.inner, None, 0)
            }
        } else {
            (bytes, None, 0)
        };
        let (header, message) = wire::decode_for_domain(bytes, self.config.domain)?;
        if header.sender == self.node_id {
            self.check_id_clash(from);
            return Err(DropReason::Own);
        }
        // In a domain with permissions every daemon signs everything it sends: an unsigned
        // datagram is nobody's word.
        if self.guard.is_some() && identity.is_none() {
            if !std::mem::replace(&mut self.warned_unsigned, true) {
                tracing::warn!(
                    %from,
                    "unsigned discovery traffic in a domain with permissions: dropped; give that \
                     daemon the domain's permissions document (--permissions, --admin-key)"
                );
            }
            return Err(DropReason::Unverified);
        }
        // Node ids travel in clear: a known node speaks only from its own address, so nobody
        // else can say its `Bye`, withdraw its endpoints or shorten its lease. (A node whose
        // address changes is heard again once its old entry has expired.) Checked before
        // anything of the datagram is believed, its identity included.
        if self
            .nodes
            .get(&header.sender)
            .is_some_and(|known| known.last_from != from)
        {
            return Err(DropReason::Spoofed);
        }
        self.check_identity(header.sender, identity)?;
        // Each signed datagram once: a recorded one re-sealed by a holder of the domain key is
        // refused (a node that is gone, below the highest number it was heard with).
        let first_count = match (identity, self.nodes.get_mut(&header.sender)) {
            (None, _) => None,
            (Some(_), Some(known)) => match &mut known.counts {
                Some(counts) => {
                    if !counts.take(count) {
                        return Err(DropReason::Replayed);
                    }
                    None
                }
                None => Some(0),
            },
            (Some((said, _)), None) => {
                let floor = self.gone.floor(&said, header.sender);
                if count <= floor {
                    return Err(DropReason::Replayed);
                }
                Some(floor)
            }
        };
        self.act(now, (from, via), header, message, identity)?;
        if let Some(floor) = first_count
            && let Some(known) = self.nodes.get_mut(&header.sender)
        {
            known.counts = Some(Counts::new(floor, count));
        }
        Ok(())
    }

    /// Does what an accepted discovery message says.
    fn act(
        &mut self,
        now: Instant,
        (from, via): (SocketAddr, Via),
        header: Header,
        message: Message,
        identity: Option<Speaker>,
    ) -> Result<(), DropReason> {
        match message {
            Message::Solicit(solicit) => {
                check_node(&solicit.node)?;
                let unicast = solicit.node.unicast;
                self.touch_node(now, header.sender, (from, via), solicit.node, identity)?;
                self.schedule_reply(now, unicast, from);
            }
            Message::Announce(announce) => {
                check_node(&announce.node)?;
                let unicast = announce.node.unicast;
                self.on_announce(now, header, (from, via), announce, identity)?;
                // A probe lost, or answered late: asked again (at most every PROBE_INTERVAL)
                // while the node speaks from an address it has not proven.
                if from == SocketAddr::V4(unicast.into()) && !self.is_validated(unicast) {
                    self.probe(now, unicast);
                }
            }
            Message::Withdraw(withdraw) => {
                for guid in &withdraw.endpoints {
                    self.remove_remote(header.sender, guid);
                }
            }
            Message::Bye(Bye) => self.forget_node(header.sender, LossReason::Bye),
            // As large as the probe: answering anyone amplifies nothing.
            Message::Probe(Probe { token }) => {
                let SocketAddr::V4(to) = from else {
                    return Err(DropReason::Invalid);
                };
                let reply = Message::ProbeReply(ProbeReply { token });
                self.encode_and_push(&[Destination::Unicast(Locator::from(to))], &reply);
            }
            Message::ProbeReply(ProbeReply { token }) => {
                let SocketAddr::V4(at) = from else {
                    return Err(DropReason::Invalid);
                };
                let at = Locator::from(at);
                // Only an answer to a probe still outstanding, for an address a known node
                // announces: nobody can fill the validated set with addresses of nobody.
                let announced = self.nodes.values().any(|node| node.info.unicast == at);
                if token != self.probe_token(at) || !announced || self.probed.remove(&at).is_none()
                {
                    return Err(DropReason::Invalid);
                }
                if self.validated.len() < MAX_NODES + MAX_PEERS {
                    self.validated.insert(at);
                }
                if self.reply_wanted.remove(&at) {
                    self.schedule_reply(now, at, from);
                }
            }
        }
        Ok(())
    }

    /// The token a `Probe` to `at` carries: only this engine can compute it.
    fn probe_token(&self, at: Locator) -> u64 {
        use sha2::Digest as _;
        let digest = sha2::Sha256::new()
            .chain_update(self.probe_secret)
            .chain_update(at.addr)
            .chain_update(at.port.to_be_bytes())
            .finalize();
        u64::from_be_bytes(digest[..8].try_into().expect("8 bytes"))
    }

    /// Whether `at` proved that it receives there (or is a configured peer): only then does it
    /// get more than probes.
    fn is_validated(&self, at: Locator) -> bool {
        self.validated.contains(&at) || self.fanout.peers().contains(&at)
    }

    /// Sends `at` a probe, at most once per `PROBE_INTERVAL`.
    fn probe(&mut self, now: Instant, at: Locator) {
        if self
            .probed
            .get(&at)
            .is_some_and(|sent| now.saturating_duration_since(*sent) < PROBE_INTERVAL)
        {
            return;
        }
        if self.probed.len() >= MAX_PENDING_REPLIES {
            // Probes unanswered for a while are given up, with the replies they held back.
            let (probed, wanted) = (&mut self.probed, &mut self.reply_wanted);
            probed.retain(|_, sent| now.saturating_duration_since(*sent) < PROBE_INTERVAL * 4);
            wanted.retain(|at| probed.contains_key(at));
            if self.probed.len() >= MAX_PENDING_REPLIES {
                return;
            }
        }
        self.probed.insert(at, now);
        let probe = Message::Probe(Probe {
            token: self.probe_token(at),
        });
        self.encode_and_push(&[Destination::Unicast(at)], &probe);
    }

    fn on_announce(
        &mut self,
        now: Instant,
        header: Header,
        (from, via): (SocketAddr, Via),
        announce: Announce,
        identity: Option<Speaker>,
    ) -> Result<(), DropReason> {
        let node = header.sender;
        let lease = lease_of(&announce.node);
        let unicast = announce.node.unicast;
        if self.touch_node(now, node, (from, via), announce.node, identity)? {
            // A node we did not know: answer with everything we have so it need not wait for
            // our next refresh (its Solicit may have been lost).
            self.schedule_reply(now, unicast, from);
        }
        for guid in &announce.withdrawn {
            self.remove_remote(node, guid);
        }
        for info in announce.endpoints {
            self.upsert_remote(node, from.ip(), now + lease, info);
        }
        Ok(())
    }

    /// Queues a unicast full announcement to `to` after a random delay, once per destination.
    /// Only a locator that is also the datagram's source is answered: a datagram naming some
    /// other address cannot turn this node into a reflector toward it.
    fn schedule_reply(&mut self, now: Instant, to: Locator, from: SocketAddr) {
        if from != SocketAddr::V4(to.into()) {
            tracing::debug!(%from, announced = %to, "not answering: source is not the announced locator");
            return;
        }
        if !self.is_validated(to) {
            // First the proof that it receives there; the answer follows the proof.
            if self.reply_wanted.len() < MAX_PENDING_REPLIES {
                self.reply_wanted.insert(to);
            }
            self.probe(now, to);
            return;
        }
        if self.replies.len() >= MAX_PENDING_REPLIES || self.replies.iter().any(|(_, d)| *d == to) {
            return;
        }
        let delay = self.jitter(self.config.reply_jitter);
        self.replies.push((now + delay, to));
    }

    /// Records that `node` spoke; returns true when it was not known before.
    fn touch_node(
        &mut self,
        now: Instant,
        node: u64,
        (from, via): (SocketAddr, Via),
        info: NodeInfo,
        identity: Option<Speaker>,
    ) -> Result<bool, DropReason> {
        let lease = lease_of(&info);
        let by_multicast = (via == Via::Multicast).then_some(now);
        if let Some(known) = self.nodes.get_mut(&node) {
            self.node_expiry.remove(&(known.expires, node));
            if known.source == from.ip() {
                self.sources.heard(known.source, node, known.last_seen, now);
            } else {
                self.sources
                    .remove(known.source, node, known.last_seen, known.charged);
                self.sources.add(from.ip(), node, now, known.charged);
                known.source = from.ip();
            }
            known.info = info;
            known.last_from = from;
            known.last_seen = now;
            known.last_multicast = by_multicast.or(known.last_multicast);
            known.expires = now + lease;
            self.node_expiry.insert((known.expires, node));
            self.recharge(node);
            return Ok(false);
        }
        let cost = node_cost(&info);
        if !self.make_room(cost, None, |engine| engine.nodes.len() >= MAX_NODES) {
            return Err(DropReason::Invalid);
        }
        self.events.push_back(Event::NodeDiscovered {
            node,
            info: info.clone(),
        });
        self.nodes.insert(
            node,
            RemoteNode {
                info,
                last_from: from,
                last_seen: now,
                last_multicast: by_multicast,
                expires: now + lease,
                source: from.ip(),
                charged: cost,
                identity: identity.map(|(id, _)| id),
                shared: identity.and_then(|speaker| self.shared_with(speaker)),
                agreement: identity.map(|(_, agreement)| agreement),
                counts: None,
            },
        );
        self.sources.add(from.ip(), node, now, cost);
        self.node_expiry.insert((now + lease, node));
        Ok(true)
    }

    /// Evicts nodes until `bytes` more fit and `full` no longer holds; false (counted) when
    /// the busiest source holds only `keep`, so nothing may be evicted for it.
    fn make_room(
        &mut self,
        bytes: usize,
        keep: Option<u64>,
        full: impl Fn(&Engine) -> bool,
    ) -> bool {
        while full(self) || self.sources.total() + bytes > MAX_REMOTE_BYTES {
            let Some(victim) = self.sources.victim(keep) else {
                self.stats.refused_full += 1;
                return false;
            };
            if self.stats.evicted_nodes.is_power_of_two() || self.stats.evicted_nodes == 0 {
                tracing::warn!(
                    node = format_args!("{victim:016x}"),
                    evicted = self.stats.evicted_nodes + 1,
                    "discovery tables full; evicting the oldest node of the busiest source"
                );
            }
            self.stats.evicted_nodes += 1;
            self.forget_node(victim, LossReason::Evicted);
        }
        true
    }

    /// Brings a node's charge up to date with its endpoints.
    fn recharge(&mut self, node: u64) {
        let endpoints = self.table.bytes_of(Origin::Remote(node));
        if let Some(known) = self.nodes.get_mut(&node) {
            let now = node_cost(&known.info) + endpoints;
            if now != known.charged {
                self.sources.recharge(known.source, known.charged, now);
                known.charged = now;
            }
        }
    }

    fn upsert_remote(&mut self, node: u64, source: IpAddr, expires: Instant, info: EndpointInfo) {
        // A node's clients live on its host: an endpoint whose locator is elsewhere would turn
        // its matches into a stream of data aimed at someone else.
        if IpAddr::from(info.locator.addr) != source {
            self.stats.invalid_endpoints += 1;
            tracing::debug!(guid = %info.guid, locator = %info.locator, %source, "ignored endpoint located off its node's host");
            return;
        }
        // In a domain with permissions a participant id is its daemon's identity's, as node ids
        // are: nobody announces endpoints in another daemon's participants' names (their pairs
        // would get keys with the wrong daemon).
        if self.guard.is_some()
            && !self
                .nodes
                .get(&node)
                .and_then(|n| n.identity)
                .is_some_and(|id| crate::security::owns_node_id(&id, info.guid.participant))
        {
            self.stats.foreign_participants += 1;
            tracing::debug!(guid = %info.guid, node = format_args!("{node:016x}"), "ignored endpoint of a participant of another identity");
            return;
        }
        let owner = self.table.get(&info.guid).map(|e| e.origin);
        // Another node's endpoint changes only by that node; moving it here (a client whose
        // daemon restarted) needs the very same declaration, from the same host.
        if let Some(Origin::Remote(other)) = owner
            && other != node
            && self.table.get(&info.guid).is_some_and(|e| e.info != info)
        {
            self.stats.invalid_endpoints += 1;
            return;
        }
        // Nobody may announce one of our own endpoints, and no node more than its share.
        let over_cap = owner != Some(Origin::Remote(node))
            && self.table.count_owned(Origin::Remote(node)) >= MAX_ENDPOINTS_PER_NODE;
        if owner == Some(Origin::Local) || over_cap {
            self.stats.invalid_endpoints += 1;
            return;
        }
        if self.table.get(&info.guid).is_some_and(|e| e.info == info) {
            // Unchanged: a refresh. If another node owned it, the owning client moved to this
            // node (its daemon restarted with a new node id): the newest announcement wins,
            // without a flap.
            self.table
                .move_to(&info.guid, Origin::Remote(node), expires);
            self.recharge(node);
            if let Some(Origin::Remote(previous)) = owner.filter(|o| *o != Origin::Remote(node)) {
                self.recharge(previous);
                // A new owner is judged as itself: the endpoint's pairs get its keys, so it
                // must be allowed them.
                let refused = self.judge(node, &info);
                self.table
                    .set_refused(&info.guid, refused, &mut self.events);
            }
            return;
        }
        if let Err(reason) = check_endpoint(&info) {
            self.stats.invalid_endpoints += 1;
            tracing::debug!(guid = %info.guid, %reason, "ignored announced endpoint");
            return;
        }
        let guid = info.guid;
        if let Some(Origin::Remote(previous)) = owner {
            self.table.remove(&guid, &mut self.events);
            self.recharge(previous);
        }
        let is_new = |engine: &Engine| {
            engine.table.get(&guid).is_none() && engine.table.count_remote() >= MAX_REMOTE_ENDPOINTS
        };
        if !self.make_room(entry_cost(&info), Some(node), is_new) || !self.nodes.contains_key(&node)
        {
            self.stats.invalid_endpoints += 1;
            return;
        }
        let refused = self.judge(node, &info);
        let entry = Entry {
            info,
            origin: Origin::Remote(node),
            expires: Some(expires),
            refused,
        };
        self.table.insert(entry, &mut self.events);
        self.recharge(node);
    }

    /// Whether the permissions document lets `node` have `info`; the refusal is counted and
    /// logged (at debug level: a refused node repeats itself every announcement).
    fn judge(&mut self, node: u64, info: &EndpointInfo) -> Option<Arc<Refusal>> {
        let identity = self.nodes.get(&node).and_then(|n| n.identity);
        let refusal = self.verdict(identity.as_ref(), info)?;
        self.stats.refused_endpoints += 1;
        tracing::debug!(
            node = format_args!("{node:016x}"),
            topic = %info.topic,
            %refusal,
            "remote endpoint refused"
        );
        Some(Arc::new(refusal))
    }

    /// Why the document in force does not let `identity` have `info` (`None`: it does, or
    /// there is no document).
    fn verdict(&self, identity: Option<&PublicId>, info: &EndpointInfo) -> Option<Refusal> {
        let permissions = &self.guard.as_ref()?.permissions;
        if self.permissions_expired {
            return Some(Refusal::Expired {
                serial: permissions.serial,
                window: format!("until Unix time {}", permissions.not_after),
            });
        }
        permissions.check(identity, &info.topic, info.kind()).err()
    }

    /// Judges every remote endpoint of `node` again (its identity became known).
    fn judge_node(&mut self, node: u64) {
        for guid in self.table.owned_by(Origin::Remote(node)) {
            let Some(info) = self.table.get(&guid).map(|e| e.info.clone()) else {
                continue;
            };
            let refused = self.judge(node, &info);
            self.table.set_refused(&guid, refused, &mut self.events);
        }
    }

    /// Judges every endpoint again, this node's own too (a new document, or the old one
    /// expired).
    fn judge_all(&mut self) {
        let nodes: Vec<u64> = self.nodes.keys().copied().collect();
        for node in nodes {
            self.judge_node(node);
        }
        let identity = self.identity();
        for guid in self.table.owned_by(Origin::Local) {
            let Some(entry) = self.table.get(&guid) else {
                continue;
            };
            let refused = self.verdict(identity.as_ref(), &entry.info).map(Arc::new);
            if entry.refused.is_none()
                && let Some(refusal) = &refused
            {
                self.stats.refused_local += 1;
                tracing::warn!(
                    endpoint = %guid,
                    topic = %entry.info.topic,
                    %refusal,
                    "a local endpoint is no longer permitted: it matches nothing until a document \
                     allows it again"
                );
            }
            self.table.set_refused(&guid, refused, &mut self.events);
        }
    }

    /// In a domain with permissions, a node is bound to the identity it first signed with:
    /// its datagrams must carry that identity from then on. (A node known unsigned, from
    /// before the engine enforced a document, is bound when it first signs, and its
    /// endpoints are judged again.)
    fn check_identity(&mut self, node: u64, identity: Option<Speaker>) -> Result<(), DropReason> {
        if self.guard.is_none() {
            return Ok(());
        }
        let Some(known) = self.nodes.get(&node) else {
            return Ok(());
        };
        match (known.identity, identity) {
            (Some(bound), Some((said, agreement))) if bound == said => {
                // The agreement key is signed with the identity: the newest one counts. (The
                // secret costs a Diffie-Hellman: only for a key not seen before.)
                if known.agreement != Some(agreement) {
                    let shared = self.shared_with((said, agreement));
                    if let Some(known) = self.nodes.get_mut(&node) {
                        known.shared = shared;
                        known.agreement = Some(agreement);
                    }
                }
                Ok(())
            }
            (Some(_), _) => Err(DropReason::Unverified),
            (None, None) => Ok(()),
            (None, Some((said, agreement))) => {
                let shared = self.shared_with((said, agreement));
                if let Some(known) = self.nodes.get_mut(&node) {
                    known.identity = Some(said);
                    known.shared = shared;
                    known.agreement = Some(agreement);
                }
                self.judge_node(node);
                Ok(())
            }
        }
    }

    /// The secret this engine's identity shares with `speaker`'s agreement key.
    fn shared_with(&self, (_, agreement): Speaker) -> Option<Shared> {
        let guard = self.guard.as_ref()?;
        guard.identity.shared_secret(&agreement).map(Shared)
    }

    /// The data keys of the pair of `local`'s participant and `other`'s, in a domain with
    /// permissions: derived from the secret this daemon shares with `other`'s daemon (or, for
    /// two participants of this node, from this daemon's agreement secret alone). `None` without permissions,
    /// or for a pair the document does not allow, or an endpoint not known.
    pub fn data_keys(&self, local: &Guid, other: &Guid) -> Option<DataKeys> {
        let guard = self.guard.as_ref()?;
        let (mine, theirs) = (self.table.get(local)?, self.table.get(other)?);
        if mine.origin != Origin::Local || mine.refused.is_some() || theirs.refused.is_some() {
            return None;
        }
        let shared = match theirs.origin {
            Origin::Local => guard.identity.derive_agreement(b"local data pairs"),
            Origin::Remote(node) => self.nodes.get(&node)?.shared?.0,
        };
        Some(DataKeys::derive(
            &shared,
            local.participant,
            other.participant,
        ))
    }

    fn remove_remote(&mut self, node: u64, guid: &Guid) {
        if self
            .table
            .get(guid)
            .is_some_and(|e| e.origin == Origin::Remote(node))
        {
            self.table.remove(guid, &mut self.events);
            self.recharge(node);
        }
    }

    fn forget_node(&mut self, node: u64, reason: LossReason) {
        for guid in self.table.owned_by(Origin::Remote(node)) {
            self.table.remove(&guid, &mut self.events);
        }
        if let Some(known) = self.nodes.remove(&node) {
            self.node_expiry.remove(&(known.expires, node));
            // Its recorded datagrams stay refused after it is gone (identities the document
            // names: any other is refused everything anyway).
            if let (Some(identity), Some(counts), Some(guard)) =
                (known.identity, &known.counts, &self.guard)
                && guard.permissions.subject(&identity).is_some()
            {
                self.gone.insert(identity, node, counts.highest());
            }
            self.sources
                .remove(known.source, node, known.last_seen, known.charged);
            let at = known.info.unicast;
            if !self.nodes.values().any(|other| other.info.unicast == at) {
                self.validated.remove(&at);
                self.probed.remove(&at);
                self.reply_wanted.remove(&at);
            }
            self.events.push_back(Event::NodeLost { node, reason });
        }
    }

    /// Declares a local endpoint at `now`: matches it at once and announces it to the domain
    /// (at once, or with the declarations that follow it within `declare_coalesce` of an
    /// announced one).
    pub fn add_local(&mut self, now: Instant, info: EndpointInfo) -> Result<(), LocalError> {
        if self.closed {
            return Err(LocalError::Closed);
        }
        self.now = self.now.max(now);
        if self.table.get(&info.guid).is_some() {
            return Err(LocalError::Duplicate(info.guid));
        }
        check_endpoint(&info)?;
        if self.table.count_owned(Origin::Local) >= MAX_ENDPOINTS_PER_NODE {
            return Err(LocalError::TooMany);
        }
        if let Some(identity) = self.identity()
            && !crate::security::owns_node_id(&identity, info.guid.participant)
        {
            return Err(LocalError::ForeignParticipant(info.guid.participant));
        }
        if let Some(refusal) = self.verdict(self.identity().as_ref(), &info) {
            self.stats.refused_local += 1;
            return Err(LocalError::NotPermitted(refusal));
        }
        let announce = Message::Announce(Announce {
            node: self.node_info(),
            endpoints: vec![info.clone()],
            withdrawn: Vec::new(),
        });
        let mut payload = Vec::new();
        let signing = if self.guard.is_some() {
            SIGNED_OVERHEAD
        } else {
            0
        };
        match wire::encode(self.config.domain, self.node_id, &announce, &mut payload) {
            Err(wire::EncodeError::TooLarge { size }) => {
                return Err(LocalError::TooLarge { size });
            }
            Ok(()) if payload.len() + signing > MAX_DATAGRAM => {
                return Err(LocalError::TooLarge {
                    size: payload.len() + signing,
                });
            }
            _ => {}
        }
        // A guid declared again must no longer be listed as withdrawn.
        self.withdrawn.retain(|(guid, _)| *guid != info.guid);
        let guid = info.guid;
        let entry = Entry {
            info,
            origin: Origin::Local,
            expires: None,
            refused: None,
        };
        self.table.insert(entry, &mut self.events);
        if self.declared_hold.is_some_and(|until| now < until) {
            // A burst: announced with the rest of it when the hold ends.
            self.declared.push(guid);
        } else if !self.declared.is_empty() {
            // The hold ended before the engine's timer ran: everything held goes now.
            self.declared.push(guid);
            self.flush_declared(now);
        } else {
            let destinations = self.fanout();
            self.push_transmits(&destinations, payload.into());
            self.hold_declarations(now);
        }
        Ok(())
    }

    /// Holds declarations for `declare_coalesce` after one was announced.
    fn hold_declarations(&mut self, now: Instant) {
        let hold = self.config.declare_coalesce;
        self.declared_hold = (!hold.is_zero()).then_some(now + hold);
    }

    /// Announces the declarations held, together.
    fn flush_declared(&mut self, now: Instant) {
        let held = std::mem::take(&mut self.declared);
        let infos: Vec<EndpointInfo> = held
            .iter()
            .filter_map(|guid| self.table.get(guid))
            .filter(|entry| entry.origin == Origin::Local)
            .map(|entry| entry.info.clone())
            .collect();
        if infos.is_empty() {
            return;
        }
        let refs: Vec<&EndpointInfo> = infos.iter().collect();
        let destinations = self.fanout();
        for (endpoints, _, _) in self.chunk_endpoints(&refs) {
            let message = Message::Announce(Announce {
                node: self.node_info(),
                endpoints,
                withdrawn: Vec::new(),
            });
            self.encode_and_push(&destinations, &message);
        }
        // A burst that goes on is held again.
        self.hold_declarations(now);
    }

    /// Removes local endpoints (a client closed them or disconnected) and withdraws them.
    /// Unknown guids are ignored.
    pub fn remove_locals(&mut self, guids: &[Guid]) {
        let mut removed = Vec::new();
        for guid in guids {
            if self
                .table
                .get(guid)
                .is_some_and(|e| e.origin == Origin::Local)
            {
                self.table.remove(guid, &mut self.events);
                removed.push(*guid);
            }
        }
        if removed.is_empty() || self.closed {
            return;
        }
        for guid in &removed {
            self.withdrawn
                .push_back((*guid, self.config.withdraw_repeats));
        }
        let destinations = self.fanout();
        for chunk in removed.chunks(2048) {
            let message = Message::Withdraw(Withdraw {
                endpoints: chunk.to_vec(),
            });
            self.encode_and_push(&destinations, &message);
        }
    }

    /// Leaves the domain: says `Bye` and stops producing output.
    pub fn close(&mut self) {
        if self.closed {
            return;
        }
        let destinations = self.fanout();
        self.encode_and_push(&destinations, &Message::Bye(Bye));
        self.closed = true;
    }

    /// Runs the timers that are due at `now`.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.closed {
            return;
        }
        self.now = self.now.max(now);
        // Expire first: a node forgotten now gets no more unicast copies.
        self.expire(now);
        let valid_until = self.guard.as_ref().and_then(|g| g.valid_until);
        if !self.permissions_expired && valid_until.is_some_and(|at| at <= now) {
            tracing::error!(
                "the permissions document's validity ended: every remote endpoint is refused until \
                 a new signed document is installed (`ndds security sign`)"
            );
            self.permissions_expired = true;
            self.judge_all();
        }
        while self.solicits.front().is_some_and(|t| *t <= now) {
            self.solicits.pop_front();
            let message = Message::Solicit(Solicit {
                node: self.node_info(),
            });
            let destinations = self.fanout();
            self.encode_and_push(&destinations, &message);
        }
        let mut due = Vec::new();
        self.replies.retain(|(at, to)| {
            let is_due = *at <= now;
            if is_due && !due.contains(to) {
                due.push(*to);
            }
            !is_due
        });
        for to in due {
            self.announce_all(&[Destination::Unicast(to)], false);
        }
        if !self.declared.is_empty() && self.declared_hold.is_some_and(|at| at <= now) {
            self.flush_declared(now);
        }
        if self.next_announce <= now {
            let destinations = self.fanout();
            // Everything local goes: the declarations held with it.
            self.declared.clear();
            self.announce_all(&destinations, true);
            let jittered = self.jittered_period();
            self.next_announce = now + jittered;
        }
        self.update_expiry();
    }

    fn expire(&mut self, now: Instant) {
        let expired_nodes: Vec<u64> = self
            .node_expiry
            .iter()
            .take_while(|(at, _)| *at <= now)
            .map(|(_, id)| *id)
            .collect();
        for node in expired_nodes {
            tracing::debug!(node = format_args!("{node:016x}"), "node lease expired");
            self.forget_node(node, LossReason::Expired);
        }
        for guid in self.table.expired(now) {
            if let Some(entry) = self.table.remove(&guid, &mut self.events)
                && let Origin::Remote(node) = entry.origin
            {
                self.recharge(node);
            }
        }
    }

    // ----- output ------------------------------------------------------------------------

    /// The next datagram to send.
    pub fn poll_transmit(&mut self) -> Option<Transmit> {
        self.transmits.pop_front()
    }

    /// The next event for the driver.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// When [`Engine::handle_timeout`] must next be called (`None` once closed).
    pub fn poll_timeout(&self) -> Option<Instant> {
        if self.closed {
            return None;
        }
        let mut next = self.next_announce;
        let candidates = self
            .solicits
            .front()
            .copied()
            .into_iter()
            .chain(self.replies.iter().map(|(at, _)| *at))
            .chain(self.declared_hold.filter(|_| !self.declared.is_empty()))
            .chain(self.next_expiry)
            .chain(
                self.guard
                    .as_ref()
                    .and_then(|g| g.valid_until)
                    .filter(|_| !self.permissions_expired),
            );
        for at in candidates {
            next = next.min(at);
        }
        Some(next)
    }

    // ----- helpers -----------------------------------------------------------------------

    /// Sends every local endpoint (split over datagrams of `announce_chunk` bytes) plus the
    /// recent withdrawals. A periodic announcement also ages the withdrawal list.
    fn announce_all(&mut self, destinations: &[Destination], periodic: bool) {
        let withdrawn: Vec<Guid> = self.withdrawn.iter().map(|(g, _)| *g).collect();
        if periodic {
            for (_, left) in self.withdrawn.iter_mut() {
                *left = left.saturating_sub(1);
            }
            self.withdrawn.retain(|(_, left)| *left > 0);
        }
        let mut locals: Vec<&EndpointInfo> = self
            .table
            .iter()
            .filter(|e| e.origin == Origin::Local)
            .map(|e| &e.info)
            .collect();
        locals.sort_by_key(|info| info.guid);
        let mut chunks = self.chunk_endpoints(&locals);
        // A withdrawal list rides along in an endpoint datagram while both fit in one chunk;
        // otherwise it gets a datagram of its own. A guid takes at most 15 bytes.
        for (i, guids) in withdrawn.chunks(WITHDRAWN_PER_DATAGRAM).enumerate() {
            let fits = chunks
                .get(i)
                .is_some_and(|(_, size, _)| size + 15 * guids.len() <= self.config.announce_chunk);
            if fits {
                chunks[i].2 = guids.to_vec();
            } else {
                chunks.push((Vec::new(), 0, guids.to_vec()));
            }
        }
        for (endpoints, _, withdrawn) in chunks {
            let message = Message::Announce(Announce {
                node: self.node_info(),
                endpoints,
                withdrawn,
            });
            self.encode_and_push(destinations, &message);
        }
    }

    /// Splits endpoints into groups of at most `announce_chunk` encoded bytes (an endpoint
    /// larger than that travels alone), with each group's size. Always at least one group, so
    /// a node without endpoints still refreshes its own entry.
    fn chunk_endpoints(
        &self,
        locals: &[&EndpointInfo],
    ) -> Vec<(Vec<EndpointInfo>, usize, Vec<Guid>)> {
        let mut chunks = vec![(Vec::new(), 0, Vec::new())];
        for info in locals {
            let info_size = postcard::to_allocvec(info).map_or(0, |v| v.len());
            let Some(last) = chunks.last_mut() else {
                continue;
            };
            if !last.0.is_empty() && last.1 + info_size > self.config.announce_chunk {
                chunks.push((vec![(*info).clone()], info_size, Vec::new()));
            } else {
                last.0.push((*info).clone());
                last.1 += info_size;
            }
        }
        chunks
    }

    fn encode_and_push(&mut self, destinations: &[Destination], message: &Message) {
        let mut payload = Vec::new();
        match wire::encode(self.config.domain, self.node_id, message, &mut payload) {
            Ok(()) => self.push_transmits(destinations, payload.into()),
            Err(err) => tracing::error!(%err, kind = message.kind().name(), "cannot encode"),
        }
    }

    /// Queues one datagram for each destination; the copies share their bytes.
    fn push_transmits(&mut self, destinations: &[Destination], payload: Arc<[u8]>) {
        // Signed before sealing: the signature speaks for the node, the seal for the domain.
        let payload = match &self.guard {
            None => payload,
            Some(guard) => match signed::wrap(&payload, &guard.identity, {
                self.signed_count += 1;
                self.signed_count
            }) {
                Ok(signed) if signed.len() <= MAX_DATAGRAM => signed.into(),
                _ => {
                    self.stats.unsealable += 1;
                    tracing::error!(
                        bytes = payload.len(),
                        "discovery datagram not signed: not sent"
                    );
                    return;
                }
            },
        };
        // Sealed once: every destination keeps its own replay window, so copies may share
        // one counter.
        let payload = match &mut self.seal {
            None => payload,
            Some((sealer, _)) => {
                let mut sealed = payload.to_vec();
                if sealer.seal(&mut sealed).is_err() || sealed.len() > MAX_DATAGRAM {
                    self.stats.unsealable += 1;
                    tracing::error!(
                        bytes = payload.len(),
                        "discovery datagram not sealed: not sent"
                    );
                    return;
                }
                sealed.into()
            }
        };
        for destination in destinations {
            self.stats.sent += 1;
            self.stats.bytes_sent += payload.len() as u64;
            self.transmits.push_back(Transmit {
                destination: *destination,
                payload: payload.clone(),
            });
        }
    }

    fn update_expiry(&mut self) {
        let node_min = self.node_expiry.first().map(|(at, _)| *at);
        let entry_min = self.table.earliest_expiry();
        self.next_expiry = match (node_min, entry_min) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
    }

    /// Our node id arrived from an address that is not ours: another node uses the same id
    /// (the same configured node id or seed on two hosts). The two cannot see each other.
    fn check_id_clash(&mut self, from: SocketAddr) {
        if from != SocketAddr::V4(self.config.unicast.into()) && !self.id_clash_reported {
            self.id_clash_reported = true;
            tracing::error!(
                %from,
                node = format_args!("{:016x}", self.node_id),
                "another node uses this node's id: the two cannot discover each other (do not \
                 give two daemons the same node id or seed)"
            );
        }
    }

    fn jitter(&mut self, max: Duration) -> Duration {
        max.mul_f64(self.rng.f64())
    }

    fn jittered_period(&mut self) -> Duration {
        let spread = self.config.period_jitter * (2.0 * self.rng.f64() - 1.0);
        self.config.announce_period.mul_f64(1.0 + spread)
    }
}

/// The rules a node's self-description must satisfy.
fn check_node(info: &NodeInfo) -> Result<(), DropReason> {
    let period = u64::from(info.announce_period_ms);
    if period == 0 || info.lease_ms <= info.announce_period_ms || period * 2 > max_lease_ms() {
        return Err(DropReason::Invalid);
    }
    if info.unicast.addr == [0; 4] || info.unicast.port == 0 {
        return Err(DropReason::Invalid);
    }
    Ok(())
}

fn max_lease_ms() -> u64 {
    MAX_LEASE.as_millis() as u64
}

/// The lease a node asked for, capped at [`MAX_LEASE`].
fn lease_of(info: &NodeInfo) -> Duration {
    Duration::from_millis(u64::from(info.lease_ms)).min(MAX_LEASE)
}

/// The rules every endpoint declaration must satisfy, local or announced.
fn check_endpoint(info: &EndpointInfo) -> Result<(), LocalError> {
    if info.topic.is_empty() || info.topic.len() > MAX_TOPIC_LEN {
        return Err(LocalError::TopicName(info.topic.len()));
    }
    info.type_desc.validate()?;
    let computed = info.type_desc.fingerprint();
    if computed != info.fingerprint {
        return Err(LocalError::Fingerprint {
            declared: info.fingerprint,
            computed,
        });
    }
    Ok(())
}

/// The estimated bytes a remote node's own entry holds.
fn node_cost(info: &NodeInfo) -> usize {
    NODE_OVERHEAD + info.hostname.len() + info.version.len()
}

/// The key of an engine's probe tokens, from its seed (random in a daemon) and node id.
fn probe_secret(seed: u64, node_id: u64) -> [u8; 32] {
    use sha2::Digest as _;
    sha2::Sha256::new()
        .chain_update(b"ndds discovery probe")
        .chain_update(seed.to_be_bytes())
        .chain_update(node_id.to_be_bytes())
        .finalize()
        .into()
}

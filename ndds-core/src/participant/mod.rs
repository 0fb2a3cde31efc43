//! The data plane of one participant, without IO: every producer's and consumer's protocol
//! state, driven like the discovery engine (and quinn-proto's `Connection`).
//!
//! A driver feeds it what arrives ([`ParticipantCore::handle_datagram`]) and the passing of
//! time ([`ParticipantCore::handle_timeout`]), gives it commands (declare and withdraw
//! endpoints, apply discovery's matches, write, acknowledge what the application took), and
//! drains what it asks for: datagrams to send ([`ParticipantCore::poll_transmit`]), samples
//! and notifications for the application and producer events
//! ([`ParticipantCore::poll_event`]), and when to call it next
//! ([`ParticipantCore::poll_timeout`]). It owns arbitration, minimum separation and
//! deadline windows, reliable readers and writers, histories, batching, fragmentation and
//! reassembly, repair scheduling, and the rule that only matched traffic is believed. It
//! reads no clock and opens no socket: `ndds-client` drives it with one I/O thread, and the
//! tests drive it over a simulated network in virtual time.
//!
//! ## Receiver rules
//! A `Data` datagram is believed only for the consumers it names that were matched with its
//! writer, and only from the locator discovery gave for that writer (see
//! [`crate::admission`]); `Feedback` only by the producer it names, from a consumer matched
//! with it, at that consumer's locator. Everything else is dropped and counted
//! ([`CoreStats`], [`ConsumerCounters`]).

mod consumer;
mod outbox;
mod producer;
mod repair;
mod sample;
mod transmit;

use std::collections::VecDeque;
use std::net::SocketAddrV4;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use bytes::{Bytes, BytesMut};
use foldhash::{HashMap, HashSet};

pub use consumer::{ConsumerCounters, ConsumerSpec};
pub use outbox::{BatchConfig, BufferPool, MatchedConsumer};
use producer::FeedbackVerdict;
pub use producer::{ProducerSpec, WriteRefused};
pub use sample::{RawSample, SampleInfo};
pub use transmit::Transmit;

use self::consumer::{ConsumerCore, Ctx, Origin, Sent};
use self::outbox::Tx;
use self::producer::ProducerCore;
use self::repair::{PieceOutcome, Repair};
use self::transmit::Transmits;
use crate::admission::{AdmissionStats, Verdict};
use crate::arbitration::Notification;
pub use crate::seal::SealSetup;
use crate::seal::{
    self, Keyring, OVERHEAD, OpenError, OpenStats, Opener, Route, SEAL_HEAD_LEN, Sealer,
};
use crate::wire::data::FLAG_RELIABLE;
use crate::wire::{
    self, DataDatagram, DataSub, DropReason, FeedbackDatagram, FeedbackSub, Guid, MAX_DATAGRAM,
    MessageKind,
};

/// A peer's data keys (domains with permissions) are dropped once it has been matched with
/// none of a participant's endpoints for this long: twice [`crate::seal::SESSION_IDLE`], after
/// which a receiver would take a silent sender's older session anyway.
pub const PAIR_KEY_IDLE: Duration = Duration::from_secs(120);

/// How often a participant holding data keys looks them over.
const PAIR_KEY_SWEEP: Duration = Duration::from_secs(30);

/// A peer this participant holds data keys for.
#[derive(Clone, Copy, Debug)]
struct PairPeer {
    /// Its data socket (where its pair sealer sends).
    at: SocketAddrV4,
    /// When it was last seen matched (or given keys).
    matched_at: Instant,
}

/// What a participant's data plane is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CoreConfig {
    /// The domain.
    pub domain: u16,
    /// This participant's id (the sender of its datagrams).
    pub participant: u64,
    /// Largest datagram sent (the path's MTU minus IP and UDP headers).
    pub max_datagram: usize,
    /// Largest sample accepted or written, in encoded bytes.
    pub max_sample: usize,
    /// A secret of this participant's, from which the address tokens of its data are
    /// derived (feedback must echo them: see `docs/protocol.md`). Unguessable in a driver:
    /// [`CoreConfig::new`] takes one from `fastrand`'s generator (seeded from the operating
    /// system); a driver may put the operating system's random bytes here instead.
    pub secret: [u8; 32],
}

impl CoreConfig {
    /// A configuration for loopback-sized datagrams and 16 MiB samples.
    pub fn new(domain: u16, participant: u64) -> Self {
        CoreConfig {
            domain,
            participant,
            max_datagram: MAX_DATAGRAM,
            max_sample: 16 << 20,
            secret: std::array::from_fn(|_| fastrand::u8(..)),
        }
    }
}

/// What the core hands its driver besides datagrams.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// An accepted sample for a consumer.
    Sample {
        /// The consumer's entity number.
        consumer: u32,
        /// The sample.
        sample: RawSample,
    },
    /// A notification for a consumer (deadline, producer lost, samples lost, ...).
    Notification {
        /// The consumer's entity number.
        consumer: u32,
        /// What happened.
        notification: Notification,
    },
    /// A reliable producer's window opened: a writer waiting for room may go on.
    WindowOpen {
        /// The producer's entity number.
        producer: u32,
    },
    /// A reliable consumer stopped acknowledging and no longer holds the producer's window.
    ReaderSilenced {
        /// The producer's entity number.
        producer: u32,
        /// The silent consumer.
        reader: Guid,
    },
}

/// Counters of the participant's data plane.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CoreStats {
    /// Datagrams handed to [`ParticipantCore::handle_datagram`].
    pub received: u64,
    /// Samples handed to consumers (before admission and arbitration).
    pub delivered: u64,
    /// Datagrams addressed to another participant.
    pub misaddressed: u64,
    /// Samples addressed to a consumer that does not exist (any more).
    pub unknown_reader: u64,
    /// Fragments of large samples refused by reassembly.
    pub fragments_refused: u64,
    /// Samples, heartbeats, gaps and feedback dropped because discovery never matched their
    /// sender with the endpoint they address.
    pub unmatched_sender: u64,
    /// Dropped because they carried a matched sender's id but came from another address.
    pub wrong_address: u64,
    /// Feedback submessages from a matched reader's address that did not echo the address
    /// token of the data sent there: not acted on, except for pieces within 3 times the bytes
    /// such feedback brought (what a host forging the reader's address can get).
    pub unvalidated_feedback: u64,
    /// Pieces asked for by unvalidated feedback and not sent (beyond its allowance).
    pub pieces_withheld: u64,
    /// Dropped datagrams, by [`DropReason::index`].
    pub dropped: [u64; DropReason::ALL.len()],
    /// Datagrams and bytes the core asked to send.
    pub transmits: u64,
    /// Bytes in those datagrams.
    pub transmit_bytes: u64,
    /// Sealed datagrams that arrived while this participant holds no domain key.
    pub sealed_without_key: u64,
    /// What opening sealed datagrams came to (a domain with a key; see [`crate::seal`]).
    pub seal: OpenStats,
    /// Datagrams not sent because they could not be sealed.
    pub unsealable: u64,
    /// Datagrams not sent because their destination has no data key (a domain with
    /// permissions: the pair was never matched by this participant's daemon).
    pub unkeyed: u64,
}

impl CoreStats {
    /// The drop count for one reason.
    pub fn dropped(&self, reason: DropReason) -> u64 {
        self.dropped[reason.index()]
    }
}

/// The consumers one datagram addresses.
type Readers = smallvec::SmallVec<[u32; 8]>;

/// The data plane of one participant (see the module documentation).
#[derive(Debug)]
pub struct ParticipantCore {
    config: CoreConfig,
    consumers: HashMap<u32, ConsumerCore>,
    producers: HashMap<u32, ProducerCore>,
    repair: Repair,
    transmits: Transmits,
    events: VecDeque<Event>,
    /// Consumers with acknowledgements to send at the next [`ParticipantCore::poll_transmit`].
    acks_due: Vec<u32>,
    stats: CoreStats,
    /// Admission counters of endpoints already withdrawn, so totals never go down.
    withdrawn: AdmissionStats,
    /// Opens what arrives, in a domain with a key.
    opener: Option<Opener>,
    /// The send key of each destination's pair sealer, so that the same keys given again keep
    /// the sealer (and its counter) instead of starting a new one at counter 0.
    pair_sends: std::collections::HashMap<SocketAddrV4, [u8; 32]>,
    /// The peers this participant holds data keys for: where they are, and when they were
    /// last matched (their keys are dropped [`PAIR_KEY_IDLE`] after that).
    pair_peers: HashMap<u64, PairPeer>,
    /// Pair sealers made so far: each new one seals for a session of its own, so that no
    /// (key, nonce) is used twice when a pair's keys are dropped and given again.
    pair_sealers_made: u64,
    /// When the pair keys are looked over next.
    next_pair_sweep: Option<Instant>,
    /// What was said in the log once already: (keyless traffic seen, sealed traffic seen).
    warned: (bool, bool),
}

impl ParticipantCore {
    /// A data plane without endpoints.
    pub fn new(config: CoreConfig) -> Self {
        ParticipantCore {
            config,
            consumers: HashMap::default(),
            producers: HashMap::default(),
            repair: Repair::new(config.max_sample),
            transmits: Transmits::default(),
            // Room for what one round of a driver's datagrams produces, so a steady state
            // does not grow it.
            events: VecDeque::with_capacity(1024),
            acks_due: Vec::with_capacity(16),
            stats: CoreStats::default(),
            withdrawn: AdmissionStats::default(),
            opener: None,
            warned: (false, false),
            pair_sends: std::collections::HashMap::new(),
            pair_peers: HashMap::default(),
            pair_sealers_made: 0,
            next_pair_sweep: None,
        }
    }

    /// Seals every datagram sent from now on and accepts only sealed ones (a domain with a
    /// key). Called before any traffic; datagrams shrink by [`crate::seal::OVERHEAD`] so that
    /// sealed ones still fit `max_datagram`.
    pub fn seal_with(&mut self, setup: SealSetup) {
        if self.transmits.sealer.is_none() {
            self.config.max_datagram = self.config.max_datagram.saturating_sub(OVERHEAD);
        }
        self.transmits.sealer = Some(Sealer::new(
            &setup.keyring,
            self.config.domain,
            self.config.participant,
            setup.session,
            setup.mode,
        ));
        self.opener = Some(Opener::new(
            setup.keyring,
            self.config.domain,
            setup.require_encryption,
        ));
    }

    /// A domain with permissions: from now on this participant sends only to peers whose
    /// data keys its daemon gave ([`ParticipantCore::set_pair_keys`]) and opens only their
    /// datagrams, with those keys; a host that holds the domain key but was never matched
    /// can neither read nor write its data. Needs [`ParticipantCore::seal_with`] first (false
    /// otherwise: nothing changes).
    pub fn require_pair_keys(&mut self) -> bool {
        let Some(opener) = &mut self.opener else {
            return false;
        };
        opener.require_pair_keys();
        self.transmits.pairwise = true;
        true
    }

    /// The data keys of this participant's pair with `peer`, whose data socket is `at`
    /// (given by the daemon before each match of the pair). False when this participant
    /// seals nothing, or holds keys for [`crate::seal::MAX_SENDERS`] peers matched within
    /// [`PAIR_KEY_IDLE`]. A peer's keys are dropped once it has been matched with none of
    /// this participant's endpoints for [`PAIR_KEY_IDLE`].
    pub fn set_pair_keys(
        &mut self,
        now: Instant,
        peer: u64,
        at: SocketAddrV4,
        keys: &crate::security::DataKeys,
    ) -> bool {
        if self.opener.is_none() || self.transmits.sealer.is_none() {
            return false;
        }
        let full = |core: &Self| {
            !core.pair_peers.contains_key(&peer)
                && (core.pair_peers.len() >= crate::seal::MAX_SENDERS
                    || (!core.transmits.pair_sealers.contains_key(&at)
                        && core.transmits.pair_sealers.len() >= crate::seal::MAX_SENDERS))
        };
        if full(self) {
            self.sweep_pair_keys(now);
            if full(self) {
                return false;
            }
        }
        let (Some(opener), Some(sealer)) = (&mut self.opener, &self.transmits.sealer) else {
            return false;
        };
        if !opener.set_pair_key(peer, crate::seal::DomainKey::from_bytes(keys.receive)) {
            return false;
        }
        self.pair_peers.insert(
            peer,
            PairPeer {
                at,
                matched_at: now,
            },
        );
        self.next_pair_sweep.get_or_insert(now + PAIR_KEY_SWEEP);
        let sealers = &mut self.transmits.pair_sealers;
        if self.pair_sends.get(&at) == Some(&keys.send) && sealers.contains_key(&at) {
            // The same keys again (another match of the same pair): the sealer keeps its
            // counter, so no (key, nonce) is ever used twice.
            return true;
        }
        // A new sealer seals for a session no sealer of this participant used before: keys
        // given again after they were dropped, or another key and then the first one again,
        // never start a (key, session) over at counter 0.
        self.pair_sealers_made += 1;
        let epoch = sealer.epoch();
        let keyring = Keyring::new(epoch, crate::seal::DomainKey::from_bytes(keys.send))
            .with_cipher(opener.keyring().cipher());
        let pair = Sealer::new(
            &keyring,
            self.config.domain,
            self.config.participant,
            sealer.session().wrapping_add(self.pair_sealers_made),
            sealer.mode(),
        );
        sealers.insert(at, pair);
        self.pair_sends.insert(at, keys.send);
        true
    }

    /// Peers this participant holds data keys for.
    pub fn pair_peers(&self) -> usize {
        self.pair_peers.len()
    }

    /// Drops the data keys of peers matched with none of this participant's endpoints for
    /// [`PAIR_KEY_IDLE`] (the daemon gives them again with a new match).
    fn sweep_pair_keys(&mut self, now: Instant) {
        let matched: HashSet<u64> = self
            .consumers
            .values()
            .flat_map(ConsumerCore::peers)
            .chain(self.producers.values().flat_map(ProducerCore::peers))
            .collect();
        let mut dropped = Vec::new();
        for (peer, state) in &mut self.pair_peers {
            if matched.contains(peer) {
                state.matched_at = now;
            } else if now.saturating_duration_since(state.matched_at) >= PAIR_KEY_IDLE {
                dropped.push((*peer, state.at));
            }
        }
        for (peer, at) in dropped {
            self.pair_peers.remove(&peer);
            if let Some(opener) = &mut self.opener {
                opener.remove_pair_key(peer);
            }
            // The destination's sealer stays while another peer of ours is there.
            if !self.pair_peers.values().any(|other| other.at == at) {
                self.transmits.pair_sealers.remove(&at);
                self.pair_sends.remove(&at);
            }
        }
        self.next_pair_sweep = (!self.pair_peers.is_empty()).then_some(now + PAIR_KEY_SWEEP);
    }

    /// A rotation step: seals with `keyring`'s sending key and accepts its keys only.
    pub fn set_keyring(&mut self, keyring: Keyring) {
        if let Some(sealer) = &mut self.transmits.sealer {
            sealer.rekey(&keyring);
        }
        if let Some(opener) = &mut self.opener {
            opener.set_keyring(keyring);
        }
    }

    /// Its configuration.
    pub fn config(&self) -> CoreConfig {
        self.config
    }

    fn ctx(&mut self) -> (Ctx<'_>, &mut HashMap<u32, ConsumerCore>) {
        (
            Ctx {
                domain: self.config.domain,
                participant: self.config.participant,
                out: &mut self.transmits,
                events: &mut self.events,
                acks_due: &mut self.acks_due,
            },
            &mut self.consumers,
        )
    }

    fn tx(
        &mut self,
    ) -> (
        Tx<'_>,
        &mut HashMap<u32, ProducerCore>,
        &mut VecDeque<Event>,
    ) {
        (
            Tx {
                domain: self.config.domain,
                participant: self.config.participant,
                max_datagram: self.config.max_datagram,
                secret: &self.config.secret,
                out: &mut self.transmits,
            },
            &mut self.producers,
            &mut self.events,
        )
    }

    // ---- consumers ----

    /// Declares consumer `entity` (replacing one of the same number).
    pub fn add_consumer(&mut self, now: Instant, entity: u32, spec: ConsumerSpec) {
        let core = ConsumerCore::new(entity, spec, now);
        if let Some(old) = self.consumers.insert(entity, core) {
            self.withdrawn = add(self.withdrawn, old.admission_stats());
        }
    }

    /// Withdraws consumer `entity`; false if there was none.
    pub fn remove_consumer(&mut self, entity: u32) -> bool {
        match self.consumers.remove(&entity) {
            Some(old) => {
                self.withdrawn = add(self.withdrawn, old.admission_stats());
                true
            }
            None => false,
        }
    }

    /// The producers consumer `entity` is matched with now (discovery's view), at their
    /// locators: only their traffic is believed from now on, and what they sent before this
    /// news (held a moment) is acted on.
    pub fn set_consumer_matched(
        &mut self,
        now: Instant,
        entity: u32,
        producers: impl IntoIterator<Item = (Guid, SocketAddrV4)>,
    ) {
        let (mut ctx, consumers) = self.ctx();
        if let Some(consumer) = consumers.get_mut(&entity) {
            consumer.set_matched(&mut ctx, now, producers);
        }
    }

    /// Discovery says producer `writer` is gone for consumer `entity`.
    pub fn producer_lost(&mut self, now: Instant, entity: u32, writer: Guid) {
        let (mut ctx, consumers) = self.ctx();
        if let Some(consumer) = consumers.get_mut(&entity) {
            consumer.writer_lost(&mut ctx, now, writer);
        }
    }

    /// Queues a notification for consumer `entity` among its other events.
    pub fn notify(&mut self, entity: u32, notification: Notification) {
        let (mut ctx, consumers) = self.ctx();
        if let Some(consumer) = consumers.get_mut(&entity) {
            consumer.notify(&mut ctx, notification);
        }
    }

    /// The application took `samples` samples of consumer `entity`: that much credit comes
    /// back, and reliable streams waiting for room deliver again.
    pub fn taken(&mut self, now: Instant, entity: u32, samples: usize) {
        let (mut ctx, consumers) = self.ctx();
        if let Some(consumer) = consumers.get_mut(&entity) {
            consumer.taken(&mut ctx, now, samples);
        }
    }

    /// Consumer `entity` no longer limits what it is handed (it delivers to a callback).
    pub fn set_unlimited(&mut self, now: Instant, entity: u32) {
        let (mut ctx, consumers) = self.ctx();
        if let Some(consumer) = consumers.get_mut(&entity) {
            consumer.set_unlimited(&mut ctx, now);
        }
    }

    /// Counters of consumer `entity`.
    pub fn consumer_counters(&self, entity: u32) -> Option<ConsumerCounters> {
        self.consumers.get(&entity).map(ConsumerCore::counters)
    }

    // ---- producers ----

    /// Declares producer `entity` (replacing one of the same number).
    pub fn add_producer(&mut self, entity: u32, spec: ProducerSpec) {
        if let Some(old) = self
            .producers
            .insert(entity, ProducerCore::new(entity, spec))
        {
            self.withdrawn = add(self.withdrawn, old.believed_stats());
        }
    }

    /// Withdraws producer `entity`, sending what waits in its batches first; false if there
    /// was none.
    pub fn remove_producer(&mut self, entity: u32) -> bool {
        self.flush(entity);
        match self.producers.remove(&entity) {
            Some(old) => {
                self.withdrawn = add(self.withdrawn, old.believed_stats());
                true
            }
            None => false,
        }
    }

    /// The consumers producer `entity` is matched with now: its samples go to them, and
    /// only their feedback is believed.
    pub fn set_producer_matched(
        &mut self,
        now: Instant,
        entity: u32,
        consumers: &[MatchedConsumer],
    ) {
        let (mut tx, producers, events) = self.tx();
        if let Some(producer) = producers.get_mut(&entity) {
            producer.set_matched(&mut tx, events, now, consumers);
        }
    }

    /// Writes one encoded sample with producer `entity`, stamped `timestamp_ns` (the source
    /// time, nanoseconds since the Unix epoch); returns its sequence number. The payload is
    /// shared (not copied) with the history and the datagrams that carry it where they keep
    /// it (take it from a [`BufferPool`]); a batched sample is copied into its batch.
    pub fn write(
        &mut self,
        now: Instant,
        timestamp_ns: u64,
        entity: u32,
        payload: &Arc<Vec<u8>>,
    ) -> Result<u64, WriteRefused> {
        let max_sample = self.config.max_sample;
        let (mut tx, producers, _) = self.tx();
        let producer = producers
            .get_mut(&entity)
            .ok_or(WriteRefused::UnknownProducer(entity))?;
        producer.write(&mut tx, now, timestamp_ns, max_sample, payload)
    }

    /// Queues what waits in producer `entity`'s batches.
    pub fn flush(&mut self, entity: u32) {
        let (mut tx, producers, _) = self.tx();
        if let Some(producer) = producers.get_mut(&entity) {
            producer.flush(&mut tx);
        }
    }

    /// True when producer `entity` may write without waiting (always for best effort).
    pub fn window_open(&self, entity: u32) -> bool {
        self.producers
            .get(&entity)
            .is_none_or(ProducerCore::window_open)
    }

    /// Samples of producer `entity` not yet acknowledged by every reliable consumer.
    pub fn unacknowledged(&self, entity: u32) -> usize {
        self.producers
            .get(&entity)
            .map_or(0, ProducerCore::unacknowledged)
    }

    /// Samples producer `entity` wrote.
    pub fn written(&self, entity: u32) -> u64 {
        self.producers.get(&entity).map_or(0, |p| p.written)
    }

    // ---- input ----

    /// A datagram arrived from `from` at `received` (the wall clock, for the samples' info).
    /// Whatever it causes is queued: transmits, events, timers. A sealed datagram is opened
    /// in place (so the buffer is mutable; samples keep shares of it).
    pub fn handle_datagram(
        &mut self,
        now: Instant,
        received: SystemTime,
        from: SocketAddrV4,
        datagram: BytesMut,
    ) {
        self.stats.received += 1;
        let Some(datagram) = self.unseal(now, from, datagram) else {
            return;
        };
        let kind = match wire::Header::parse(&datagram) {
            Ok((header, _)) if header.domain != self.config.domain => {
                return self.count_drop(DropReason::OtherDomain);
            }
            Ok((header, _)) => header.kind,
            Err(reason) => return self.count_drop(reason),
        };
        let result = match kind {
            MessageKind::Data => self.on_data(now, received, &datagram, from),
            MessageKind::Feedback => self.on_feedback(now, &datagram, from),
            // A discovery message: counted as malformed when its body does not decode, else
            // as unexpected here.
            _ => match wire::decode_for_domain(&datagram, self.config.domain) {
                Ok(_) => Err(DropReason::Unexpected),
                Err(reason) => Err(reason),
            },
        };
        if let Err(reason) = result {
            self.count_drop(reason);
        }
    }

    /// The plain datagram: opened in place in a domain with a key, as it came otherwise;
    /// `None`, counted (and said once in the log, naming the sender's address), when it must
    /// be dropped.
    fn unseal(
        &mut self,
        now: Instant,
        from: SocketAddrV4,
        mut datagram: BytesMut,
    ) -> Option<Bytes> {
        match seal::route(&datagram, self.opener.is_some()) {
            Route::Plain => return Some(datagram.freeze()),
            Route::Junk(reason) => {
                self.stats.dropped[reason.index()] += 1;
                return None;
            }
            Route::SealedWithoutKey => {
                self.stats.sealed_without_key += 1;
                if !std::mem::replace(&mut self.warned.1, true) {
                    tracing::warn!(
                        %from,
                        "sealed data arrives and this participant has no domain key: give it the \
                         domain's key file (NDDS_KEY_FILE), or unseal the sender's domain"
                    );
                }
                return None;
            }
            Route::Open => {}
        }
        let opener = self.opener.as_mut()?;
        let len = match opener.open(now, &mut datagram) {
            Ok(plain) => plain.len(),
            Err(error) => {
                if error == OpenError::NotSealed && !std::mem::replace(&mut self.warned.0, true) {
                    tracing::warn!(
                        %from,
                        "unsealed data arrives in a domain with a key: dropped; give the sender \
                         the domain's key file (NDDS_KEY_FILE), or remove the key here"
                    );
                }
                return None;
            }
        };
        Some(datagram.freeze().slice(SEAL_HEAD_LEN..SEAL_HEAD_LEN + len))
    }

    fn count_drop(&mut self, reason: DropReason) {
        self.stats.dropped[reason.index()] += 1;
    }

    fn on_data(
        &mut self,
        now: Instant,
        received: SystemTime,
        datagram: &Bytes,
        from: SocketAddrV4,
    ) -> Result<(), DropReason> {
        let parsed = DataDatagram::parse(datagram, self.config.domain)?;
        if parsed.reader_participant != self.config.participant {
            self.stats.misaddressed += 1;
            return Ok(());
        }
        let origin = Origin {
            writer: Guid {
                participant: parsed.header.sender,
                entity: parsed.writer,
            },
            from,
            received,
            token: parsed.token,
        };
        let mut readers = Readers::new();
        for reader in parsed.readers.iter() {
            if self.consumers.contains_key(reader) {
                readers.push(*reader);
            } else {
                self.stats.unknown_reader += 1;
            }
        }
        if readers.is_empty() {
            return Ok(());
        }
        for sub in parsed.subs() {
            match sub? {
                DataSub::Sample(sample) => {
                    let (meta, info) = origin.describe(&sample.meta);
                    let raw = RawSample {
                        payload: datagram.slice_ref(sample.payload),
                        info,
                    };
                    self.offer(&readers, now, &origin, meta, sample.meta.flags, raw);
                }
                DataSub::Fragment(fragment) => {
                    // Missing pieces are asked for only of a writer discovery matched with a
                    // consumer here (for that consumer): pieces from anyone else are put
                    // together (a writer not matched yet is held like its samples) but
                    // make no requests, so they neither turn this participant into a
                    // reflector towards a forged address nor flood a writer it cannot
                    // believe yet with requests for every sample it misses.
                    // A piece under a matched writer's id from another address is dropped
                    // before reassembly (counted by the consumers as from a wrong address),
                    // where it would become part of the genuine sample of its seq.
                    let mut asker = None;
                    let mut misplaced = false;
                    for reader in &readers {
                        if let Some(consumer) = self.consumers.get_mut(reader) {
                            match consumer.check_piece(&origin.writer, from) {
                                Verdict::Matched => asker = asker.or(Some(*reader)),
                                Verdict::WrongAddress => misplaced = true,
                                Verdict::Unmatched => {}
                            }
                        }
                    }
                    if misplaced && asker.is_none() {
                        continue;
                    }
                    let outcome = self.repair.piece(
                        now,
                        origin.writer,
                        (from, parsed.token),
                        asker,
                        &fragment,
                    );
                    match outcome {
                        PieceOutcome::Complete(whole) => {
                            let (meta, info) = origin.describe(&fragment.meta);
                            let raw = RawSample {
                                payload: Bytes::from(whole),
                                info,
                            };
                            self.offer(&readers, now, &origin, meta, fragment.meta.flags, raw);
                            if fragment.meta.flags & FLAG_RELIABLE != 0 {
                                // Pieces of samples every reliable consumer here has moved
                                // past are stale: they must not start a partial sample again.
                                let floor = readers
                                    .iter()
                                    .filter_map(|r| self.consumers.get(r)?.next_seq(origin.writer))
                                    .min();
                                if let Some(floor) = floor {
                                    self.repair.skip_before(origin.writer, floor);
                                }
                            }
                        }
                        PieceOutcome::Pending => {
                            if fragment.meta.flags & FLAG_RELIABLE != 0 {
                                self.control(&readers, now, &origin, || {
                                    Sent::Partial(fragment.meta.seq)
                                });
                            }
                        }
                        PieceOutcome::Ignored => {}
                        PieceOutcome::Refused => self.stats.fragments_refused += 1,
                    }
                }
                DataSub::Heartbeat(heartbeat) => {
                    self.control(&readers, now, &origin, || Sent::Heartbeat(heartbeat));
                }
                DataSub::Gap(gap) => self.control(&readers, now, &origin, || Sent::Gap(gap)),
            }
        }
        Ok(())
    }

    /// Offers one sample to every addressed consumer (the last one takes it without a
    /// reference-count increment).
    fn offer(
        &mut self,
        readers: &[u32],
        now: Instant,
        origin: &Origin,
        meta: crate::arbitration::Incoming,
        flags: u8,
        raw: RawSample,
    ) {
        let Some((last, others)) = readers.split_last() else {
            return;
        };
        self.stats.delivered += readers.len() as u64;
        let (mut ctx, consumers) = self.ctx();
        for reader in others {
            if let Some(consumer) = consumers.get_mut(reader) {
                consumer.offer(&mut ctx, now, origin, meta, flags, raw.clone());
            }
        }
        if let Some(consumer) = consumers.get_mut(last) {
            consumer.offer(&mut ctx, now, origin, meta, flags, raw);
        }
    }

    /// Hands reliable-stream control to every addressed reliable consumer.
    fn control(&mut self, readers: &[u32], now: Instant, origin: &Origin, what: impl Fn() -> Sent) {
        let (mut ctx, consumers) = self.ctx();
        for reader in readers {
            if let Some(consumer) = consumers.get_mut(reader)
                && consumer.is_reliable()
            {
                consumer.control(&mut ctx, now, origin, what());
            }
        }
    }

    fn on_feedback(
        &mut self,
        now: Instant,
        datagram: &Bytes,
        from: SocketAddrV4,
    ) -> Result<(), DropReason> {
        let parsed = FeedbackDatagram::parse(datagram, self.config.domain)?;
        if parsed.writer_participant != self.config.participant {
            self.stats.misaddressed += 1;
            return Ok(());
        }
        let sender = parsed.header.sender;
        // What the datagram brought counts once towards an unvalidated sender's allowance.
        let mut credit = datagram.len();
        for sub in parsed.subs() {
            let sub = sub?;
            let (reader, writer) = match &sub {
                FeedbackSub::AckNack(a) => (a.reader, a.writer),
                FeedbackSub::NackFrag(n) => (n.reader, n.writer),
            };
            let reader = Guid {
                participant: sender,
                entity: reader,
            };
            let (mut tx, producers, events) = self.tx();
            let Some(producer) = producers.get_mut(&writer) else {
                continue;
            };
            let how = (from, parsed.token, std::mem::take(&mut credit));
            match producer.on_feedback(&mut tx, events, now, reader, how, &sub) {
                FeedbackVerdict::NotBelieved | FeedbackVerdict::Acted => {}
                FeedbackVerdict::Unvalidated { withheld } => {
                    self.stats.unvalidated_feedback += 1;
                    self.stats.pieces_withheld += withheld as u64;
                }
            }
        }
        Ok(())
    }

    /// Runs every timer due at `now`: deadlines and separation windows, heartbeats,
    /// acknowledgements and repairs, batch flushes, piece requests, admission hold expiry.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.next_pair_sweep.is_some_and(|at| at <= now) {
            self.sweep_pair_keys(now);
        }
        let config = &self.config;
        if self.repair.poll_timeout().is_some_and(|at| at <= now) {
            self.repair.handle_timeout(
                now,
                (config.domain, config.participant, config.max_datagram),
                &mut self.transmits,
            );
        }
        let (mut ctx, consumers) = self.ctx();
        for consumer in consumers.values_mut() {
            if consumer.due.is_some_and(|due| due <= now) {
                consumer.handle_timeout(&mut ctx, now);
            }
        }
        let (mut tx, producers, events) = self.tx();
        for producer in producers.values_mut() {
            if producer.due.is_some_and(|due| due <= now) {
                producer.handle_timeout(&mut tx, events, now);
            }
        }
    }

    // ---- output ----

    /// When [`ParticipantCore::handle_timeout`] must be called next.
    pub fn poll_timeout(&self) -> Option<Instant> {
        self.consumers
            .values()
            .filter_map(|c| c.due)
            .chain(self.producers.values().filter_map(|p| p.due))
            .chain(self.repair.poll_timeout())
            .chain(self.next_pair_sweep)
            .min()
    }

    /// The next datagram to send.
    ///
    /// Acknowledgements are made here, for everything handled since the last call: a
    /// driver that handles a burst of datagrams before it sends answers them with one
    /// AckNack per reliable stream.
    pub fn poll_transmit(&mut self) -> Option<Transmit> {
        self.send_acks();
        self.transmits.pop()
    }

    /// Datagrams waiting to be sent (acknowledgements included).
    pub fn pending_transmits(&mut self) -> usize {
        self.send_acks();
        self.transmits.len()
    }

    fn send_acks(&mut self) {
        if self.acks_due.is_empty() {
            return;
        }
        let mut due = std::mem::take(&mut self.acks_due);
        let (mut ctx, consumers) = self.ctx();
        for entity in due.drain(..) {
            if let Some(consumer) = consumers.get_mut(&entity) {
                consumer.send_acks(&mut ctx);
            }
        }
        // Its allocation is kept for the next round.
        self.acks_due = due;
    }

    /// Gives a sent datagram's buffer back for reuse.
    pub fn recycle(&mut self, transmit: Transmit) {
        self.transmits.recycle(transmit);
    }

    /// The next event for the application or the producers' handles.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// Moves every waiting event to the end of `into`, in order: a swap of the queues when
    /// `into` is empty, so a driver takes a round's events without moving them one by one
    /// (and the queue it gives back keeps its capacity).
    pub fn take_events(&mut self, into: &mut VecDeque<Event>) {
        if into.is_empty() {
            std::mem::swap(&mut self.events, into);
        } else {
            into.append(&mut self.events);
        }
    }

    /// True when events wait.
    pub fn has_events(&self) -> bool {
        !self.events.is_empty()
    }

    /// The counters.
    pub fn stats(&self) -> CoreStats {
        let mut stats = self.stats.clone();
        let unbelieved = self
            .consumers
            .values()
            .map(ConsumerCore::admission_stats)
            .chain(self.producers.values().map(ProducerCore::believed_stats))
            .fold(self.withdrawn, add);
        stats.unmatched_sender = unbelieved.unmatched;
        stats.wrong_address = unbelieved.wrong_address;
        stats.transmits = self.transmits.datagrams;
        stats.transmit_bytes = self.transmits.bytes;
        stats.unsealable = self.transmits.unsealable;
        stats.unkeyed = self.transmits.unkeyed;
        if let Some(opener) = &self.opener {
            stats.seal = opener.stats().clone();
        }
        stats
    }
}

fn add(a: AdmissionStats, b: AdmissionStats) -> AdmissionStats {
    AdmissionStats {
        unmatched: a.unmatched + b.unmatched,
        wrong_address: a.wrong_address + b.wrong_address,
        released: a.released + b.released,
    }
}

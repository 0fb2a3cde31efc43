//! What the receive thread does with a datagram: `Data` goes to the consumers it addresses
//! (whole samples, pieces of large samples through reassembly, reliable-stream control);
//! `Feedback` goes to the producer it addresses.

use std::collections::{BTreeMap, BTreeSet};
use std::net::SocketAddrV4;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use bytes::Bytes;
use ndds_core::arbitration::{Incoming, SampleStatus};
use ndds_core::fragment::{FragmentResult, Mode, Piece, Reassembler, ReassemblyConfig};
use ndds_core::reliability::RttEstimate;
use ndds_core::wire::data::{FLAG_RELIABLE, Fragment};
use ndds_core::wire::feedback::{NackFrag, encode_feedback};
use ndds_core::wire::{
    self, DataDatagram, DataSub, DropReason, FeedbackDatagram, FeedbackSub, Guid, MessageKind,
    SampleMeta,
};
use smallvec::SmallVec;

use super::{DataPlane, Limits, Net};
use crate::sample::{RawSample, SampleInfo};
use crate::slot::ConsumerSlot;
use crate::sync::{lock, read};

/// The consumers one datagram addresses.
type Slots = SmallVec<[Arc<ConsumerSlot>; 8]>;

/// Where a sample came from and what it says about itself, for the consumers it reaches.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Origin {
    /// The writer.
    pub(crate) writer: Guid,
    /// The writer's data socket (feedback goes there).
    pub(crate) from: SocketAddrV4,
    /// When the datagram arrived (read once per datagram).
    pub(crate) received: SystemTime,
}

impl Origin {
    /// The arbiter's view and the application's view of a sample.
    pub(crate) fn describe(&self, meta: &SampleMeta) -> (Incoming, SampleInfo) {
        let incoming = Incoming {
            writer: self.writer,
            seq: meta.seq,
            strength: meta.strength,
            persistence: Duration::from_micros(meta.persistence_us),
            source_ns: meta.timestamp_ns,
        };
        let info = SampleInfo {
            writer: self.writer,
            seq: meta.seq,
            source_timestamp: SystemTime::UNIX_EPOCH + Duration::from_nanos(meta.timestamp_ns),
            reception_timestamp: self.received,
            strength: meta.strength,
            status: SampleStatus::Fresh,
        };
        (incoming, info)
    }
}

/// Partial samples held per reliable writer.
const RELIABLE_PARTIALS: usize = 4096;

/// How long after the last piece of an incomplete sample its missing pieces are requested,
/// and how often again while they stay missing.
const NACK_FRAG_DELAY: Duration = Duration::from_millis(5);
const NACK_FRAG_RETRY: Duration = Duration::from_millis(20);
/// At least 5 ms between requests for one sample's pieces: the round trip is measured to the
/// first piece of an answer, but an answer is up to 512 pieces, and on a loaded machine a
/// shorter floor asked again while the answer was still arriving, multiplying the traffic
/// until nothing completed (a 16 MiB reliable sample between two namespaces failed about one
/// run in four with a 1 ms floor; 6 of 6 passed with 5 ms).
const NACK_FRAG_RETRY_MIN: Duration = Duration::from_millis(5);

/// A partial sample whose missing pieces will be requested.
#[derive(Clone, Copy, Debug)]
struct Wanted {
    from: SocketAddrV4,
    reader: u32,
    due: Instant,
    /// When its pieces were first asked for, and whether they were asked for again since
    /// (only an answer to a single request measures a round trip).
    asked: Option<(Instant, bool)>,
}

/// What became of one piece.
#[derive(Debug)]
enum PieceOutcome {
    /// The sample is whole.
    Complete { bytes: Vec<u8>, ask_now: bool },
    /// The sample still lacks pieces.
    Pending { ask_now: bool },
    /// Nothing to do (a duplicate, a stale piece).
    Ignored,
    /// Refused by reassembly (counted).
    Refused,
}

/// A piece of sample `key.1` arrived: a writer sends the pieces of one sample before those of
/// the next, so earlier samples of the same writer that are still incomplete will get no
/// more pieces of their first sending: their missing pieces are asked for now rather than
/// after the quiet delay. Returns whether any request became due.
fn ask_earlier(state: &mut ReassemblyState, key: (Guid, u64), now: Instant) -> bool {
    let (writer, seq) = key;
    let mut any = false;
    while let Some(&earlier) = state.unasked.range((writer, 0)..(writer, seq)).next() {
        state.unasked.remove(&earlier);
        if let Some(want) = state.wanted.get_mut(&earlier) {
            want.due = want.due.min(now);
            any = true;
        }
    }
    any
}

#[derive(Debug)]
struct ReassemblyState {
    reassembler: Reassembler<Guid>,
    wanted: BTreeMap<(Guid, u64), Wanted>,
    /// The keys of `wanted` never asked for nor made due yet.
    unasked: BTreeSet<(Guid, u64)>,
    feedback: Vec<u8>,
    /// Round trip from a piece request to the first piece answering it.
    rtt: RttEstimate,
}

impl ReassemblyState {
    /// Stops asking for the pieces of `writer`'s samples `from..to`.
    fn forget(&mut self, writer: Guid, from: u64, to: u64) {
        while let Some((&key, _)) = self.wanted.range((writer, from)..(writer, to)).next() {
            self.wanted.remove(&key);
            self.unasked.remove(&key);
        }
    }

    /// How long a piece request stands before it is repeated: adapted to the measured round
    /// trip, like a reliable reader's requests.
    fn retry(&self) -> Duration {
        self.rtt.timeout(NACK_FRAG_RETRY_MIN, NACK_FRAG_RETRY)
    }
}

/// Reassembly of large samples for all writers of the participant, and the requests for
/// missing pieces.
#[derive(Debug)]
pub(crate) struct Reassembly {
    state: Mutex<ReassemblyState>,
}

impl Reassembly {
    pub(crate) fn new(limits: Limits) -> Self {
        // Room for four samples of the largest size being put together at once.
        let config = ReassemblyConfig {
            max_sample_bytes: limits.max_sample,
            max_total_bytes: limits
                .max_sample
                .saturating_mul(4)
                .saturating_add(1 << 20)
                .max(ReassemblyConfig::default().max_total_bytes),
            ..ReassemblyConfig::default()
        };
        Reassembly {
            state: Mutex::new(ReassemblyState {
                reassembler: Reassembler::new(config),
                wanted: BTreeMap::new(),
                unasked: BTreeSet::new(),
                feedback: Vec::new(),
                rtt: RttEstimate::default(),
            }),
        }
    }

    /// Takes one piece; returns the whole sample once it is complete.
    fn piece(
        &self,
        now: Instant,
        origin: &Origin,
        reader: u32,
        fragment: &Fragment<'_>,
    ) -> PieceOutcome {
        let mode = if fragment.meta.flags & FLAG_RELIABLE != 0 {
            // A reliable writer has a whole window of samples in flight, and under loss many
            // of them are incomplete at once: hold as many (the byte budget still bounds them).
            Mode::KeepAll {
                max_partials: RELIABLE_PARTIALS,
            }
        } else {
            Mode::LastIsBest
        };
        let mut state = lock(&self.state);
        let key = (origin.writer, fragment.meta.seq);
        match state
            .reassembler
            .handle_fragment(now, origin.writer, mode, &Piece::from(fragment))
        {
            FragmentResult::Complete(bytes) => {
                if let Some(Wanted {
                    asked: Some((at, false)),
                    ..
                }) = state.wanted.remove(&key)
                {
                    state.rtt.sample(now.saturating_duration_since(at));
                }
                state.unasked.remove(&key);
                let ask_now = ask_earlier(&mut state, key, now);
                PieceOutcome::Complete { bytes, ask_now }
            }
            FragmentResult::Pending => {
                if mode == Mode::LastIsBest {
                    // Only the newest sample of a best-effort writer is worth repairing.
                    state.forget(origin.writer, 0, key.1);
                    state.forget(origin.writer, key.1.saturating_add(1), u64::MAX);
                }
                let asked = state.wanted.get(&key).and_then(|w| w.asked);
                if let Some((at, false)) = asked {
                    state.rtt.sample(now.saturating_duration_since(at));
                }
                let wait = match asked {
                    Some(_) => state.retry(),
                    None => NACK_FRAG_DELAY,
                };
                state.wanted.insert(
                    key,
                    Wanted {
                        from: origin.from,
                        reader,
                        due: now + wait,
                        // Measured once: later pieces of the same answer are no round trip.
                        asked: asked.map(|(at, _)| (at, true)),
                    },
                );
                if asked.is_none() {
                    state.unasked.insert(key);
                }
                let ask_now = ask_earlier(&mut state, key, now);
                PieceOutcome::Pending { ask_now }
            }
            FragmentResult::Ignored(_) => PieceOutcome::Ignored,
            FragmentResult::Rejected(_) => PieceOutcome::Refused,
        }
    }

    /// Forgets partial samples of `writer` below `seq` and ignores their pieces from now on.
    fn skip_before(&self, writer: Guid, seq: u64) {
        let mut state = lock(&self.state);
        state.reassembler.skip_before(writer, seq);
        state.forget(writer, 0, seq);
    }

    /// Asks for the missing pieces of samples that stopped progressing; drops partial samples
    /// that timed out. Returns when to run again.
    pub(crate) fn timeout(&self, now: Instant, net: &Net) -> Option<Instant> {
        let mut state = lock(&self.state);
        let retry = state.retry();
        let ReassemblyState {
            reassembler,
            wanted,
            unasked,
            feedback,
            ..
        } = &mut *state;
        reassembler.handle_timeout(now);
        wanted.retain(|(writer, seq), want| {
            if want.due > now {
                return true;
            }
            unasked.remove(&(*writer, *seq));
            let Some(missing) = reassembler.missing(*writer, *seq) else {
                return false;
            };
            let nack = FeedbackSub::NackFrag(NackFrag {
                reader: want.reader,
                writer: writer.entity,
                seq: *seq,
                base: missing.base,
                missing: missing.bitmap(),
            });
            let encoded = encode_feedback(
                net.domain,
                net.participant,
                writer.participant,
                &[nack],
                feedback,
            );
            if encoded.is_ok() {
                let _ = net.send(feedback, want.from);
            }
            want.due = now + retry;
            want.asked = Some(match want.asked {
                Some((first, _)) => (first, true),
                None => (now, false),
            });
            true
        });
        let next = wanted.values().map(|w| w.due).min();
        match (next, reassembler.poll_timeout()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

impl DataPlane {
    pub(super) fn on_datagram(&self, datagram: Bytes, from: SocketAddrV4) {
        if self.closed.load(Ordering::Acquire) {
            return;
        }
        self.stats.received.fetch_add(1, Ordering::Relaxed);
        let kind = match wire::Header::parse(&datagram) {
            Ok((header, _)) if header.domain != self.net.domain => {
                return self.count_drop(DropReason::OtherDomain);
            }
            Ok((header, _)) => header.kind,
            Err(reason) => return self.count_drop(reason),
        };
        let result = match kind {
            MessageKind::Data => self.on_data(&datagram, from),
            MessageKind::Feedback => self.on_feedback(&datagram, from),
            // A discovery message: counted as malformed when its body does not decode (the
            // receive checks of protocol.md section 4 come first), else as unexpected here.
            _ => match wire::decode_for_domain(&datagram, self.net.domain) {
                Ok(_) => Err(DropReason::Unexpected),
                Err(reason) => Err(reason),
            },
        };
        if let Err(reason) = result {
            self.count_drop(reason);
        }
    }

    fn on_data(&self, datagram: &Bytes, from: SocketAddrV4) -> Result<(), DropReason> {
        let parsed = DataDatagram::parse(datagram, self.net.domain)?;
        if parsed.reader_participant != self.net.participant {
            self.stats.misaddressed.fetch_add(1, Ordering::Relaxed);
            return Ok(());
        }
        let origin = Origin {
            writer: Guid {
                participant: parsed.header.sender,
                entity: parsed.writer,
            },
            from,
            received: SystemTime::now(),
        };
        let slots = self.slots(&parsed.readers);
        if slots.is_empty() {
            return Ok(());
        }
        let now = Instant::now();
        for sub in parsed.subs() {
            match sub? {
                DataSub::Sample(sample) => {
                    let (meta, info) = origin.describe(&sample.meta);
                    let raw = RawSample {
                        payload: datagram.slice_ref(sample.payload),
                        info,
                    };
                    self.offer(&slots, now, &origin, meta, sample.meta.flags, raw);
                }
                DataSub::Fragment(fragment) => {
                    let reader = slots.first().map_or(0, |s| s.entity);
                    match self.reassembly.piece(now, &origin, reader, &fragment) {
                        PieceOutcome::Complete {
                            bytes: whole,
                            ask_now,
                        } => {
                            if ask_now {
                                self.schedule(now);
                            }
                            let (meta, info) = origin.describe(&fragment.meta);
                            let raw = RawSample {
                                payload: Bytes::from(whole),
                                info,
                            };
                            self.offer(&slots, now, &origin, meta, fragment.meta.flags, raw);
                            if fragment.meta.flags & FLAG_RELIABLE != 0 {
                                // Pieces of samples every reliable consumer here has moved
                                // past are stale: they must not start a partial sample again.
                                let floor =
                                    slots.iter().filter_map(|s| s.next_seq(origin.writer)).min();
                                if let Some(floor) = floor {
                                    self.reassembly.skip_before(origin.writer, floor);
                                }
                            }
                        }
                        PieceOutcome::Pending { ask_now } => {
                            if fragment.meta.flags & FLAG_RELIABLE != 0 {
                                for slot in &slots {
                                    slot.on_partial(now, &origin, fragment.meta.seq);
                                }
                            }
                            self.schedule(if ask_now { now } else { now + NACK_FRAG_DELAY });
                        }
                        PieceOutcome::Ignored => {}
                        PieceOutcome::Refused => {
                            self.stats.fragments_refused.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                }
                DataSub::Heartbeat(heartbeat) => {
                    for slot in &slots {
                        slot.on_heartbeat(now, &origin, heartbeat);
                    }
                }
                DataSub::Gap(gap) => {
                    for slot in &slots {
                        slot.on_gap(now, &origin, gap);
                    }
                }
            }
        }
        Ok(())
    }

    /// Offers one sample to every addressed consumer.
    pub(crate) fn offer(
        &self,
        slots: &Slots,
        now: Instant,
        origin: &Origin,
        meta: Incoming,
        flags: u8,
        raw: RawSample,
    ) {
        let Some((last, others)) = slots.split_last() else {
            return;
        };
        self.stats
            .delivered
            .fetch_add(slots.len() as u64, Ordering::Relaxed);
        for slot in others {
            slot.offer(now, origin, meta, flags, raw.clone());
        }
        // The last one takes the sample itself: no reference count traffic for one consumer.
        last.offer(now, origin, meta, flags, raw);
    }

    /// The consumers named by a datagram; unknown ones are counted.
    fn slots(&self, readers: &[u32]) -> Slots {
        let consumers = read(&self.consumers);
        let mut slots = Slots::new();
        for reader in readers {
            match consumers.get(reader) {
                Some(slot) => slots.push(slot.clone()),
                None => {
                    self.stats.unknown_reader.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        slots
    }

    fn on_feedback(&self, datagram: &Bytes, from: SocketAddrV4) -> Result<(), DropReason> {
        let parsed = FeedbackDatagram::parse(datagram, self.net.domain)?;
        if parsed.writer_participant != self.net.participant {
            self.stats.misaddressed.fetch_add(1, Ordering::Relaxed);
            return Ok(());
        }
        let now = Instant::now();
        for sub in parsed.subs() {
            let sub = sub?;
            let (reader, writer) = match &sub {
                wire::FeedbackSub::AckNack(a) => (a.reader, a.writer),
                wire::FeedbackSub::NackFrag(n) => (n.reader, n.writer),
            };
            let Some(side) = read(&self.writers).get(&writer).cloned() else {
                continue;
            };
            let reader = Guid {
                participant: parsed.header.sender,
                entity: reader,
            };
            if let Some(at) = side.on_feedback(now, reader, from, &sub) {
                self.schedule(at);
            }
        }
        Ok(())
    }
}

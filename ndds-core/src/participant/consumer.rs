//! One consumer's receiving end: who it believes (admission), the reliable streams of its
//! reliable producers (ordering, repair requests, loss reports, acknowledgements that pace
//! the producers), and its arbiter (NDDS semantics). Accepted samples and notifications
//! become [`Event`]s.
//!
//! Samples of a reliable producer reach a reliable consumer's arbiter only through the
//! producer's stream, in order, and only while the consumer has credit (room the application
//! made by taking samples): what the application has not taken is not acknowledged, so a
//! slow consumer slows its producers down instead of dropping.

use std::collections::VecDeque;
use std::net::SocketAddrV4;
use std::time::{Duration, Instant, SystemTime};

use crate::admission::{Admission, AdmissionConfig, AdmissionStats, Verdict};
use crate::arbitration::SampleStatus;
use crate::arbitration::{Arbiter, ArbiterStats, Incoming, Notification, Output, Rules};
use crate::reliability::{AckNack, Delivery, ReaderConfig, ReaderStats, ReliableReader};
use crate::wire::data::{AddressToken, FLAG_RELIABLE, Gap, Heartbeat};
use crate::wire::feedback::{AckNack as WireAckNack, encode_feedback};
use crate::wire::{FeedbackSub, Guid, SampleMeta};
use foldhash::HashMap;

use super::Event;
use super::sample::{RawSample, SampleInfo};
use super::transmit::Transmits;

/// How a consumer is declared to the core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConsumerSpec {
    /// Minimum separation and deadline.
    pub rules: Rules,
    /// `Some` for a consumer that asks for reliability.
    pub reliable: Option<ReaderConfig>,
    /// Samples the application may hold before reliable streams stop delivering (the
    /// consumer's queue depth); `None`: no limit (a callback or a latest-value cell).
    pub credit: Option<usize>,
}

/// Where a sample came from.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Origin {
    /// The writer.
    pub(crate) writer: Guid,
    /// The writer's data socket (feedback goes there).
    pub(crate) from: SocketAddrV4,
    /// When the datagram arrived (the driver's wall clock, read once per datagram).
    pub(crate) received: SystemTime,
    /// The writer participant's address token for this participant, echoed in feedback.
    pub(crate) token: AddressToken,
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

/// What a consumer's handlers need of the participant: the sender identity for feedback, and
/// where datagrams and events go.
pub(crate) struct Ctx<'a> {
    pub(crate) domain: u16,
    pub(crate) participant: u64,
    pub(crate) out: &'a mut Transmits,
    pub(crate) events: &'a mut VecDeque<Event>,
    /// Consumers whose reliable streams have acknowledgements to send: sent when the
    /// driver next asks for transmits, so one burst of datagrams is answered by one
    /// AckNack per stream rather than one per datagram.
    pub(crate) acks_due: &'a mut Vec<u32>,
}

/// One reliable producer's stream towards this consumer.
#[derive(Debug)]
struct Stream {
    reader: ReliableReader<(Incoming, RawSample)>,
    /// Where the producer's feedback goes (its data socket).
    from: SocketAddrV4,
    /// The token its data carried last, echoed in the feedback.
    token: AddressToken,
}

/// What a producer sent: held, in arrival order, until the producer is matched.
#[derive(Debug)]
struct Early {
    origin: Origin,
    what: Sent,
}

#[derive(Debug)]
pub(crate) enum Sent {
    Sample {
        meta: Incoming,
        flags: u8,
        sample: RawSample,
    },
    /// Reliable-stream control: a heartbeat, a gap, a piece of a large sample (its seq).
    Heartbeat(Heartbeat),
    Gap(Gap),
    Partial(u64),
}

impl Early {
    /// The same, a sample's payload in a buffer of its own.
    fn detached(self) -> Self {
        let what = match self.what {
            Sent::Sample {
                meta,
                flags,
                sample,
            } => Sent::Sample {
                meta,
                flags,
                sample: sample.detached(),
            },
            control => control,
        };
        Early { what, ..self }
    }
}

/// The bytes a held control message is counted as.
const CONTROL_BYTES: usize = 32;

/// Lost producers whose stream position is remembered (the oldest is forgotten first).
const RESUMABLE: usize = 256;

/// Counters of one consumer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ConsumerCounters {
    /// Samples that arrived for it (before admission, ordering and arbitration).
    pub arrived: u64,
    /// The arbiter's counters.
    pub arbiter: ArbiterStats,
    /// What admission refused.
    pub admission: AdmissionStats,
    /// Reliable streams (one per matched reliable producer heard from).
    pub streams: usize,
    /// Their readers' counters, summed (of the streams there are now: a producer that went
    /// away takes its stream's counts with it).
    pub reliable: ReaderStats,
}

/// A consumer's receiving end.
#[derive(Debug)]
pub(crate) struct ConsumerCore {
    pub(crate) entity: u32,
    reliable: Option<ReaderConfig>,
    /// The matched producers: samples, heartbeats and gaps from anyone else are not
    /// believed (a sample from a producer not matched yet is held a moment).
    admission: Admission<Early>,
    arbiter: Arbiter<RawSample>,
    streams: HashMap<Guid, Stream>,
    /// Where the streams of lost producers stood (next seq, when lost): a producer matched
    /// again resumes there, so what it wrote meanwhile is reported lost.
    resume: HashMap<Guid, (u64, Instant)>,
    /// Samples still allowed out (`None`: unlimited), and the most ever allowed.
    credit: Option<usize>,
    capacity: usize,
    feedback: Vec<u8>,
    /// In the participant's list of consumers with acknowledgements to send.
    acks_queued: bool,
    arrived: u64,
    /// Cached next timer.
    pub(crate) due: Option<Instant>,
}

impl ConsumerCore {
    pub(crate) fn new(entity: u32, spec: ConsumerSpec, now: Instant) -> Self {
        let mut core = ConsumerCore {
            entity,
            reliable: spec.reliable,
            admission: Admission::new(AdmissionConfig::default()),
            arbiter: Arbiter::new(spec.rules, now),
            streams: HashMap::default(),
            resume: HashMap::default(),
            credit: spec.credit,
            capacity: spec.credit.unwrap_or(usize::MAX),
            feedback: Vec::new(),
            acks_queued: false,
            arrived: 0,
            due: None,
        };
        // The deadline runs from the consumer's creation.
        core.reschedule();
        core
    }

    /// What to make of a piece of a large sample `writer` sent from `from`: one under a
    /// matched writer's id from another address is counted here (the caller drops it before
    /// reassembly, where it could corrupt the genuine sample of the same seq).
    pub(crate) fn check_piece(&mut self, writer: &Guid, from: SocketAddrV4) -> Verdict {
        let verdict = self.admission.check(writer, from);
        if verdict == Verdict::WrongAddress {
            self.admission.admit(writer, from);
        }
        verdict
    }

    pub(crate) fn is_reliable(&self) -> bool {
        self.reliable.is_some()
    }

    pub(crate) fn counters(&self) -> ConsumerCounters {
        let reliable = self
            .streams
            .values()
            .map(|stream| stream.reader.stats())
            .fold(ReaderStats::default(), add_reader_stats);
        ConsumerCounters {
            arrived: self.arrived,
            arbiter: self.arbiter.stats(),
            admission: self.admission.stats(),
            streams: self.streams.len(),
            reliable,
        }
    }

    pub(crate) fn admission_stats(&self) -> AdmissionStats {
        self.admission.stats()
    }

    /// An arriving sample.
    pub(crate) fn offer(
        &mut self,
        ctx: &mut Ctx<'_>,
        now: Instant,
        origin: &Origin,
        meta: Incoming,
        flags: u8,
        sample: RawSample,
    ) {
        self.arrived += 1;
        let bytes = sample.payload.len();
        let what = Sent::Sample {
            meta,
            flags,
            sample,
        };
        self.admit(ctx, now, origin, bytes, what);
    }

    /// Reliable-stream control (a reliable consumer only): acted on for a matched producer,
    /// held like its samples for one not matched yet (its first heartbeat is what starts the
    /// stream), dropped from anyone else.
    pub(crate) fn control(&mut self, ctx: &mut Ctx<'_>, now: Instant, origin: &Origin, what: Sent) {
        if self.reliable.is_none() {
            return;
        }
        self.admit(ctx, now, origin, CONTROL_BYTES, what);
    }

    /// Offers what `origin` sent to admission: acted on now if believed, held or dropped
    /// otherwise.
    fn admit(
        &mut self,
        ctx: &mut Ctx<'_>,
        now: Instant,
        origin: &Origin,
        bytes: usize,
        what: Sent,
    ) {
        let early = Early {
            origin: *origin,
            what,
        };
        // What is held for a producer not matched yet gets a buffer of its own, so it does
        // not keep a whole receive buffer alive.
        let admitted = self.admission.offer(
            now,
            origin.writer,
            origin.from,
            bytes,
            early,
            Early::detached,
        );
        if let Some(early) = admitted {
            self.accept(ctx, now, early);
        }
        self.reschedule();
    }

    /// Acts on what a matched producer sent.
    fn accept(&mut self, ctx: &mut Ctx<'_>, now: Instant, early: Early) {
        let Early { origin, what } = early;
        match (what, self.reliable) {
            (
                Sent::Sample {
                    meta,
                    flags,
                    sample,
                },
                Some(config),
            ) if flags & FLAG_RELIABLE != 0 => {
                let stream = self.stream(config, &origin);
                stream.reader.handle_sample(now, meta.seq, (meta, sample));
                self.pump(ctx, now);
            }
            (Sent::Sample { meta, sample, .. }, _) => {
                self.arbiter.handle_sample(now, meta, sample);
                self.drain(ctx);
            }
            (control, Some(config)) => {
                let reader = &mut self.stream(config, &origin).reader;
                match control {
                    Sent::Heartbeat(heartbeat) => {
                        reader.handle_heartbeat(now, heartbeat.first, heartbeat.last);
                    }
                    Sent::Gap(gap) => reader.handle_gap(gap.from, gap.to),
                    Sent::Partial(seq) => reader.handle_partial(now, seq),
                    Sent::Sample { .. } => {}
                }
                self.pump(ctx, now);
            }
            // Reliable-stream control for a best-effort consumer: nothing to do.
            (_, None) => {}
        }
    }

    /// The participants of the endpoints it is matched with (or still believes a moment).
    pub(crate) fn peers(&self) -> impl Iterator<Item = u64> + '_ {
        self.admission.senders().map(|guid| guid.participant)
    }

    /// The producers this consumer is matched with now (discovery's view): what was held for
    /// the new ones is acted on.
    pub(crate) fn set_matched(
        &mut self,
        ctx: &mut Ctx<'_>,
        now: Instant,
        producers: impl IntoIterator<Item = (Guid, SocketAddrV4)>,
    ) {
        let producers: smallvec::SmallVec<[(Guid, SocketAddrV4); 8]> =
            producers.into_iter().collect();
        for (writer, _) in &producers {
            self.arbiter.handle_writer_back(*writer);
        }
        let released = self.admission.set_matched(now, producers);
        for early in released {
            self.accept(ctx, now, early);
        }
        self.reschedule();
    }

    /// A matched producer went away.
    pub(crate) fn writer_lost(&mut self, ctx: &mut Ctx<'_>, now: Instant, writer: Guid) {
        self.admission.unmatched(now, &writer);
        if let Some(stream) = self.streams.remove(&writer)
            && stream.reader.is_synced()
        {
            if self.resume.len() >= RESUMABLE
                && let Some(oldest) = self
                    .resume
                    .iter()
                    .min_by_key(|(_, (_, at))| *at)
                    .map(|(guid, _)| *guid)
            {
                self.resume.remove(&oldest);
            }
            self.resume.insert(writer, (stream.reader.next_seq(), now));
        }
        self.arbiter.handle_writer_lost(writer);
        self.drain(ctx);
        self.reschedule();
    }

    /// A notification that does not come from arbitration.
    pub(crate) fn notify(&mut self, ctx: &mut Ctx<'_>, notification: Notification) {
        ctx.events.push_back(Event::Notification {
            consumer: self.entity,
            notification,
        });
    }

    /// The application took `samples` samples: reliable streams waiting for room move on.
    pub(crate) fn taken(&mut self, ctx: &mut Ctx<'_>, now: Instant, samples: usize) {
        if let Some(credit) = &mut self.credit {
            *credit = credit.saturating_add(samples).min(self.capacity);
        }
        if self.reliable.is_some() {
            self.pump(ctx, now);
            self.reschedule();
        }
    }

    /// Lifts the credit limit (the consumer now delivers to a callback).
    pub(crate) fn set_unlimited(&mut self, ctx: &mut Ctx<'_>, now: Instant) {
        self.credit = None;
        self.capacity = usize::MAX;
        self.taken(ctx, now, 0);
    }

    /// The next seq the reliable stream of `writer` hands out (`None`: no such stream).
    pub(crate) fn next_seq(&self, writer: Guid) -> Option<u64> {
        self.reliable?;
        self.streams.get(&writer).map(|s| s.reader.next_seq())
    }

    /// Runs the due timers.
    pub(crate) fn handle_timeout(&mut self, ctx: &mut Ctx<'_>, now: Instant) {
        if self.admission.poll_timeout().is_some_and(|due| due <= now) {
            self.admission.handle_timeout(now);
        }
        if self.arbiter.poll_timeout().is_some_and(|due| due <= now) {
            self.arbiter.handle_timeout(now);
            self.drain(ctx);
        }
        for stream in self.streams.values_mut() {
            if stream.reader.poll_timeout().is_some_and(|due| due <= now) {
                stream.reader.handle_timeout(now);
            }
        }
        self.pump(ctx, now);
        self.reschedule();
    }

    /// Moves in-order samples of the reliable streams to the arbiter while there is credit,
    /// reports lost runs, and queues the consumer for sending the streams'
    /// acknowledgements.
    fn pump(&mut self, ctx: &mut Ctx<'_>, now: Instant) {
        let entity = self.entity;
        let ConsumerCore {
            arbiter,
            streams,
            credit,
            acks_queued,
            ..
        } = self;
        // With unlimited credit each stream is drained in turn. With limited credit the
        // streams take one sample each per pass, so that no stream waits for another one to
        // empty (the map's order would otherwise favour the same stream every time).
        let per_pass = if credit.is_none() { usize::MAX } else { 1 };
        loop {
            let mut delivered = false;
            for (writer, stream) in streams.iter_mut() {
                let mut taken = 0;
                while taken < per_pass && credit.is_none_or(|c| c > 0) {
                    match stream.reader.poll_deliver() {
                        Some(Delivery::Sample {
                            sample: (meta, raw),
                            ..
                        }) => {
                            arbiter.handle_sample(now, meta, raw);
                            drain_into(arbiter, entity, credit, ctx.events);
                        }
                        Some(Delivery::Lost { from, to }) => {
                            ctx.events.push_back(Event::Notification {
                                consumer: entity,
                                notification: Notification::SamplesLost {
                                    writer: *writer,
                                    from,
                                    to,
                                },
                            });
                        }
                        None => break,
                    }
                    taken += 1;
                }
                delivered |= taken > 0;
            }
            if per_pass == usize::MAX || !delivered || credit.is_some_and(|c| c == 0) {
                break;
            }
        }
        if !*acks_queued && streams.values().any(|stream| stream.reader.has_output()) {
            *acks_queued = true;
            ctx.acks_due.push(entity);
        }
    }

    /// Sends the acknowledgements the reliable streams have (see [`Ctx::acks_due`]).
    pub(crate) fn send_acks(&mut self, ctx: &mut Ctx<'_>) {
        self.acks_queued = false;
        let ConsumerCore {
            entity,
            streams,
            feedback,
            ..
        } = self;
        for (writer, stream) in streams.iter_mut() {
            while let Some(ack) = stream.reader.poll_output() {
                send_ack(ctx, feedback, *entity, *writer, stream, ack);
            }
        }
    }

    /// Moves the arbiter's outputs to the events.
    fn drain(&mut self, ctx: &mut Ctx<'_>) {
        drain_into(&mut self.arbiter, self.entity, &mut self.credit, ctx.events);
    }

    /// The stream of `origin`'s writer, created on first use.
    fn stream(&mut self, config: ReaderConfig, origin: &Origin) -> &mut Stream {
        let resume = &mut self.resume;
        let stream = self.streams.entry(origin.writer).or_insert_with(|| {
            let mut reader = ReliableReader::new(config);
            if let Some((next, _)) = resume.remove(&origin.writer) {
                reader.resume_at(next);
            }
            Stream {
                reader,
                from: origin.from,
                token: origin.token,
            }
        });
        stream.from = origin.from;
        stream.token = origin.token;
        stream
    }

    fn reschedule(&mut self) {
        self.due = self
            .streams
            .values()
            .filter_map(|s| s.reader.poll_timeout())
            .chain(self.arbiter.poll_timeout())
            .chain(self.admission.poll_timeout())
            .min();
    }
}

/// Moves an arbiter's outputs to the events; each sample spends one credit.
fn drain_into(
    arbiter: &mut Arbiter<RawSample>,
    consumer: u32,
    credit: &mut Option<usize>,
    events: &mut VecDeque<Event>,
) {
    while let Some(output) = arbiter.poll_output() {
        match output {
            Output::Deliver { mut sample, status } => {
                sample.info.status = status;
                if let Some(credit) = credit {
                    *credit = credit.saturating_sub(1);
                }
                events.push_back(Event::Sample { consumer, sample });
            }
            Output::Notify(notification) => {
                events.push_back(Event::Notification {
                    consumer,
                    notification,
                });
            }
        }
    }
}

fn send_ack(
    ctx: &mut Ctx<'_>,
    buf: &mut Vec<u8>,
    reader: u32,
    writer: Guid,
    stream: &Stream,
    ack: AckNack,
) {
    let sub = FeedbackSub::AckNack(WireAckNack {
        reader,
        writer: writer.entity,
        acked: ack.acked,
        missing: ack.missing.as_bytes(),
    });
    let (domain, participant, token) = (ctx.domain, ctx.participant, stream.token);
    if encode_feedback(domain, participant, writer.participant, token, &[sub], buf).is_ok() {
        ctx.out.push(stream.from, buf, None);
    }
}

fn add_reader_stats(a: ReaderStats, b: ReaderStats) -> ReaderStats {
    ReaderStats {
        received: a.received + b.received,
        delivered: a.delivered + b.delivered,
        duplicates: a.duplicates + b.duplicates,
        out_of_window: a.out_of_window + b.out_of_window,
        lost: a.lost + b.lost,
        early_retries: a.early_retries + b.early_retries,
        lost_reports: a.lost_reports + b.lost_reports,
        nacks: a.nacks + b.nacks,
        acks: a.acks + b.acks,
        invalid: a.invalid + b.invalid,
    }
}

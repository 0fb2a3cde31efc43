//! One consumer's receiving end inside the participant: the reliable streams of its reliable
//! producers (ordering, repair requests, loss reports, acknowledgements that pace the
//! producers), its arbiter (NDDS semantics), and its sink.
//!
//! Samples of a reliable producer reach a reliable consumer's arbiter only through the
//! producer's stream, in order, and only while the sink has room: what the application has not
//! taken is not acknowledged, so a slow consumer slows its producers down instead of dropping.
//! Everything happens under one lock, so events reach the sink in order whichever thread (the
//! receive thread, the timer thread, or the application taking an event) moves them.

mod sink;

use std::collections::HashMap;
use std::net::SocketAddrV4;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use ndds_core::admission::{Admission, AdmissionConfig, AdmissionStats};
use ndds_core::arbitration::{Arbiter, ArbiterStats, Incoming, Notification, Output};
use ndds_core::reliability::{AckNack, Delivery, ReaderConfig, ReliableReader};
use ndds_core::wire::data::{FLAG_RELIABLE, Gap, Heartbeat};
use ndds_core::wire::feedback::{AckNack as WireAckNack, encode_feedback};
use ndds_core::wire::{EndpointKind, FeedbackSub, Guid, Reliability};

pub(crate) use sink::{Direct, Sink};

use crate::peers::Matched;
use crate::plane::{Net, Origin, Timer};
use crate::qos::ConsumerQos;
use crate::sample::{RawEvent, RawSample};
use crate::sync::lock;

/// One reliable producer's stream towards this consumer.
#[derive(Debug)]
struct Stream {
    reader: ReliableReader<(Incoming, RawSample)>,
    /// Where the producer's feedback goes (its data socket).
    from: SocketAddrV4,
}

/// What a producer sent: held, in arrival order, until the producer is matched.
#[derive(Debug)]
struct Early {
    origin: Origin,
    what: Sent,
}

#[derive(Debug)]
enum Sent {
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

#[derive(Debug)]
struct State {
    /// The matched producers: samples, heartbeats and gaps from anyone else are not
    /// believed (a sample from a producer not matched yet is held a moment).
    admission: Admission<Early>,
    arbiter: Arbiter<RawSample>,
    streams: HashMap<Guid, Stream>,
    /// Where the streams of lost producers stood (next seq, when lost): a producer matched
    /// again resumes there, so what it wrote meanwhile is reported lost.
    resume: HashMap<Guid, (u64, Instant)>,
    feedback: Vec<u8>,
}

/// Lost producers whose stream position is remembered (the oldest is forgotten first).
const RESUMABLE: usize = 256;

/// A consumer's receiving end.
#[derive(Debug)]
pub(crate) struct ConsumerSlot {
    /// The consumer's entity number.
    pub(crate) entity: u32,
    /// `Some` when the consumer requests reliability.
    reliable: Option<ReaderConfig>,
    state: Mutex<State>,
    pub(crate) sink: Sink,
    net: Arc<Net>,
    timer: Arc<Timer>,
    /// Samples that arrived for this consumer (before ordering and arbitration).
    pub(crate) arrived: AtomicU64,
}

impl ConsumerSlot {
    /// A slot for a consumer created at `now`; in immediate mode, also the application's
    /// receiver.
    pub(crate) fn new(
        entity: u32,
        qos: ConsumerQos,
        now: Instant,
        net: Arc<Net>,
        timer: Arc<Timer>,
    ) -> (Self, Option<flume::Receiver<RawEvent>>) {
        let (sink, rx) = Sink::new(&qos);
        let reliable = match qos.reliability {
            Reliability::Reliable { depth } => Some(ReaderConfig {
                depth: usize::try_from(depth).unwrap_or(usize::MAX).max(1),
                ..ReaderConfig::default()
            }),
            Reliability::BestEffort => None,
        };
        let slot = ConsumerSlot {
            entity,
            reliable,
            state: Mutex::new(State {
                admission: Admission::new(AdmissionConfig::default()),
                arbiter: Arbiter::new(qos.rules(), now),
                streams: HashMap::new(),
                resume: HashMap::new(),
                feedback: Vec::new(),
            }),
            sink,
            net,
            timer,
            arrived: AtomicU64::new(0),
        };
        (slot, rx)
    }

    /// Offers an arriving sample.
    pub(crate) fn offer(
        &self,
        now: Instant,
        origin: &Origin,
        meta: Incoming,
        flags: u8,
        sample: RawSample,
    ) {
        // Counted first, so a reader woken by the delivery sees the count.
        self.arrived.fetch_add(1, Ordering::Relaxed);
        let mut state = lock(&self.state);
        let before = state.admission.stats();
        let bytes = sample.payload.len();
        let what = Sent::Sample {
            meta,
            flags,
            sample,
        };
        self.admit(&mut state, before, now, origin, bytes, what);
    }

    /// Offers what `origin` sent to admission (`before`: its counters when the lock was
    /// taken): acted on now if believed, held or dropped otherwise.
    fn admit(
        &self,
        state: &mut State,
        before: AdmissionStats,
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
        let admitted = state.admission.offer(
            now,
            origin.writer,
            origin.from,
            bytes,
            early,
            Early::detached,
        );
        self.net.unbelieved.add(before, state.admission.stats());
        if let Some(early) = admitted {
            self.accept(state, now, early);
        }
        self.reschedule(state);
    }

    /// Acts on what a matched producer sent.
    fn accept(&self, state: &mut State, now: Instant, early: Early) {
        let Early { origin, what } = early;
        let reliable = self.reliable;
        match (what, reliable) {
            (
                Sent::Sample {
                    meta,
                    flags,
                    sample,
                },
                Some(config),
            ) if flags & FLAG_RELIABLE != 0 => {
                let stream = stream(state, config, &origin);
                stream.reader.handle_sample(now, meta.seq, (meta, sample));
                self.pump(state, now);
            }
            (Sent::Sample { meta, sample, .. }, _) => {
                state.arbiter.handle_sample(now, meta, sample);
                self.drain(&mut state.arbiter);
            }
            (control, Some(config)) => {
                let reader = &mut stream(state, config, &origin).reader;
                match control {
                    Sent::Heartbeat(heartbeat) => {
                        reader.handle_heartbeat(now, heartbeat.first, heartbeat.last);
                    }
                    Sent::Gap(gap) => reader.handle_gap(gap.from, gap.to),
                    Sent::Partial(seq) => reader.handle_partial(now, seq),
                    Sent::Sample { .. } => {}
                }
                self.pump(state, now);
            }
            // Reliable-stream control for a best-effort consumer: nothing to do.
            (_, None) => {}
        }
    }

    /// The producers this consumer is matched with now (discovery's view): samples held for
    /// the new ones are acted on.
    pub(crate) fn set_matched(&self, now: Instant, matched: Matched<'_>) {
        let producers = matched
            .filter(|info| info.kind() == EndpointKind::Producer)
            .map(|info| (info.guid, SocketAddrV4::from(info.locator)));
        let mut state = lock(&self.state);
        let before = state.admission.stats();
        let released = state.admission.set_matched(now, producers);
        self.net.unbelieved.add(before, state.admission.stats());
        for early in released {
            self.accept(&mut state, now, early);
        }
        self.reschedule(&state);
    }

    /// What this consumer did not believe.
    pub(crate) fn admission_stats(&self) -> AdmissionStats {
        lock(&self.state).admission.stats()
    }

    /// A reliable producer's heartbeat.
    pub(crate) fn on_heartbeat(&self, now: Instant, origin: &Origin, heartbeat: Heartbeat) {
        self.control(now, origin, Sent::Heartbeat(heartbeat));
    }

    /// A piece of a reliable producer's large sample arrived; the sample is not complete.
    pub(crate) fn on_partial(&self, now: Instant, origin: &Origin, seq: u64) {
        self.control(now, origin, Sent::Partial(seq));
    }

    /// A reliable producer's gap.
    pub(crate) fn on_gap(&self, now: Instant, origin: &Origin, gap: Gap) {
        self.control(now, origin, Sent::Gap(gap));
    }

    /// Reliable-stream control (a reliable consumer only): acted on for a matched producer,
    /// held like its samples for one not matched yet (its first heartbeat is what starts the
    /// stream), dropped from anyone else. Then moves what it can deliver and sends the
    /// acknowledgements.
    fn control(&self, now: Instant, origin: &Origin, what: Sent) {
        if self.reliable.is_none() {
            return;
        }
        let mut state = lock(&self.state);
        let before = state.admission.stats();
        self.admit(&mut state, before, now, origin, CONTROL_BYTES, what);
    }

    /// The application took events: samples waiting for room move on (reliable only).
    pub(crate) fn resume(&self, now: Instant) {
        if self.reliable.is_none() {
            return;
        }
        let mut state = lock(&self.state);
        self.pump(&mut state, now);
        self.reschedule(&state);
    }

    /// Runs the due timers; returns the next one.
    pub(crate) fn timeout(&self, now: Instant) -> Option<Instant> {
        let mut state = lock(&self.state);
        if state.admission.poll_timeout().is_some_and(|due| due <= now) {
            let before = state.admission.stats();
            state.admission.handle_timeout(now);
            self.net.unbelieved.add(before, state.admission.stats());
        }
        if state.arbiter.poll_timeout().is_some_and(|due| due <= now) {
            state.arbiter.handle_timeout(now);
            self.drain(&mut state.arbiter);
        }
        for stream in state.streams.values_mut() {
            if stream.reader.poll_timeout().is_some_and(|due| due <= now) {
                stream.reader.handle_timeout(now);
            }
        }
        self.pump(&mut state, now);
        next_timer(&state)
    }

    /// A matched producer went away.
    pub(crate) fn writer_lost(&self, writer: Guid) {
        let mut state = lock(&self.state);
        state.admission.unmatched(Instant::now(), &writer);
        if let Some(stream) = state.streams.remove(&writer)
            && stream.reader.is_synced()
        {
            if state.resume.len() >= RESUMABLE
                && let Some(oldest) = state
                    .resume
                    .iter()
                    .min_by_key(|(_, (_, at))| *at)
                    .map(|(guid, _)| *guid)
            {
                state.resume.remove(&oldest);
            }
            state
                .resume
                .insert(writer, (stream.reader.next_seq(), Instant::now()));
        }
        state.arbiter.handle_writer_lost(writer);
        self.drain(&mut state.arbiter);
    }

    /// Hands the application a notification that does not come from arbitration.
    pub(crate) fn notify(&self, notification: Notification) {
        let _state = lock(&self.state);
        self.sink.push(RawEvent::Notification(notification));
    }

    /// Sends every later event to `callback`, on the thread that produces it.
    pub(crate) fn set_direct(&self, callback: Direct) {
        let _state = lock(&self.state);
        self.sink.set_direct(callback);
    }

    /// The next seq the reliable stream of `writer` hands out (`None`: no such stream).
    pub(crate) fn next_seq(&self, writer: Guid) -> Option<u64> {
        self.reliable?;
        lock(&self.state)
            .streams
            .get(&writer)
            .map(|stream| stream.reader.next_seq())
    }

    /// The arbiter's counters.
    pub(crate) fn arbiter_stats(&self) -> ArbiterStats {
        lock(&self.state).arbiter.stats()
    }

    /// Moves in-order samples of the reliable streams to the arbiter while the sink has room,
    /// reports lost runs, and sends the streams' acknowledgements.
    fn pump(&self, state: &mut State, now: Instant) {
        let State {
            arbiter,
            streams,
            feedback,
            ..
        } = state;
        for (writer, stream) in streams.iter_mut() {
            while self.sink.room() > 0 {
                match stream.reader.poll_deliver() {
                    Some(Delivery::Sample {
                        sample: (meta, raw),
                        ..
                    }) => {
                        arbiter.handle_sample(now, meta, raw);
                        self.drain(arbiter);
                    }
                    Some(Delivery::Lost { from, to }) => {
                        self.sink
                            .push(RawEvent::Notification(Notification::SamplesLost {
                                writer: *writer,
                                from,
                                to,
                            }));
                    }
                    None => break,
                }
            }
            while let Some(ack) = stream.reader.poll_output() {
                self.send_ack(feedback, *writer, stream.from, ack);
            }
        }
    }

    fn send_ack(&self, buf: &mut Vec<u8>, writer: Guid, to: SocketAddrV4, ack: AckNack) {
        let sub = FeedbackSub::AckNack(WireAckNack {
            reader: self.entity,
            writer: writer.entity,
            acked: ack.acked,
            missing: ack.missing.as_bytes(),
        });
        let net = &self.net;
        if encode_feedback(net.domain, net.participant, writer.participant, &[sub], buf).is_ok() {
            let _ = net.send(buf, to);
        }
    }

    /// Moves the arbiter's outputs to the sink.
    fn drain(&self, arbiter: &mut Arbiter<RawSample>) {
        while let Some(output) = arbiter.poll_output() {
            match output {
                Output::Deliver { mut sample, status } => {
                    sample.info.status = status;
                    self.sink.push(RawEvent::Sample(sample));
                }
                Output::Notify(notification) => {
                    self.sink.push(RawEvent::Notification(notification));
                }
            }
        }
    }

    fn reschedule(&self, state: &State) {
        if let Some(at) = next_timer(state) {
            self.timer.schedule(at);
        }
    }
}

/// The stream of `origin`'s writer, created on first use.
fn stream<'a>(state: &'a mut State, config: ReaderConfig, origin: &Origin) -> &'a mut Stream {
    let resume = &mut state.resume;
    let stream = state.streams.entry(origin.writer).or_insert_with(|| {
        let mut reader = ReliableReader::new(config);
        if let Some((next, _)) = resume.remove(&origin.writer) {
            reader.resume_at(next);
        }
        Stream {
            reader,
            from: origin.from,
        }
    });
    stream.from = origin.from;
    stream
}

/// The earliest timer of the arbiter and the streams.
fn next_timer(state: &State) -> Option<Instant> {
    state
        .streams
        .values()
        .filter_map(|s| s.reader.poll_timeout())
        .chain(state.arbiter.poll_timeout())
        .chain(state.admission.poll_timeout())
        .min()
}

//! Producers: write samples of a topic straight to every matched consuming process — each
//! in a datagram of its own, packed with others (batching), or cut into fragments when it is
//! larger than a datagram.

mod outbox;

use std::marker::PhantomData;
use std::net::SocketAddrV4;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};

use ndds_core::admission::{Admission, AdmissionConfig};
use ndds_core::reliability::{ReliableWriter, WriterConfig, WriterOutput};
use ndds_core::types::TypeDescription;
use ndds_core::wire::data::{FLAG_RELIABLE, Gap, Heartbeat, Sample};
use ndds_core::wire::feedback::bit;
use ndds_core::wire::{
    DataSub, EndpointInfo, EndpointKind, EndpointQos, FeedbackSub, Guid, Reliability, SampleMeta,
};
use serde::Serialize;

use self::outbox::{Kept, KeptPool, Outbox, whole_limit};
use crate::error::WriteError;
use crate::participant::EndpointHandle;
use crate::peers::{Matched, Peers};
use crate::plane::{Net, Timed, Timer, WriterSide};
use crate::qos::{Batching, ProducerQos, WhenFull, duration_us};
use crate::sync::lock;

/// A fragmented sample of at most this many pieces is resent whole when a reader asks for it
/// again; a larger one is repaired piece by piece.
const FULL_RESEND_PIECES: u32 = 16;

/// The reliable side of a reliable producer.
#[derive(Debug)]
struct Reliable {
    writer: ReliableWriter<Guid, Kept>,
    /// What the writer asked to send, drained into this reused buffer.
    outputs: Vec<WriterOutput<Guid, Kept>>,
}

/// Everything a write changes, under one lock.
#[derive(Debug, Default)]
struct Out {
    outbox: Outbox,
    seq: u64,
    /// The newest fragmented sample, for best-effort readers that ask for missing pieces.
    kept: Option<Kept>,
    /// `Some` for a reliable producer.
    reliable: Option<Reliable>,
    /// Buffers of kept samples.
    pool: KeptPool,
    /// The time the timer thread will run this producer's timers at the latest (what was last
    /// handed to it), so a write schedules the timer only when it needs it earlier.
    armed: Option<Instant>,
    /// The matched consumers: feedback from anyone else is not believed.
    believed: Believed,
}

/// The matched consumers of a producer, at their locators.
#[derive(Debug)]
struct Believed(Admission<()>);

impl Default for Believed {
    fn default() -> Self {
        // Feedback is never held: a consumer acknowledges only what it was sent.
        Believed(Admission::new(AdmissionConfig {
            max_held: 0,
            ..AdmissionConfig::default()
        }))
    }
}

/// State of one producer shared with the participant's router, receive and timer threads.
#[derive(Debug)]
pub(crate) struct ProducerState {
    pub(crate) entity: u32,
    qos: ProducerQos,
    pub(crate) peers: Peers,
    net: Arc<Net>,
    timer: Arc<Timer>,
    out: Mutex<Out>,
    /// Signalled when a reliable producer's window may have opened.
    window: Condvar,
    written: AtomicU64,
}

impl ProducerState {
    pub(crate) fn new(
        entity: u32,
        topic: &str,
        type_desc: TypeDescription,
        qos: ProducerQos,
        net: Arc<Net>,
        timer: Arc<Timer>,
    ) -> Self {
        let reliable = match qos.reliability {
            Reliability::Reliable { depth } => Some(Reliable {
                writer: ReliableWriter::new(WriterConfig {
                    depth: usize::try_from(depth).unwrap_or(usize::MAX).max(1),
                    late_joiners: qos.late_joiners,
                    ..WriterConfig::default()
                }),
                outputs: Vec::new(),
            }),
            Reliability::BestEffort => None,
        };
        ProducerState {
            entity,
            qos,
            peers: Peers::new(topic, type_desc),
            net,
            timer,
            out: Mutex::new(Out {
                pool: KeptPool::new(
                    reliable
                        .as_ref()
                        .map_or(2, |r| r.writer.config().depth.saturating_add(2)),
                ),
                reliable,
                ..Out::default()
            }),
            window: Condvar::new(),
            written: AtomicU64::new(0),
        }
    }

    /// Rebuilds the destinations from the matched consumers; a reliable producer starts
    /// serving the reliable consumers that appeared and forgets those that left.
    pub(crate) fn set_matched(&self, matched: Matched<'_>) {
        let mut out = lock(&self.out);
        let consumers: Vec<(Guid, SocketAddrV4)> = matched
            .clone()
            .filter(|info| info.kind() == EndpointKind::Consumer)
            .map(|info| (info.guid, SocketAddrV4::from(info.locator)))
            .collect();
        // The consumers that join now: not believed before this change.
        let joined: Vec<Guid> = consumers
            .iter()
            .map(|(guid, _)| *guid)
            .filter(|guid| !out.believed.0.is_matched(guid))
            .collect();
        out.believed.0.set_matched(Instant::now(), consumers);
        out.outbox.set_matched(&self.net, matched.clone());
        let Some(reliable) = out.reliable.as_mut() else {
            if self.qos.late_joiners > 0 {
                self.send_latest(&mut out, &joined);
            }
            return;
        };
        let now = Instant::now();
        let wanted: Vec<Guid> = matched
            .filter(|info| {
                matches!(
                    &info.qos,
                    EndpointQos::Consumer(c) if matches!(c.reliability, Reliability::Reliable { .. })
                )
            })
            .map(|info| info.guid)
            .collect();
        let gone: Vec<Guid> = reliable
            .writer
            .readers()
            .filter(|reader| !wanted.contains(reader))
            .collect();
        for reader in gone {
            reliable.writer.remove_reader(reader);
        }
        for reader in wanted {
            reliable.writer.add_reader(now, reader);
        }
        self.window.notify_all();
        self.drain(&mut out);
        if let Some(at) = self.arm(&mut out) {
            self.timer.schedule(at);
        }
    }

    /// Best effort, keeping the newest sample for late joiners: sends it to the consumers
    /// that just matched.
    fn send_latest(&self, out: &mut Out, joined: &[Guid]) {
        let Some(latest) = out.kept.clone() else {
            return;
        };
        for &reader in joined {
            let Some(dest) = out.outbox.dest_of(reader) else {
                continue;
            };
            let sent = if latest.bytes.len() > whole_limit(&self.net) {
                dest.send_fragments(
                    &self.net,
                    self.entity,
                    Some(reader.entity),
                    latest.meta,
                    &latest.bytes,
                    None,
                )
            } else {
                let sample = DataSub::Sample(Sample {
                    meta: latest.meta,
                    payload: &latest.bytes,
                });
                dest.send_now(
                    &self.net,
                    self.entity,
                    Some(reader.entity),
                    std::iter::once(sample),
                )
            };
            if let Err(err) = sent {
                tracing::debug!(%reader, %err, "sending the latest sample to a late joiner failed");
            }
        }
    }

    fn flags(&self) -> u8 {
        match self.qos.reliability {
            Reliability::Reliable { .. } => FLAG_RELIABLE,
            Reliability::BestEffort => 0,
        }
    }

    /// Encodes with `encode` into the reused buffer and sends; returns when the producer's
    /// timers must run next.
    fn write_with(
        &self,
        encode: impl FnOnce(&mut Vec<u8>) -> Result<(), WriteError>,
    ) -> Result<Option<Instant>, WriteError> {
        let mut out = self.wait_for_window(lock(&self.out))?;
        if out.reliable.is_some() {
            // Encoded straight into a history buffer: the history needs no copy.
            let encoded = out.pool.fill(encode)?;
            return self.send_locked(&mut out, &encoded, Some(&encoded));
        }
        let mut payload = std::mem::take(&mut out.outbox.payload);
        payload.clear();
        let result = encode(&mut payload).and_then(|()| self.send_locked(&mut out, &payload, None));
        out.outbox.payload = payload;
        result
    }

    /// Waits (up to the write timeout) until a reliable producer's window is open. On the
    /// participant's own receive or timer thread (a direct callback writing) it never waits:
    /// the acknowledgements that would open the window arrive on that very thread.
    fn wait_for_window<'a>(
        &self,
        mut out: MutexGuard<'a, Out>,
    ) -> Result<MutexGuard<'a, Out>, WriteError> {
        let mut started = None;
        loop {
            let Some(reliable) = &out.reliable else {
                return Ok(out);
            };
            if reliable.writer.window_open() || self.qos.when_full == WhenFull::DropOldest {
                return Ok(out);
            }
            let started = *started.get_or_insert_with(Instant::now);
            let waited = started.elapsed();
            let left = self
                .qos
                .write_timeout
                .checked_sub(waited)
                .filter(|l| !l.is_zero() && !crate::plane::on_plane_thread());
            let Some(left) = left else {
                return Err(WriteError::WouldBlock {
                    waited,
                    unacknowledged: reliable.writer.history_len(),
                });
            };
            out = self
                .window
                .wait_timeout(out, left)
                .map(|(guard, _)| guard)
                .unwrap_or_else(|poison| poison.into_inner().0);
        }
    }

    /// Sends `payload`; `kept` is the same bytes already in a pooled buffer, if they are.
    fn send_locked(
        &self,
        out: &mut Out,
        payload: &[u8],
        kept: Option<&Arc<Vec<u8>>>,
    ) -> Result<Option<Instant>, WriteError> {
        let max = self.net.limits.max_sample;
        if payload.len() > max {
            return Err(WriteError::TooLarge {
                size: payload.len(),
                max,
            });
        }
        out.seq += 1;
        let meta = SampleMeta {
            seq: out.seq,
            timestamp_ns: now_ns(),
            strength: self.qos.strength,
            persistence_us: duration_us(self.qos.persistence),
            flags: self.flags(),
        };
        // The monotonic clock only where something is timed: reliable streams and batches.
        let now = (out.reliable.is_some() || self.qos.batching != Batching::Off).then(Instant::now);
        let fragmented = payload.len() > whole_limit(&self.net);
        // The newest sample of a best-effort producer that keeps it for late joiners.
        let latest = out.reliable.is_none() && self.qos.late_joiners > 0;
        // Kept for repairs: every sample of a reliable producer (its history), the newest
        // fragmented one of a best-effort producer (and the newest one for late joiners).
        let kept = (out.reliable.is_some() || fragmented || latest).then(|| Kept {
            meta,
            bytes: kept.cloned().unwrap_or_else(|| out.pool.copy(payload)),
        });
        if let Some(reliable) = &mut out.reliable
            && let Some(kept) = &kept
            && let Some(now) = now
        {
            // Recorded before sending, so an acknowledgement racing the send finds it.
            let _ = reliable
                .writer
                .write(now, meta.seq, kept.clone(), payload.len());
        }
        let result = out.outbox.send(
            &self.net,
            self.entity,
            meta,
            payload,
            now,
            self.qos.batching,
        );
        if fragmented || latest {
            out.kept = kept;
        }
        self.written.fetch_add(1, Ordering::Relaxed);
        self.drain(out);
        result.map(|()| self.arm(out))
    }

    /// The time the timer thread must be told about: the next timer, when it is earlier than
    /// what the timer thread already has for this producer.
    fn arm(&self, out: &mut Out) -> Option<Instant> {
        let at = self.next_timer(out)?;
        if out.armed.is_some_and(|armed| armed <= at) {
            return None;
        }
        out.armed = Some(at);
        Some(at)
    }

    /// When the producer's timers (batch flush, heartbeats) must run next.
    fn next_timer(&self, out: &Out) -> Option<Instant> {
        let batch = out.outbox.next_due(self.qos.batching);
        let reliable = out.reliable.as_ref().and_then(|r| r.writer.poll_timeout());
        match (batch, reliable) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Sends what the reliable writer asked for: per reader, its gaps, resends and heartbeat,
    /// in datagrams addressed to that reader only.
    fn drain(&self, out: &mut Out) {
        let Out {
            outbox, reliable, ..
        } = out;
        let Some(reliable) = reliable else {
            return;
        };
        reliable.outputs.clear();
        while let Some(output) = reliable.writer.poll_output() {
            reliable.outputs.push(output);
        }
        let net = &self.net;
        let mut rest = &reliable.outputs[..];
        while let Some(first) = rest.first() {
            let reader = output_reader(first);
            let count = rest
                .iter()
                .take_while(|o| output_reader(o) == reader)
                .count();
            let (group, tail) = rest.split_at(count);
            rest = tail;
            let Some(dest) = outbox.dest_of(reader) else {
                continue;
            };
            // Fragmented samples asked for again: a few pieces go again whole; of a large
            // one, only its last piece goes, and the reader's requests for the pieces it
            // lacks (NackFrag) do the rest, so what already arrived is not sent again.
            for output in group {
                if let WriterOutput::Resend { sample, .. } = output
                    && sample.bytes.len() > whole_limit(net)
                {
                    let count = outbox::split(net, sample.bytes.len()).map_or(1, |s| s.count());
                    let last = count.saturating_sub(1);
                    let mut only_last = std::iter::once(last);
                    let pieces: Option<&mut dyn Iterator<Item = u32>> =
                        (count > FULL_RESEND_PIECES).then_some(&mut only_last);
                    let _ = dest.send_fragments(
                        net,
                        self.entity,
                        Some(reader.entity),
                        sample.meta,
                        &sample.bytes,
                        pieces,
                    );
                }
            }
            let subs = group.iter().filter_map(|output| match output {
                WriterOutput::Resend { sample, .. } => (sample.bytes.len() <= whole_limit(net))
                    .then(|| {
                        DataSub::Sample(Sample {
                            meta: sample.meta,
                            payload: &sample.bytes,
                        })
                    }),
                WriterOutput::Gap { from, to, .. } => Some(DataSub::Gap(Gap {
                    from: *from,
                    to: *to,
                })),
                WriterOutput::Heartbeat { first, last, .. } => {
                    Some(DataSub::Heartbeat(Heartbeat {
                        first: *first,
                        last: *last,
                    }))
                }
            });
            if let Err(err) = dest.send_now(net, self.entity, Some(reader.entity), subs) {
                tracing::debug!(to = %dest.addr, %err, "reliable control send failed");
            }
        }
        reliable.outputs.clear();
    }
}

fn output_reader(output: &WriterOutput<Guid, Kept>) -> Guid {
    match output {
        WriterOutput::Resend { reader, .. }
        | WriterOutput::Gap { reader, .. }
        | WriterOutput::Heartbeat { reader, .. } => *reader,
    }
}

impl Timed for ProducerState {
    fn timeout(&self, now: Instant) -> Option<Instant> {
        let mut out = lock(&self.out);
        out.outbox.flush_due(&self.net, now, self.qos.batching);
        if let Some(reliable) = &mut out.reliable
            && reliable.writer.poll_timeout().is_some_and(|due| due <= now)
        {
            let was_open = reliable.writer.window_open();
            reliable.writer.handle_timeout(now);
            while let Some(reader) = reliable.writer.poll_silenced() {
                tracing::warn!(
                    topic = %self.peers.topic,
                    consumer = %reader,
                    "a reliable consumer stopped acknowledging: it no longer holds this producer's window (it gets SamplesLost for what it misses if it comes back)"
                );
            }
            if !was_open && reliable.writer.window_open() {
                self.window.notify_all();
            }
            self.drain(&mut out);
        }
        out.armed = self.next_timer(&out);
        out.armed
    }
}

impl WriterSide for ProducerState {
    fn on_feedback(
        &self,
        now: Instant,
        reader: Guid,
        from: SocketAddrV4,
        sub: &FeedbackSub<'_>,
    ) -> Option<Instant> {
        let mut out = lock(&self.out);
        let before = out.believed.0.stats();
        let believed = out.believed.0.admit(&reader, from);
        self.net.unbelieved.add(before, out.believed.0.stats());
        if !believed {
            return None;
        }
        match sub {
            FeedbackSub::AckNack(ack) => {
                let reliable = out.reliable.as_mut()?;
                let was_open = reliable.writer.window_open();
                reliable
                    .writer
                    .handle_acknack(now, reader, ack.acked, ack.missing);
                if !was_open && reliable.writer.window_open() {
                    self.window.notify_all();
                }
                self.drain(&mut out);
                self.arm(&mut out)
            }
            FeedbackSub::NackFrag(nack) => {
                // The history of a reliable producer, else the newest fragmented sample.
                let kept = out
                    .reliable
                    .as_ref()
                    .and_then(|r| r.writer.sample(nack.seq))
                    .or(out.kept.as_ref())
                    .filter(|k| k.meta.seq == nack.seq)?
                    .clone();
                let dest = out.outbox.dest_of(reader)?;
                let mut missing = (0..nack.missing.len() * 8)
                    .filter(|i| bit(nack.missing, *i))
                    .filter_map(|i| nack.base.checked_add(u32::try_from(i).ok()?));
                let _ = dest.send_fragments(
                    &self.net,
                    self.entity,
                    Some(reader.entity),
                    kept.meta,
                    &kept.bytes,
                    Some(&mut missing),
                );
                None
            }
        }
    }
}

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// A producer of samples of type `T` on one topic. Closing (dropping) it withdraws it.
#[derive(Debug)]
pub struct Producer<T> {
    raw: RawProducer,
    _type: PhantomData<fn(&T)>,
}

impl<T: Serialize> Producer<T> {
    pub(crate) fn new(raw: RawProducer) -> Self {
        Producer {
            raw,
            _type: PhantomData,
        }
    }

    /// Sends `value` to every matched consumer. Without batching it returns once the
    /// datagrams are handed to the operating system; with batching the sample may wait in a
    /// batch up to the batching delay (see [`RawProducer::flush`]).
    pub fn write(&self, value: &T) -> Result<(), WriteError> {
        self.raw.finish(self.raw.state.write_with(|payload| {
            let buffer = std::mem::take(payload);
            *payload = postcard::to_extend(value, buffer)?;
            Ok(())
        }))
    }

    /// See [`RawProducer::wait_for_acknowledgments`].
    pub fn wait_for_acknowledgments(&self, timeout: Duration) -> bool {
        self.raw.wait_for_acknowledgments(timeout)
    }

    /// The untyped producer underneath.
    pub fn raw(&self) -> &RawProducer {
        &self.raw
    }
}

impl<T> std::ops::Deref for Producer<T> {
    type Target = RawProducer;

    fn deref(&self) -> &RawProducer {
        &self.raw
    }
}

/// A producer of already-encoded samples (postcard bytes of the declared type), as tools use
/// it. Closing (dropping) it withdraws it.
#[derive(Debug)]
pub struct RawProducer {
    pub(crate) handle: EndpointHandle,
    pub(crate) state: Arc<ProducerState>,
}

impl RawProducer {
    /// Sends an encoded sample to every matched consumer.
    pub fn write_bytes(&self, payload: &[u8]) -> Result<(), WriteError> {
        // Sent from the caller's bytes, with no copy into the producer's buffer.
        let state = &self.state;
        let sent = state
            .wait_for_window(lock(&state.out))
            .and_then(|mut out| state.send_locked(&mut out, payload, None));
        self.finish(sent)
    }

    /// Hands a batch's timer to the participant's timer thread.
    fn finish(&self, result: Result<Option<Instant>, WriteError>) -> Result<(), WriteError> {
        if let Some(at) = result? {
            self.handle.inner.data.schedule(at);
        }
        Ok(())
    }

    /// Sends every sample waiting in a batch now.
    pub fn flush(&self) -> Result<(), WriteError> {
        let state = &self.state;
        let mut out = lock(&state.out);
        out.outbox.flush_all(&state.net)?;
        Ok(())
    }

    /// The topic name.
    pub fn topic(&self) -> &str {
        &self.state.peers.topic
    }

    /// This producer's global id (the `writer` of its samples at consumers).
    pub fn guid(&self) -> Guid {
        self.handle.guid()
    }

    /// The type description announced with this producer.
    pub fn type_description(&self) -> &TypeDescription {
        &self.state.peers.type_desc
    }

    /// The consumers currently matched.
    pub fn matched(&self) -> Vec<EndpointInfo> {
        self.state.peers.matched_list()
    }

    /// Consumers of this topic whose type differs.
    pub fn incompatible(&self) -> Vec<EndpointInfo> {
        self.state.peers.incompatible_list()
    }

    /// Waits until at least `count` consumers are matched; false at the timeout.
    pub fn wait_for_consumers(&self, count: usize, timeout: Duration) -> bool {
        self.state.peers.wait_matched(count, timeout)
    }

    /// Number of samples written so far.
    pub fn written(&self) -> u64 {
        self.state.written.load(Ordering::Relaxed)
    }

    /// The quality of service it was declared with.
    pub fn qos(&self) -> ProducerQos {
        self.state.qos
    }

    /// Waits until every matched consumer has acknowledged every sample written so far (a
    /// reliable producer about to be dropped calls this so its history can still repair
    /// losses); true at once for a best-effort producer, false if `timeout` passed first.
    pub fn wait_for_acknowledgments(&self, timeout: Duration) -> bool {
        let _ = self.flush();
        let deadline = Instant::now() + timeout;
        loop {
            let pending = lock(&self.state.out)
                .reliable
                .as_ref()
                .map_or(0, |reliable| reliable.writer.history_len());
            if pending == 0 {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

impl Drop for RawProducer {
    fn drop(&mut self) {
        // Whatever waits in a batch still leaves.
        let _ = self.flush();
    }
}

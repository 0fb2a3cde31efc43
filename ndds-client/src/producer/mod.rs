//! Producers: write samples of a topic straight to every matched consuming process — each
//! in a datagram of its own, packed with others (batching), or cut into fragments when it is
//! larger than a datagram.

mod outbox;

use std::marker::PhantomData;
use std::net::SocketAddrV4;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use ndds_core::types::TypeDescription;
use ndds_core::wire::data::FLAG_RELIABLE;
use ndds_core::wire::{EndpointInfo, FeedbackSub, Guid, Reliability, SampleMeta};
use serde::Serialize;

use self::outbox::{Kept, Outbox, send_fragments};
use crate::error::WriteError;
use crate::participant::EndpointHandle;
use crate::peers::{Matched, Peers};
use crate::plane::{Net, Timed, WriterSide};
use crate::qos::{ProducerQos, duration_us};
use crate::sync::lock;

/// Everything a write changes, under one lock.
#[derive(Debug, Default)]
struct Out {
    outbox: Outbox,
    seq: u64,
    /// The newest fragmented sample, for readers that ask for missing pieces.
    kept: Option<Kept>,
}

/// State of one producer shared with the participant's router, receive and timer threads.
#[derive(Debug)]
pub(crate) struct ProducerState {
    pub(crate) entity: u32,
    qos: ProducerQos,
    pub(crate) peers: Peers,
    net: Arc<Net>,
    out: Mutex<Out>,
    written: AtomicU64,
}

impl ProducerState {
    pub(crate) fn new(
        entity: u32,
        topic: &str,
        type_desc: TypeDescription,
        qos: ProducerQos,
        net: Arc<Net>,
    ) -> Self {
        ProducerState {
            entity,
            qos,
            peers: Peers::new(topic, type_desc),
            net,
            out: Mutex::new(Out::default()),
            written: AtomicU64::new(0),
        }
    }

    /// Rebuilds the destinations from the matched consumers.
    pub(crate) fn set_matched(&self, matched: Matched<'_>) {
        lock(&self.out).outbox.set_matched(&self.net, matched);
    }

    fn flags(&self) -> u8 {
        match self.qos.reliability {
            Reliability::Reliable { .. } => FLAG_RELIABLE,
            Reliability::BestEffort => 0,
        }
    }

    /// Encodes with `encode` into the reused buffer and sends.
    fn write_with(
        &self,
        encode: impl FnOnce(&mut Vec<u8>) -> Result<(), WriteError>,
    ) -> Result<Option<Instant>, WriteError> {
        let mut out = lock(&self.out);
        let mut payload = std::mem::take(&mut out.outbox.payload);
        payload.clear();
        let result = encode(&mut payload).and_then(|()| self.send_locked(&mut out, &payload));
        out.outbox.payload = payload;
        result
    }

    fn send_locked(&self, out: &mut Out, payload: &[u8]) -> Result<Option<Instant>, WriteError> {
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
        let now = Instant::now();
        let result = out.outbox.send(
            &self.net,
            self.entity,
            meta,
            payload,
            now,
            self.qos.batching,
        );
        if out
            .outbox
            .dests
            .iter()
            .any(|d| payload.len() > d.whole_limit(&self.net))
        {
            out.kept = Some(Kept {
                meta,
                bytes: bytes::Bytes::copy_from_slice(payload),
            });
        }
        self.written.fetch_add(1, Ordering::Relaxed);
        result.map(|()| out.outbox.next_due(self.qos.batching))
    }
}

impl Timed for ProducerState {
    fn timeout(&self, now: Instant) -> Option<Instant> {
        lock(&self.out)
            .outbox
            .flush_due(&self.net, now, self.qos.batching)
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
        let _ = (now, from);
        let FeedbackSub::NackFrag(nack) = sub else {
            return None;
        };
        let mut out = lock(&self.out);
        let kept = out.kept.clone().filter(|k| k.meta.seq == nack.seq)?;
        let dest = out
            .outbox
            .dests
            .iter_mut()
            .find(|d| d.participant == reader.participant)?;
        let mut missing = (0..nack.missing.len() * 8)
            .filter(|i| ndds_core::wire::feedback::bit(nack.missing, *i))
            .filter_map(|i| nack.base.checked_add(i as u32));
        let _ = send_fragments(
            dest,
            &self.net,
            self.entity,
            kept.meta,
            &kept.bytes,
            Some(&mut missing),
        );
        None
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
        self.finish(self.state.write_with(|buffer| {
            buffer.extend_from_slice(payload);
            Ok(())
        }))
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
}

impl Drop for RawProducer {
    fn drop(&mut self) {
        // Whatever waits in a batch still leaves.
        let _ = self.flush();
    }
}

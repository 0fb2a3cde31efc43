//! Producers: write samples of a topic straight to every matched consuming process — each
//! in a datagram of its own, packed with others (batching), or cut into fragments when it is
//! larger than a datagram (the data plane's core decides which, see
//! `ndds_core::participant`).

use std::marker::PhantomData;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use ndds_core::participant::{BatchConfig, BufferPool, MatchedConsumer, ProducerSpec};
use ndds_core::reliability::WriterConfig;
use ndds_core::types::TypeDescription;
use ndds_core::wire::{EndpointInfo, EndpointKind, EndpointQos, Guid, Reliability};
use serde::Serialize;

use crate::data_plane::DataPlane;
use crate::error::WriteError;
use crate::matches::{Matched, Peers};
use crate::participant::EndpointHandle;
use crate::qos::{Batching, ProducerQos, WhenFull, duration_us};
use crate::sync::lock;

/// State of one producer shared with the participant's router.
#[derive(Debug)]
pub(crate) struct ProducerState {
    pub(crate) entity: u32,
    qos: ProducerQos,
    pub(crate) peers: Peers,
    pub(crate) plane: Arc<DataPlane>,
    /// Buffers samples are encoded into before the data plane takes them (and shares them
    /// with its history and the datagrams that carry them). Held by a write from encoding
    /// until its datagrams are sent, so two threads writing with this producer never put its
    /// datagrams on the wire out of order (the data plane's own lock is not held while
    /// sending); one lock per write for both.
    writing: Mutex<BufferPool>,
}

impl ProducerState {
    pub(crate) fn new(
        entity: u32,
        topic: &str,
        type_desc: TypeDescription,
        qos: ProducerQos,
        plane: Arc<DataPlane>,
    ) -> Self {
        let reliable = match qos.reliability {
            Reliability::Reliable { depth } => Some(WriterConfig {
                depth: usize::try_from(depth).unwrap_or(usize::MAX).max(1),
                late_joiners: qos.late_joiners,
                ..WriterConfig::default()
            }),
            Reliability::BestEffort => None,
        };
        let spec = ProducerSpec {
            strength: qos.strength,
            persistence_us: duration_us(qos.persistence),
            reliable,
            refuse_when_full: qos.when_full != WhenFull::DropOldest,
            batching: match qos.batching {
                Batching::On {
                    max_bytes,
                    max_delay,
                } => Some(BatchConfig {
                    max_bytes,
                    max_delay,
                }),
                Batching::Off => None,
            },
            late_joiners: qos.late_joiners,
        };
        plane.add_producer(entity, spec, topic);
        // A history of `depth` samples, one being written and a few on their way out.
        let buffers = reliable.map_or(8, |r| r.depth.saturating_add(8));
        ProducerState {
            entity,
            qos,
            peers: Peers::new(topic, type_desc),
            plane,
            writing: Mutex::new(BufferPool::new(buffers)),
        }
    }

    /// Re-targets the samples at the matched consumers; a reliable producer starts serving
    /// the reliable consumers that appeared and forgets those that left.
    pub(crate) fn set_matched(&self, matched: Matched<'_>) {
        let consumers: Vec<MatchedConsumer> = matched
            .filter(|info| info.kind() == EndpointKind::Consumer)
            .map(|info| MatchedConsumer {
                guid: info.guid,
                locator: info.locator.into(),
                reliable: matches!(
                    &info.qos,
                    EndpointQos::Consumer(c) if matches!(c.reliability, Reliability::Reliable { .. })
                ),
            })
            .collect();
        self.plane.set_producer_matched(self.entity, &consumers);
    }

    /// Encodes with `encode` into a pooled buffer (outside the data plane's lock), then
    /// hands the sample to the data plane.
    fn write_with(
        &self,
        encode: impl FnOnce(&mut Vec<u8>) -> Result<(), WriteError>,
    ) -> Result<(), WriteError> {
        let mut pool = lock(&self.writing);
        let payload = pool.fill(encode)?;
        self.plane
            .write(self.entity, payload, self.qos.write_timeout)
    }

    /// Hands an encoded sample to the data plane, in order with this producer's other writes.
    fn send(&self, payload: &Arc<Vec<u8>>, timeout: Duration) -> Result<(), WriteError> {
        let _order = lock(&self.writing);
        self.plane.write(self.entity, payload, timeout)
    }
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
        self.raw.state.write_with(|payload| {
            let buffer = std::mem::take(payload);
            *payload = postcard::to_extend(value, buffer)?;
            Ok(())
        })
    }

    /// [`Producer::write`] for async code: a reliable producer whose window is full waits
    /// for it without blocking the thread (and without a thread per call: the participant's
    /// I/O thread wakes the task when acknowledgements open the window). It waits as long as
    /// it takes, not `write_timeout`; bound it with the runtime's timeout if needed. A
    /// consumer that stops acknowledging leaves the window within its liveness timeout, so
    /// the wait ends.
    pub async fn write_async(&self, value: &T) -> Result<(), WriteError> {
        let state = &self.raw.state;
        // Its own reference: the pool is not held while the task waits.
        let payload = Arc::clone(lock(&state.writing).fill(|payload| {
            let buffer = std::mem::take(payload);
            *payload = postcard::to_extend(value, buffer)?;
            Ok::<(), WriteError>(())
        })?);
        loop {
            match state.send(&payload, Duration::ZERO) {
                Err(WriteError::WouldBlock { .. }) => {
                    std::future::poll_fn(|cx| {
                        if state.plane.poll_window(state.entity, cx) {
                            std::task::Poll::Ready(())
                        } else {
                            std::task::Poll::Pending
                        }
                    })
                    .await;
                }
                other => return other,
            }
        }
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
        // Copied into a pooled buffer, which the history and the datagrams then share.
        let state = &self.state;
        let mut pool = lock(&state.writing);
        let payload = pool.copy(payload);
        state
            .plane
            .write(state.entity, payload, state.qos.write_timeout)
    }

    /// Sends every sample waiting in a batch now.
    pub fn flush(&self) -> Result<(), WriteError> {
        self.state.plane.flush(self.state.entity)
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

    /// Ready once at least `count` consumers are matched (the async form of
    /// [`RawProducer::wait_for_consumers`], without a timeout: race it with one).
    pub(crate) fn consumers_matched(&self, count: usize) -> impl Future<Output = ()> + '_ {
        std::future::poll_fn(move |cx| self.state.peers.poll_matched(count, cx))
    }

    /// Number of samples written so far.
    pub fn written(&self) -> u64 {
        self.state.plane.written(self.state.entity)
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
        self.state
            .plane
            .wait_acknowledged(self.state.entity, timeout)
    }
}

impl Drop for RawProducer {
    fn drop(&mut self) {
        // Whatever waits in a batch still leaves.
        let _ = self.flush();
    }
}

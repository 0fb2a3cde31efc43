//! Producers: write samples of a topic straight to every matched consuming process.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::marker::PhantomData;
use std::net::SocketAddrV4;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::time::{Duration, SystemTime};

use ndds_core::types::TypeDescription;
use ndds_core::wire::{
    self, Data, EncodeError, EndpointInfo, MAX_DATAGRAM, Message, ProducerQosWire,
};
use serde::Serialize;

use crate::error::WriteError;
use crate::participant::{EndpointHandle, Inner};
use crate::peers::{Matched, Peers};
use crate::sync::{lock, read, write};

/// Bytes a `Data` datagram adds to its payload: the header, and the body's fields at their
/// largest with up to 64 reader entities (the exact size is checked when encoding).
const DATA_OVERHEAD: usize = wire::HEADER_LEN + 5 + 10 + 1 + 64 * 5 + 10 + 10 + 5 + 10 + 3;

/// The largest encoded sample a producer accepts (no fragmentation yet).
pub const MAX_PAYLOAD: usize = MAX_DATAGRAM - DATA_OVERHEAD;

/// One consuming process: where to send, and which of its consumers to address.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Destination {
    addr: SocketAddrV4,
    participant: u64,
    readers: Vec<u32>,
}

/// Reused buffers, so steady-state writing does not allocate.
#[derive(Debug, Default)]
struct Scratch {
    payload: Vec<u8>,
    datagram: Vec<u8>,
}

/// State of one producer shared with the participant's event router.
#[derive(Debug)]
pub(crate) struct ProducerState {
    pub(crate) entity: u32,
    qos: ProducerQosWire,
    pub(crate) peers: Peers,
    destinations: RwLock<Vec<Destination>>,
    seq: AtomicU64,
    scratch: Mutex<Scratch>,
}

impl ProducerState {
    pub(crate) fn new(
        entity: u32,
        topic: &str,
        type_desc: TypeDescription,
        qos: ProducerQosWire,
    ) -> Self {
        ProducerState {
            entity,
            qos,
            peers: Peers::new(topic, type_desc),
            destinations: RwLock::new(Vec::new()),
            seq: AtomicU64::new(0),
            scratch: Mutex::new(Scratch::default()),
        }
    }

    /// Rebuilds the destination list from the matched consumers: one datagram per consuming
    /// participant (a stale entry may share an address with a live one).
    pub(crate) fn set_matched(&self, matched: Matched<'_>) {
        let mut by_locator: BTreeMap<(SocketAddrV4, u64), Destination> = BTreeMap::new();
        for consumer in matched {
            let addr = SocketAddrV4::from(consumer.locator);
            by_locator
                .entry((addr, consumer.guid.participant))
                .or_insert_with(|| Destination {
                    addr,
                    participant: consumer.guid.participant,
                    readers: Vec::new(),
                })
                .readers
                .push(consumer.guid.entity);
        }
        *write(&self.destinations) = by_locator.into_values().collect();
    }

    fn write_with(
        &self,
        inner: &Inner,
        encode: impl FnOnce(&mut Vec<u8>) -> Result<(), WriteError>,
    ) -> Result<(), WriteError> {
        let mut scratch = lock(&self.scratch);
        let Scratch { payload, datagram } = &mut *scratch;
        payload.clear();
        encode(payload)?;
        self.send(inner, payload, datagram)
    }

    fn send(
        &self,
        inner: &Inner,
        payload: &[u8],
        datagram: &mut Vec<u8>,
    ) -> Result<(), WriteError> {
        // Refused whether or not a consumer is matched, so the error never depends on timing.
        if payload.len() > MAX_PAYLOAD {
            return Err(WriteError::TooLarge {
                size: payload.len(),
                max: MAX_PAYLOAD,
            });
        }
        let seq = self.seq.fetch_add(1, Ordering::Relaxed) + 1;
        let timestamp_ns = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        let destinations = read(&self.destinations);
        let mut last_error = None;
        let mut delivered = 0usize;
        for destination in destinations.iter() {
            datagram.clear();
            let message = Message::Data(Data {
                writer: self.entity,
                reader_participant: destination.participant,
                readers: Cow::Borrowed(&destination.readers),
                seq,
                timestamp_ns,
                strength: self.qos.strength,
                persistence_us: self.qos.persistence_us,
                payload,
            });
            match wire::encode(inner.domain(), inner.participant, &message, datagram) {
                Ok(()) => {}
                // Only with more readers in one process than the overhead allows for.
                Err(EncodeError::TooLarge { size }) => {
                    return Err(WriteError::TooLarge {
                        size: payload.len(),
                        max: MAX_DATAGRAM - (size - payload.len()),
                    });
                }
                Err(EncodeError::Postcard(err)) => return Err(WriteError::Serialize(err)),
            }
            match inner.data.socket.send_to(datagram, destination.addr) {
                Ok(_) => delivered += 1,
                Err(err) => {
                    tracing::debug!(to = %destination.addr, %err, "data send failed");
                    last_error = Some(err);
                }
            }
        }
        match last_error {
            Some(err) if delivered == 0 => Err(err.into()),
            _ => Ok(()),
        }
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

    /// Sends `value` to every matched consumer. Returns once the datagrams are handed to the
    /// operating system; best effort: a consumer may miss it.
    pub fn write(&self, value: &T) -> Result<(), WriteError> {
        self.raw
            .state
            .write_with(&self.raw.handle.inner, |payload| {
                let buffer = std::mem::take(payload);
                *payload = postcard::to_extend(value, buffer)?;
                Ok(())
            })
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
        let mut scratch = lock(&self.state.scratch);
        self.state
            .send(&self.handle.inner, payload, &mut scratch.datagram)
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
        self.state.seq.load(Ordering::Relaxed)
    }
}

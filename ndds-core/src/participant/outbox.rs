//! A producer's outgoing side: its destinations (one per group of consumers in one
//! participant), the batch being filled for each, the cutting of large samples into
//! fragments, and datagrams addressed to a single consumer (repairs and reliable-stream
//! control). Everything becomes [`Transmit`](super::Transmit)s; nothing is sent here.

use std::net::SocketAddrV4;
use std::sync::Arc;
use std::time::{Duration, Instant};

use sha2::{Digest, Sha256};

use crate::fragment::Split;
use crate::wire::data::{
    AddressToken, Addressing, FRAGMENT_OVERHEAD, Fragment, SAMPLE_OVERHEAD, Sample, prefix_overhead,
};
use crate::wire::{DataSub, DataWriter, Guid, SampleMeta};

use super::transmit::Transmits;

/// Most consumers one datagram names. A participant with more consumers of the topic gets
/// one destination per group. Sizes are computed for a full group, so a sample is cut the
/// same way (same piece size) whichever destination or single reader it is sent to, and
/// resent pieces always match the first ones.
pub(crate) const GROUP: usize = 8;

/// How a producer packs samples into datagrams.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchConfig {
    /// A batch leaves once it holds this many bytes (capped by the datagram size).
    pub max_bytes: usize,
    /// ... or once its first sample has waited this long.
    pub max_delay: Duration,
}

/// What encoding needs: the sender, the datagram size, and where datagrams go.
pub(crate) struct Tx<'a> {
    pub(crate) domain: u16,
    pub(crate) participant: u64,
    pub(crate) max_datagram: usize,
    /// The participant's secret, from which its address tokens are derived.
    pub(crate) secret: &'a [u8; 32],
    pub(crate) out: &'a mut Transmits,
}

/// Bytes a producer may send in answer to feedback that did not echo its destination's
/// address token, per byte of that feedback: the address has not proved it receives there.
pub(crate) const UNVALIDATED_FACTOR: usize = 3;

/// The token of destination `participant` at `addr`: the first 8 bytes of SHA-256 over a
/// label, the secret and the destination, never 0 (which stands for none).
pub(crate) fn address_token(
    secret: &[u8; 32],
    addr: SocketAddrV4,
    participant: u64,
) -> AddressToken {
    let mut hash = Sha256::new();
    hash.update(b"ndds address token v1");
    hash.update(secret);
    hash.update(addr.ip().octets());
    hash.update(addr.port().to_le_bytes());
    hash.update(participant.to_le_bytes());
    let digest = hash.finalize();
    let mut first = [0; 8];
    first.copy_from_slice(&digest[..8]);
    u64::from_le_bytes(first).max(1)
}

impl Tx<'_> {
    /// Largest sample sent whole, in one datagram.
    pub(crate) fn whole_limit(&self) -> usize {
        whole_limit(self.max_datagram)
    }
}

/// Largest sample sent whole in datagrams of `max_datagram` bytes.
pub(crate) fn whole_limit(max_datagram: usize) -> usize {
    max_datagram.saturating_sub(prefix_overhead(GROUP) + SAMPLE_OVERHEAD)
}

/// The pieces of a large sample, for datagrams of `max_datagram` bytes.
pub(crate) fn split(max_datagram: usize, len: usize) -> Option<Split> {
    let frag_size = max_datagram.saturating_sub(prefix_overhead(GROUP) + FRAGMENT_OVERHEAD);
    Split::new(len, frag_size).ok()
}

/// A group of consumers in one participant: where their samples go, and the batch being
/// filled for them.
#[derive(Debug)]
pub(crate) struct Dest {
    pub(crate) addr: SocketAddrV4,
    pub(crate) participant: u64,
    pub(crate) readers: Vec<u32>,
    /// What every datagram sent here carries, and feedback from here must echo.
    pub(crate) token: AddressToken,
    /// Bytes that may still be sent in answer to feedback from here that did not echo the
    /// token ([`UNVALIDATED_FACTOR`] times what such feedback brought, less what was sent).
    pub(crate) allowance: usize,
    batch: DataWriter,
    opened: Option<Instant>,
}

impl Dest {
    fn new(addr: SocketAddrV4, participant: u64, token: AddressToken) -> Self {
        Dest {
            addr,
            participant,
            readers: Vec::new(),
            token,
            allowance: 0,
            batch: DataWriter::new(),
            opened: None,
        }
    }

    /// True when this destination names `reader`.
    pub(crate) fn has(&self, reader: Guid) -> bool {
        self.participant == reader.participant && self.readers.contains(&reader.entity)
    }

    /// Starts a datagram in the batch buffer, to all readers or to `only`.
    fn begin(&mut self, tx: &Tx<'_>, writer: u32, only: Option<u32>) {
        let one;
        let readers = match only {
            Some(reader) => {
                one = [reader];
                &one[..]
            }
            None => &self.readers[..],
        };
        let to = Addressing {
            reader_participant: self.participant,
            writer,
            token: self.token,
            readers,
        };
        self.batch.begin(tx.domain, tx.participant, &to);
    }

    fn emit(&mut self, tx: &mut Tx<'_>) {
        tx.out.push(self.addr, self.batch.bytes(), None);
    }

    /// Queues submessages now (after any pending batch), to all readers or to `only`, packed
    /// into as few datagrams as they fit.
    pub(crate) fn send_now<'a>(
        &mut self,
        tx: &mut Tx<'_>,
        writer: u32,
        only: Option<u32>,
        subs: impl IntoIterator<Item = DataSub<'a>>,
    ) {
        self.flush(tx);
        let max = tx.max_datagram;
        self.begin(tx, writer, only);
        for sub in subs {
            if !self.batch.push(&sub, max) {
                if !self.batch.is_empty() {
                    self.emit(tx);
                }
                self.begin(tx, writer, only);
                if !self.batch.push(&sub, max) {
                    // Cannot happen for the sizes used here; never loop on it.
                    tracing::debug!("submessage larger than a datagram: not sent");
                    return;
                }
            }
        }
        if !self.batch.is_empty() {
            self.emit(tx);
        }
    }

    /// Queues one whole sample in a datagram of its own (after any pending batch), to all
    /// readers or to `only`; the payload follows the head without being copied (but for a
    /// small one).
    fn send_sample(
        &mut self,
        tx: &mut Tx<'_>,
        writer: u32,
        only: Option<u32>,
        meta: SampleMeta,
        payload: &Arc<Vec<u8>>,
    ) {
        self.flush(tx);
        self.begin(tx, writer, only);
        let sub = DataSub::Sample(Sample {
            meta,
            payload: payload.as_slice(),
        });
        if self.batch.push_head(&sub, tx.max_datagram).is_some() {
            tx.out.push(
                self.addr,
                self.batch.bytes(),
                Some((payload, 0..payload.len())),
            );
        }
    }

    /// Adds a whole sample to the batch.
    fn batch(
        &mut self,
        tx: &mut Tx<'_>,
        writer: u32,
        meta: SampleMeta,
        payload: &Arc<Vec<u8>>,
        now: Instant,
        max_bytes: usize,
    ) {
        let sub = DataSub::Sample(Sample {
            meta,
            payload: payload.as_slice(),
        });
        let limit = max_bytes.min(tx.max_datagram);
        if self.opened.is_none() {
            self.begin(tx, writer, None);
            self.opened = Some(now);
        }
        if !self.batch.push(&sub, limit) {
            self.flush(tx);
            self.begin(tx, writer, None);
            self.opened = Some(now);
            if !self.batch.push(&sub, limit) {
                // Larger than a batch but fits a datagram: it leaves alone.
                self.opened = None;
                return self.send_sample(tx, writer, None, meta, payload);
            }
        }
        if self.batch.bytes().len() >= limit {
            self.flush(tx);
        }
    }

    /// Queues the pending batch, if any.
    pub(crate) fn flush(&mut self, tx: &mut Tx<'_>) {
        if self.opened.take().is_none() || self.batch.is_empty() {
            return;
        }
        self.emit(tx);
    }

    /// When the pending batch must leave at the latest.
    fn due(&self, batching: Option<BatchConfig>) -> Option<Instant> {
        let batching = batching?;
        self.opened
            .and_then(|at| at.checked_add(batching.max_delay))
    }

    /// Queues the pieces of a large sample (all, or those listed), to all readers or to
    /// `only`, in order, one per datagram. Returns how many bytes were queued.
    pub(crate) fn send_fragments(
        &mut self,
        tx: &mut Tx<'_>,
        writer: u32,
        only: Option<u32>,
        meta: SampleMeta,
        payload: &Arc<Vec<u8>>,
        pieces: Option<&mut dyn Iterator<Item = u32>>,
    ) -> usize {
        let Some(split) = split(tx.max_datagram, payload.len()) else {
            return 0;
        };
        let mut all = 0..split.count();
        let indices: &mut dyn Iterator<Item = u32> = match pieces {
            Some(listed) => listed,
            None => &mut all,
        };
        self.flush(tx);
        let mut queued = 0;
        for index in indices {
            let Some(range) = split.range(index) else {
                continue;
            };
            let sub = DataSub::Fragment(Fragment {
                meta,
                total_len: split.total_len() as u32,
                frag_size: split.frag_size() as u32,
                index,
                chunk: &payload[range.clone()],
            });
            self.begin(tx, writer, only);
            if self.batch.push_head(&sub, tx.max_datagram).is_some() {
                queued += self.batch.bytes().len() + range.len();
                tx.out
                    .push(self.addr, self.batch.bytes(), Some((payload, range)));
            }
        }
        queued
    }
}

/// One matched consumer, as a producer sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MatchedConsumer {
    /// Its id.
    pub guid: Guid,
    /// Its participant's data socket.
    pub locator: SocketAddrV4,
    /// True when it asked for reliability.
    pub reliable: bool,
}

/// All destinations of one producer.
#[derive(Debug, Default)]
pub(crate) struct Outbox {
    pub(crate) dests: Vec<Dest>,
}

impl Outbox {
    /// Rebuilds the destinations from the matched consumers, sending pending batches first.
    pub(crate) fn set_matched(&mut self, tx: &mut Tx<'_>, matched: &[MatchedConsumer]) {
        for dest in &mut self.dests {
            dest.flush(tx);
        }
        let mut dests: Vec<Dest> = Vec::new();
        for consumer in matched {
            let addr = consumer.locator;
            let participant = consumer.guid.participant;
            let index = match dests.iter().position(|d| {
                d.addr == addr && d.participant == participant && d.readers.len() < GROUP
            }) {
                Some(index) => index,
                None => {
                    let token = address_token(tx.secret, addr, participant);
                    let mut dest = Dest::new(addr, participant, token);
                    // What feedback from there has earned so far stays earned.
                    dest.allowance = self
                        .dests
                        .iter()
                        .find(|d| d.addr == addr && d.participant == participant)
                        .map_or(0, |d| d.allowance);
                    dests.push(dest);
                    dests.len() - 1
                }
            };
            dests[index].readers.push(consumer.guid.entity);
        }
        self.dests = dests;
    }

    /// The destination that names `reader`.
    pub(crate) fn dest_of(&mut self, reader: Guid) -> Option<&mut Dest> {
        self.dests.iter_mut().find(|d| d.has(reader))
    }

    /// Queues one sample for every destination, whole (batched or not) or in fragments.
    pub(crate) fn send(
        &mut self,
        tx: &mut Tx<'_>,
        writer: u32,
        meta: SampleMeta,
        payload: &Arc<Vec<u8>>,
        now: Instant,
        batching: Option<BatchConfig>,
    ) {
        let whole = payload.len() <= tx.whole_limit();
        for dest in &mut self.dests {
            if whole {
                match batching {
                    Some(batching) => {
                        dest.batch(tx, writer, meta, payload, now, batching.max_bytes)
                    }
                    None => dest.send_sample(tx, writer, None, meta, payload),
                }
            } else {
                dest.send_fragments(tx, writer, None, meta, payload, None);
            }
        }
    }

    /// Sends one sample to one reader only (a late joiner).
    pub(crate) fn send_to(
        &mut self,
        tx: &mut Tx<'_>,
        writer: u32,
        reader: Guid,
        meta: SampleMeta,
        payload: &Arc<Vec<u8>>,
    ) {
        let whole = payload.len() <= tx.whole_limit();
        let Some(dest) = self.dest_of(reader) else {
            return;
        };
        if whole {
            dest.send_sample(tx, writer, Some(reader.entity), meta, payload);
        } else {
            dest.send_fragments(tx, writer, Some(reader.entity), meta, payload, None);
        }
    }

    /// Queues every batch that is due.
    pub(crate) fn flush_due(
        &mut self,
        tx: &mut Tx<'_>,
        now: Instant,
        batching: Option<BatchConfig>,
    ) {
        for dest in &mut self.dests {
            if dest.due(batching).is_some_and(|at| at <= now) {
                dest.flush(tx);
            }
        }
    }

    /// Queues every pending batch now.
    pub(crate) fn flush_all(&mut self, tx: &mut Tx<'_>) {
        for dest in &mut self.dests {
            dest.flush(tx);
        }
    }

    /// When the earliest pending batch is due.
    pub(crate) fn next_due(&self, batching: Option<BatchConfig>) -> Option<Instant> {
        self.dests.iter().filter_map(|d| d.due(batching)).min()
    }
}

/// Buffers for samples, reused once nothing holds them any more (the history let go of the
/// sample and the datagrams carrying it were sent), so a producer allocates nothing per
/// sample in a steady state. The producer's handle keeps one and encodes into it *before*
/// handing the sample to the core. A filled buffer is lent, not handed out: the core takes
/// its own reference only where it keeps the sample, so a write whose sample is copied into
/// a batch or a datagram costs no reference count at all.
#[derive(Debug, Default)]
pub struct BufferPool {
    buffers: Vec<Arc<Vec<u8>>>,
    /// Where the search for a free buffer starts: buffers come free in the order they were
    /// taken (the history is first in, first out), so the next one is usually free.
    next: usize,
    /// The largest sample kept so far: a new buffer starts with this capacity, so filling it
    /// does not grow it again.
    largest: usize,
    /// A buffer made when every kept one was busy and the pool was full: lent from here.
    extra: Option<Arc<Vec<u8>>>,
}

impl BufferPool {
    /// At most `capacity` buffers are kept for reuse (a history of `depth` samples needs
    /// `depth + 2`).
    pub fn new(capacity: usize) -> Self {
        BufferPool {
            buffers: Vec::with_capacity(capacity.clamp(2, 4096)),
            next: 0,
            largest: 0,
            extra: None,
        }
    }

    /// A buffer holding a copy of `payload`.
    pub fn copy(&mut self, payload: &[u8]) -> &Arc<Vec<u8>> {
        let filled = self.fill(|buffer| {
            buffer.extend_from_slice(payload);
            Ok::<(), std::convert::Infallible>(())
        });
        match filled {
            Ok(buffer) => buffer,
            Err(never) => match never {},
        }
    }

    /// A buffer filled by `fill` (given it empty), such as a sample encoded straight into it;
    /// clone the `Arc` to keep it beyond the next call.
    pub fn fill<E>(
        &mut self,
        fill: impl FnOnce(&mut Vec<u8>) -> Result<(), E>,
    ) -> Result<&Arc<Vec<u8>>, E> {
        let len = self.buffers.len();
        for step in 0..len {
            let index = (self.next + step) % len;
            if let Some(buffer) = Arc::get_mut(&mut self.buffers[index]) {
                buffer.clear();
                fill(buffer)?;
                self.largest = self.largest.max(buffer.len());
                self.next = (index + 1) % len;
                return Ok(&self.buffers[index]);
            }
        }
        let mut buffer = Vec::with_capacity(self.largest);
        fill(&mut buffer)?;
        self.largest = self.largest.max(buffer.len());
        let buffer = Arc::new(buffer);
        if self.buffers.len() < self.buffers.capacity() {
            self.buffers.push(buffer);
            return Ok(&self.buffers[len]);
        }
        Ok(self.extra.insert(buffer))
    }
}

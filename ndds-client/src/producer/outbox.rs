//! A producer's outgoing side: its destinations (one per group of consumers in one
//! participant), the batch being filled for each, the cutting of large samples into
//! fragments, and datagrams addressed to a single consumer (repairs and reliable-stream
//! control).

use std::net::SocketAddrV4;
use std::sync::Arc;
use std::time::Instant;

use ndds_core::fragment::Split;
use ndds_core::wire::data::{
    Addressing, FRAGMENT_OVERHEAD, Fragment, SAMPLE_OVERHEAD, Sample, prefix_overhead,
};
use ndds_core::wire::{DataSub, DataWriter, EndpointInfo, Guid, SampleMeta};

use crate::error::WriteError;
use crate::plane::Net;
use crate::qos::Batching;

/// Most consumers one datagram names. A participant with more consumers of the topic gets
/// one destination per group. Sizes are computed for a full group, so a sample is cut the
/// same way (same piece size) whichever destination or single reader it is sent to, and
/// resent pieces always match the first ones.
pub(crate) const GROUP: usize = 8;

/// Largest sample sent whole, in one datagram.
pub(crate) fn whole_limit(net: &Net) -> usize {
    net.limits
        .max_datagram
        .saturating_sub(prefix_overhead(GROUP) + SAMPLE_OVERHEAD)
}

/// The piece size of fragmented samples.
fn frag_size(net: &Net) -> usize {
    net.limits
        .max_datagram
        .saturating_sub(prefix_overhead(GROUP) + FRAGMENT_OVERHEAD)
}

/// The pieces of a large sample.
pub(crate) fn split(net: &Net, len: usize) -> std::io::Result<Split> {
    Split::new(len, frag_size(net)).map_err(|err| std::io::Error::other(err.to_string()))
}

/// A group of consumers in one participant: where their samples go, and the batch being
/// filled for them.
#[derive(Debug)]
pub(crate) struct Dest {
    pub(crate) addr: SocketAddrV4,
    pub(crate) participant: u64,
    pub(crate) readers: Vec<u32>,
    batch: DataWriter,
    opened: Option<Instant>,
}

impl Dest {
    fn new(addr: SocketAddrV4, participant: u64) -> Self {
        Dest {
            addr,
            participant,
            readers: Vec::new(),
            batch: DataWriter::new(),
            opened: None,
        }
    }

    /// True when this destination names `reader`.
    pub(crate) fn has(&self, reader: Guid) -> bool {
        self.participant == reader.participant && self.readers.contains(&reader.entity)
    }

    /// Starts a datagram in the batch buffer, to all readers or to `only`.
    fn begin(&mut self, net: &Net, writer: u32, only: Option<u32>) {
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
            readers,
        };
        self.batch.begin(net.domain, net.participant, &to);
    }

    /// Sends submessages now (after any pending batch), to all readers or to `only`, packed
    /// into as few datagrams as they fit.
    pub(crate) fn send_now<'a>(
        &mut self,
        net: &Net,
        writer: u32,
        only: Option<u32>,
        subs: impl IntoIterator<Item = DataSub<'a>>,
    ) -> std::io::Result<()> {
        self.flush(net)?;
        let max = net.limits.max_datagram;
        self.begin(net, writer, only);
        for sub in subs {
            if !self.batch.push(&sub, max) {
                if !self.batch.is_empty() {
                    net.send(self.batch.bytes(), self.addr)?;
                }
                self.begin(net, writer, only);
                if !self.batch.push(&sub, max) {
                    // Cannot happen for the sizes used here; never loop on it.
                    return Err(std::io::Error::other("submessage larger than a datagram"));
                }
            }
        }
        if self.batch.is_empty() {
            return Ok(());
        }
        net.send(self.batch.bytes(), self.addr)
    }

    /// Sends one whole sample now, in a datagram of its own (after any pending batch), to all
    /// readers or to `only`; the payload goes to the kernel without being copied first.
    pub(crate) fn send_sample(
        &mut self,
        net: &Net,
        writer: u32,
        only: Option<u32>,
        sub: &DataSub<'_>,
    ) -> std::io::Result<()> {
        self.flush(net)?;
        self.begin(net, writer, only);
        match self.batch.push_head(sub, net.limits.max_datagram) {
            Some(trailing) => net.send_parts(self.batch.bytes(), trailing, self.addr),
            None => Err(std::io::Error::other("sample larger than a datagram")),
        }
    }

    /// Adds a submessage to the batch.
    fn batch(
        &mut self,
        net: &Net,
        writer: u32,
        sub: &DataSub<'_>,
        now: Instant,
        max_bytes: usize,
    ) -> std::io::Result<()> {
        let limit = max_bytes.min(net.limits.max_datagram);
        if self.opened.is_none() {
            self.begin(net, writer, None);
            self.opened = Some(now);
        }
        if !self.batch.push(sub, limit) {
            self.flush(net)?;
            self.begin(net, writer, None);
            self.opened = Some(now);
            if !self.batch.push(sub, limit) {
                // Larger than a batch but fits a datagram: it leaves alone.
                return self.send_now(net, writer, None, [sub.clone()]);
            }
        }
        if self.batch.bytes().len() >= limit {
            self.flush(net)?;
        }
        Ok(())
    }

    /// Sends the pending batch, if any.
    pub(crate) fn flush(&mut self, net: &Net) -> std::io::Result<()> {
        if self.opened.take().is_none() || self.batch.is_empty() {
            return Ok(());
        }
        net.send(self.batch.bytes(), self.addr)
    }

    /// When the pending batch must leave at the latest.
    fn due(&self, batching: Batching) -> Option<Instant> {
        match batching {
            Batching::On { max_delay, .. } => self.opened.and_then(|at| at.checked_add(max_delay)),
            Batching::Off => None,
        }
    }

    /// Sends the pieces of a large sample (all, or those listed), to all readers or to
    /// `only`. Pieces go in order, one per datagram.
    pub(crate) fn send_fragments(
        &mut self,
        net: &Net,
        writer: u32,
        only: Option<u32>,
        meta: SampleMeta,
        payload: &[u8],
        pieces: Option<&mut dyn Iterator<Item = u32>>,
    ) -> std::io::Result<()> {
        let split = split(net, payload.len())?;
        let mut all = 0..split.count();
        let indices: &mut dyn Iterator<Item = u32> = match pieces {
            Some(listed) => listed,
            None => &mut all,
        };
        self.flush(net)?;
        for index in indices {
            let Some(range) = split.range(index) else {
                continue;
            };
            let sub = DataSub::Fragment(Fragment {
                meta,
                total_len: split.total_len() as u32,
                frag_size: split.frag_size() as u32,
                index,
                chunk: &payload[range],
            });
            self.begin(net, writer, only);
            if let Some(chunk) = self.batch.push_head(&sub, net.limits.max_datagram) {
                net.send_parts(self.batch.bytes(), chunk, self.addr)?;
            }
        }
        Ok(())
    }
}

/// All destinations of one producer.
#[derive(Debug, Default)]
pub(crate) struct Outbox {
    pub(crate) dests: Vec<Dest>,
    /// Serialization scratch, reused.
    pub(crate) payload: Vec<u8>,
}

impl Outbox {
    /// Rebuilds the destinations from the matched consumers, sending pending batches first.
    pub(crate) fn set_matched<'a>(
        &mut self,
        net: &Net,
        matched: impl Iterator<Item = &'a EndpointInfo>,
    ) {
        for dest in &mut self.dests {
            let _ = dest.flush(net);
        }
        let mut dests: Vec<Dest> = Vec::new();
        for consumer in matched {
            let addr = SocketAddrV4::from(consumer.locator);
            let participant = consumer.guid.participant;
            let index = match dests.iter().position(|d| {
                d.addr == addr && d.participant == participant && d.readers.len() < GROUP
            }) {
                Some(index) => index,
                None => {
                    dests.push(Dest::new(addr, participant));
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

    /// Sends one sample to every destination, whole or in fragments; returns the last send
    /// error if every destination failed.
    pub(crate) fn send(
        &mut self,
        net: &Net,
        writer: u32,
        meta: SampleMeta,
        payload: &[u8],
        now: Option<Instant>,
        batching: Batching,
    ) -> Result<(), WriteError> {
        let mut last_error = None;
        let mut delivered = 0usize;
        let whole = payload.len() <= whole_limit(net);
        for dest in &mut self.dests {
            let result = if whole {
                let sub = DataSub::Sample(Sample { meta, payload });
                match (batching, now) {
                    (Batching::On { max_bytes, .. }, Some(now)) => {
                        dest.batch(net, writer, &sub, now, max_bytes)
                    }
                    _ => dest.send_sample(net, writer, None, &sub),
                }
            } else {
                dest.send_fragments(net, writer, None, meta, payload, None)
            };
            match result {
                Ok(()) => delivered += 1,
                Err(err) => {
                    tracing::debug!(to = %dest.addr, %err, "data send failed");
                    last_error = Some(err);
                }
            }
        }
        match last_error {
            Some(err) if delivered == 0 => Err(err.into()),
            _ => Ok(()),
        }
    }

    /// Sends every batch that is due; returns when the next one is.
    pub(crate) fn flush_due(
        &mut self,
        net: &Net,
        now: Instant,
        batching: Batching,
    ) -> Option<Instant> {
        let mut next: Option<Instant> = None;
        for dest in &mut self.dests {
            match dest.due(batching) {
                Some(at) if at <= now => {
                    let _ = dest.flush(net);
                }
                Some(at) => next = Some(next.map_or(at, |n| n.min(at))),
                None => {}
            }
        }
        next
    }

    /// Sends every pending batch now.
    pub(crate) fn flush_all(&mut self, net: &Net) -> std::io::Result<()> {
        let mut result = Ok(());
        for dest in &mut self.dests {
            if let Err(err) = dest.flush(net) {
                result = Err(err);
            }
        }
        result
    }

    /// When the earliest pending batch is due.
    pub(crate) fn next_due(&self, batching: Batching) -> Option<Instant> {
        self.dests.iter().filter_map(|d| d.due(batching)).min()
    }
}

/// A sample as written: its metadata and encoded bytes. Cheap to clone (shared bytes).
#[derive(Clone, Debug)]
pub(crate) struct Kept {
    pub(crate) meta: SampleMeta,
    pub(crate) bytes: Arc<Vec<u8>>,
}

/// Buffers for kept samples, reused once nothing holds them any more (the history let go of
/// the sample), so a reliable producer allocates nothing per sample in a steady state.
#[derive(Debug, Default)]
pub(crate) struct KeptPool {
    buffers: Vec<Arc<Vec<u8>>>,
    /// Where the search for a free buffer starts: buffers come free in the order they were
    /// taken (the history is first in, first out), so the next one is usually free.
    next: usize,
    /// The largest sample kept so far: a new buffer starts with this capacity, so filling it
    /// does not grow it again.
    largest: usize,
}

impl KeptPool {
    /// At most this many buffers are kept for reuse (a history of `depth` samples needs
    /// `depth + 1`).
    pub(crate) fn new(capacity: usize) -> Self {
        KeptPool {
            buffers: Vec::with_capacity(capacity.min(4096)),
            next: 0,
            largest: 0,
        }
    }

    /// A buffer holding a copy of `payload`.
    pub(crate) fn copy(&mut self, payload: &[u8]) -> Arc<Vec<u8>> {
        let filled = self.fill(|buffer| {
            buffer.extend_from_slice(payload);
            Ok::<(), std::convert::Infallible>(())
        });
        match filled {
            Ok(buffer) => buffer,
            Err(never) => match never {},
        }
    }

    /// A buffer filled by `fill` (given it empty), such as a sample encoded straight into it.
    pub(crate) fn fill<E>(
        &mut self,
        fill: impl FnOnce(&mut Vec<u8>) -> Result<(), E>,
    ) -> Result<Arc<Vec<u8>>, E> {
        let len = self.buffers.len();
        for step in 0..len {
            let index = (self.next + step) % len;
            if let Some(buffer) = Arc::get_mut(&mut self.buffers[index]) {
                buffer.clear();
                fill(buffer)?;
                self.largest = self.largest.max(buffer.len());
                self.next = (index + 1) % len;
                return Ok(self.buffers[index].clone());
            }
        }
        let mut buffer = Vec::with_capacity(self.largest);
        fill(&mut buffer)?;
        self.largest = self.largest.max(buffer.len());
        let buffer = Arc::new(buffer);
        if self.buffers.len() < self.buffers.capacity() {
            self.buffers.push(buffer.clone());
        }
        Ok(buffer)
    }
}

//! A producer's outgoing side: its destinations (one per consuming participant), the batch
//! being filled for each, and the cutting of large samples into fragments.

use std::net::SocketAddrV4;
use std::time::Instant;

use bytes::Bytes;
use ndds_core::fragment::Split;
use ndds_core::wire::data::{
    Addressing, FRAGMENT_OVERHEAD, Fragment, SAMPLE_OVERHEAD, Sample, prefix_overhead,
};
use ndds_core::wire::{DataSub, DataWriter, EndpointInfo, SampleMeta};

use crate::error::WriteError;
use crate::plane::Net;
use crate::qos::Batching;

/// One consuming participant: where its samples go, and the batch being filled for it.
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

    /// Starts a datagram to this destination in its batch buffer.
    fn begin(&mut self, net: &Net, writer: u32) {
        let to = Addressing {
            reader_participant: self.participant,
            writer,
            readers: &self.readers,
        };
        self.batch.begin(net.domain, net.participant, &to);
    }

    /// Largest whole sample this destination takes in one datagram.
    pub(crate) fn whole_limit(&self, net: &Net) -> usize {
        net.limits
            .max_datagram
            .saturating_sub(prefix_overhead(self.readers.len()) + SAMPLE_OVERHEAD)
    }

    /// Fragment size for this destination.
    pub(crate) fn frag_size(&self, net: &Net) -> usize {
        net.limits
            .max_datagram
            .saturating_sub(prefix_overhead(self.readers.len()) + FRAGMENT_OVERHEAD)
    }

    /// Sends one submessage now, in a datagram of its own (after any pending batch).
    pub(crate) fn send_now(
        &mut self,
        net: &Net,
        writer: u32,
        sub: &DataSub<'_>,
    ) -> std::io::Result<()> {
        self.flush(net)?;
        let to = self.addr;
        self.begin(net, writer);
        self.batch.push(sub, net.limits.max_datagram);
        net.send(self.batch.bytes(), to)
    }

    /// Adds a submessage to the batch; returns when the batch must leave at the latest.
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
            self.begin(net, writer);
            self.opened = Some(now);
        }
        if !self.batch.push(sub, limit) {
            self.flush(net)?;
            self.begin(net, writer);
            self.opened = Some(now);
            if !self.batch.push(sub, limit) {
                // Larger than a batch but fits a datagram: it leaves alone.
                return self.send_now(net, writer, sub);
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
            let index = match dests
                .iter()
                .position(|d| d.addr == addr && d.participant == participant)
            {
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

    /// Sends one sample to every destination, whole or in fragments; returns the last send
    /// error if every destination failed.
    pub(crate) fn send(
        &mut self,
        net: &Net,
        writer: u32,
        meta: SampleMeta,
        payload: &[u8],
        now: Instant,
        batching: Batching,
    ) -> Result<(), WriteError> {
        let mut last_error = None;
        let mut delivered = 0usize;
        for dest in &mut self.dests {
            let result = if payload.len() <= dest.whole_limit(net) {
                let sub = DataSub::Sample(Sample { meta, payload });
                match batching {
                    Batching::Off => dest.send_now(net, writer, &sub),
                    Batching::On { max_bytes, .. } => dest.batch(net, writer, &sub, now, max_bytes),
                }
            } else {
                send_fragments(dest, net, writer, meta, payload, None)
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

/// Sends the pieces of a large sample to one destination (all pieces, or only those listed).
pub(crate) fn send_fragments(
    dest: &mut Dest,
    net: &Net,
    writer: u32,
    meta: SampleMeta,
    payload: &[u8],
    only: Option<&mut dyn Iterator<Item = u32>>,
) -> std::io::Result<()> {
    let split = Split::new(payload.len(), dest.frag_size(net))
        .map_err(|err| std::io::Error::other(err.to_string()))?;
    let send_piece = |dest: &mut Dest, index: u32| -> std::io::Result<()> {
        let Some(range) = split.range(index) else {
            return Ok(());
        };
        let sub = DataSub::Fragment(Fragment {
            meta,
            total_len: split.total_len() as u32,
            frag_size: split.frag_size() as u32,
            index,
            chunk: &payload[range],
        });
        dest.send_now(net, writer, &sub)
    };
    match only {
        Some(indices) => {
            for index in indices {
                send_piece(dest, index)?;
            }
        }
        None => {
            for index in 0..split.count() {
                send_piece(dest, index)?;
            }
        }
    }
    Ok(())
}

/// A sample kept so readers can ask for its missing pieces.
#[derive(Clone, Debug)]
pub(crate) struct Kept {
    pub(crate) meta: SampleMeta,
    pub(crate) bytes: Bytes,
}

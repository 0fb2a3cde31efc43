//! One producer's sending end: sequence numbers, destinations and batches, fragments, the
//! reliable writer's history and window, the newest sample kept for late joiners and for
//! piece requests, and who it believes (feedback only from matched consumers).

use std::collections::VecDeque;
use std::net::SocketAddrV4;
use std::sync::Arc;
use std::time::Instant;

use crate::admission::{Admission, AdmissionConfig};
use crate::reliability::{ReliableWriter, WriterConfig, WriterOutput};
use crate::wire::data::{AddressToken, FLAG_RELIABLE, Gap, Heartbeat, Sample};
use crate::wire::feedback::bit;
use crate::wire::{DataSub, FeedbackSub, Guid, SampleMeta};

use super::Event;
use super::outbox::{BatchConfig, MatchedConsumer, Outbox, Tx, UNVALIDATED_FACTOR, split};

/// What became of one feedback submessage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FeedbackVerdict {
    /// From a reader that is not matched here, or not at its discovered locator (counted by
    /// the admission).
    NotBelieved,
    /// Believed and acted on.
    Acted,
    /// From the right address but without its address token: acknowledgements ignored,
    /// pieces sent only within the allowance; `withheld` pieces were asked for beyond it.
    Unvalidated {
        /// Pieces not sent.
        withheld: usize,
    },
}

/// A fragmented sample of at most this many pieces is resent whole when a reader asks for it
/// again; a larger one is repaired piece by piece.
const FULL_RESEND_PIECES: u32 = 16;

/// How a producer is declared to the core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProducerSpec {
    /// Strength carried by every sample.
    pub strength: i32,
    /// Persistence carried by every sample, in microseconds.
    pub persistence_us: u64,
    /// `Some` for a reliable producer.
    pub reliable: Option<WriterConfig>,
    /// A reliable write into a full window is refused ([`WriteRefused::WindowFull`]) so the
    /// caller can wait; false: it goes anyway, pushing the oldest sample out of the history.
    pub refuse_when_full: bool,
    /// `Some` to pack samples into batches.
    pub batching: Option<BatchConfig>,
    /// The newest this many samples are kept for consumers that match later (a best-effort
    /// producer keeps only the newest, whatever the number).
    pub late_joiners: usize,
}

/// Why the core did not take a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum WriteRefused {
    /// No producer with this entity number.
    #[error("no producer {0}")]
    UnknownProducer(u32),
    /// The encoded sample is larger than the participant accepts.
    #[error("sample of {size} bytes exceeds the maximum of {max}")]
    TooLarge {
        /// Its size.
        size: usize,
        /// The limit.
        max: usize,
    },
    /// A reliable producer's window is full (see [`ProducerSpec::refuse_when_full`]).
    #[error("the reliable window is full ({unacknowledged} samples unacknowledged)")]
    WindowFull {
        /// Samples in the history.
        unacknowledged: usize,
    },
}

/// A sample as written: its metadata and encoded bytes. Cheap to clone (shared bytes).
#[derive(Clone, Debug)]
pub(crate) struct Kept {
    pub(crate) meta: SampleMeta,
    pub(crate) bytes: Arc<Vec<u8>>,
}

/// The reliable side of a reliable producer.
#[derive(Debug)]
struct Reliable {
    writer: ReliableWriter<Guid, Kept>,
    /// What the writer asked to send, drained into this reused buffer.
    outputs: Vec<WriterOutput<Guid, Kept>>,
}

#[derive(Debug)]
pub(crate) struct ProducerCore {
    pub(crate) entity: u32,
    spec: ProducerSpec,
    outbox: Outbox,
    seq: u64,
    /// The newest sample, when fragmented (for best-effort readers that ask for missing
    /// pieces) or kept for late joiners.
    kept: Option<Kept>,
    reliable: Option<Reliable>,
    /// The matched consumers: feedback from anyone else is not believed.
    believed: Admission<()>,
    pub(crate) written: u64,
    /// Cached next timer.
    pub(crate) due: Option<Instant>,
}

impl ProducerCore {
    pub(crate) fn new(entity: u32, spec: ProducerSpec) -> Self {
        ProducerCore {
            entity,
            spec,
            outbox: Outbox::default(),
            seq: 0,
            kept: None,
            reliable: spec.reliable.map(|config| Reliable {
                writer: ReliableWriter::new(config),
                outputs: Vec::new(),
            }),
            // Feedback is never held: a consumer acknowledges only what it was sent.
            believed: Admission::new(AdmissionConfig {
                max_held: 0,
                ..AdmissionConfig::default()
            }),
            written: 0,
            due: None,
        }
    }

    pub(crate) fn window_open(&self) -> bool {
        self.reliable
            .as_ref()
            .is_none_or(|r| r.writer.window_open())
    }

    pub(crate) fn unacknowledged(&self) -> usize {
        self.reliable.as_ref().map_or(0, |r| r.writer.history_len())
    }

    pub(crate) fn believed_stats(&self) -> crate::admission::AdmissionStats {
        self.believed.stats()
    }

    fn flags(&self) -> u8 {
        if self.reliable.is_some() {
            FLAG_RELIABLE
        } else {
            0
        }
    }

    /// The participants of the endpoints it is matched with (or still believes a moment).
    pub(crate) fn peers(&self) -> impl Iterator<Item = u64> + '_ {
        self.believed.senders().map(|guid| guid.participant)
    }

    /// Rebuilds the destinations from the matched consumers; a reliable producer starts
    /// serving the reliable consumers that appeared and forgets those that left.
    pub(crate) fn set_matched(
        &mut self,
        tx: &mut Tx<'_>,
        events: &mut VecDeque<Event>,
        now: Instant,
        consumers: &[MatchedConsumer],
    ) {
        // The consumers that join now: not believed before this change.
        let joined: Vec<Guid> = consumers
            .iter()
            .map(|c| c.guid)
            .filter(|guid| !self.believed.is_matched(guid))
            .collect();
        self.believed
            .set_matched(now, consumers.iter().map(|c| (c.guid, c.locator)));
        self.outbox.set_matched(tx, consumers);
        match &mut self.reliable {
            None => {
                if self.spec.late_joiners > 0
                    && let Some(latest) = self.kept.clone()
                {
                    for reader in joined {
                        self.outbox
                            .send_to(tx, self.entity, reader, latest.meta, &latest.bytes);
                    }
                }
            }
            Some(reliable) => {
                let was_open = reliable.writer.window_open();
                let gone: Vec<Guid> = reliable
                    .writer
                    .readers()
                    .filter(|reader| !consumers.iter().any(|c| c.reliable && c.guid == *reader))
                    .collect();
                for reader in gone {
                    reliable.writer.remove_reader(reader);
                }
                for consumer in consumers.iter().filter(|c| c.reliable) {
                    reliable.writer.add_reader(now, consumer.guid);
                }
                if !was_open && reliable.writer.window_open() {
                    events.push_back(Event::WindowOpen {
                        producer: self.entity,
                    });
                }
                self.drain(tx);
            }
        }
        self.reschedule();
    }

    /// Takes one encoded sample; returns its sequence number.
    pub(crate) fn write(
        &mut self,
        tx: &mut Tx<'_>,
        now: Instant,
        timestamp_ns: u64,
        max_sample: usize,
        payload: &Arc<Vec<u8>>,
    ) -> Result<u64, WriteRefused> {
        let size = payload.len();
        if size > max_sample {
            return Err(WriteRefused::TooLarge {
                size,
                max: max_sample,
            });
        }
        if let Some(reliable) = &self.reliable
            && self.spec.refuse_when_full
            && !reliable.writer.window_open()
        {
            return Err(WriteRefused::WindowFull {
                unacknowledged: reliable.writer.history_len(),
            });
        }
        self.seq += 1;
        let meta = SampleMeta {
            seq: self.seq,
            timestamp_ns,
            strength: self.spec.strength,
            persistence_us: self.spec.persistence_us,
            flags: self.flags(),
        };
        let fragmented = size > tx.whole_limit();
        // The newest sample of a best-effort producer that keeps it for late joiners.
        let latest = self.reliable.is_none() && self.spec.late_joiners > 0;
        if let Some(reliable) = &mut self.reliable {
            // Recorded before sending, so an acknowledgement racing the send finds it.
            let kept = Kept {
                meta,
                bytes: Arc::clone(payload),
            };
            let _ = reliable.writer.write(now, meta.seq, kept, size);
        }
        self.outbox
            .send(tx, self.entity, meta, payload, now, self.spec.batching);
        if fragmented || latest {
            self.kept = Some(Kept {
                meta,
                bytes: Arc::clone(payload),
            });
        }
        self.written += 1;
        self.drain(tx);
        self.reschedule();
        Ok(meta.seq)
    }

    /// Queues every sample waiting in a batch.
    pub(crate) fn flush(&mut self, tx: &mut Tx<'_>) {
        self.outbox.flush_all(tx);
        self.reschedule();
    }

    /// Acknowledgements and repair requests from reader `reader`, sent from `from` in a
    /// datagram that echoed `token` and brought `credit` bytes (counted once per datagram).
    ///
    /// Feedback is acted on in full only when it comes from the reader's discovered locator
    /// and echoes that destination's address token, proof that its sender receives what is
    /// sent there. Feedback from the right address with another token (a host forging the
    /// reader's address, which never sees the token) moves nothing: its acknowledgements are
    /// ignored, and the pieces it asks for are sent only within [`UNVALIDATED_FACTOR`] times
    /// the bytes such feedback brought.
    pub(crate) fn on_feedback(
        &mut self,
        tx: &mut Tx<'_>,
        events: &mut VecDeque<Event>,
        now: Instant,
        reader: Guid,
        (from, token, credit): (SocketAddrV4, AddressToken, usize),
        sub: &FeedbackSub<'_>,
    ) -> FeedbackVerdict {
        if !self.believed.admit(&reader, from) {
            return FeedbackVerdict::NotBelieved;
        }
        let Some(dest) = self.outbox.dest_of(reader) else {
            return FeedbackVerdict::NotBelieved;
        };
        let validated = token == dest.token;
        if !validated {
            dest.allowance = dest
                .allowance
                .saturating_add(credit.saturating_mul(UNVALIDATED_FACTOR));
        }
        let mut withheld = 0;
        match sub {
            FeedbackSub::AckNack(ack) => {
                if validated && let Some(reliable) = &mut self.reliable {
                    let was_open = reliable.writer.window_open();
                    reliable
                        .writer
                        .handle_acknack(now, reader, ack.acked, ack.missing);
                    if !was_open && reliable.writer.window_open() {
                        events.push_back(Event::WindowOpen {
                            producer: self.entity,
                        });
                    }
                    self.drain(tx);
                }
            }
            FeedbackSub::NackFrag(nack) => {
                // The history of a reliable producer, else the newest fragmented sample.
                let kept = self
                    .reliable
                    .as_ref()
                    .and_then(|r| r.writer.sample(nack.seq))
                    .or(self.kept.as_ref())
                    .filter(|k| k.meta.seq == nack.seq)
                    .cloned();
                if let Some(kept) = kept
                    && let Some(dest) = self.outbox.dest_of(reader)
                {
                    let asked = (0..nack.missing.len() * 8)
                        .filter(|i| bit(nack.missing, *i))
                        .filter_map(|i| nack.base.checked_add(u32::try_from(i).ok()?));
                    // Unvalidated: only as many pieces as the allowance covers, each counted
                    // as a whole datagram.
                    let limit = if validated {
                        usize::MAX
                    } else {
                        dest.allowance / tx.max_datagram.max(1)
                    };
                    let mut missing = asked.take(limit);
                    let sent = dest.send_fragments(
                        tx,
                        self.entity,
                        Some(reader.entity),
                        kept.meta,
                        &kept.bytes,
                        Some(&mut missing),
                    );
                    if !validated {
                        dest.allowance = dest.allowance.saturating_sub(sent);
                        let wanted = nack.missing.iter().map(|b| b.count_ones() as usize).sum();
                        withheld = usize::saturating_sub(wanted, limit);
                    }
                }
            }
        }
        self.reschedule();
        if validated {
            FeedbackVerdict::Acted
        } else {
            FeedbackVerdict::Unvalidated { withheld }
        }
    }

    /// Runs the due timers: batch flushes, heartbeats, repairs, reader liveness.
    pub(crate) fn handle_timeout(
        &mut self,
        tx: &mut Tx<'_>,
        events: &mut VecDeque<Event>,
        now: Instant,
    ) {
        self.outbox.flush_due(tx, now, self.spec.batching);
        if self.believed.poll_timeout().is_some_and(|due| due <= now) {
            // Consumers that left stop being believed once their grace is over.
            self.believed.handle_timeout(now);
        }
        if let Some(reliable) = &mut self.reliable
            && reliable.writer.poll_timeout().is_some_and(|due| due <= now)
        {
            let was_open = reliable.writer.window_open();
            reliable.writer.handle_timeout(now);
            while let Some(reader) = reliable.writer.poll_silenced() {
                events.push_back(Event::ReaderSilenced {
                    producer: self.entity,
                    reader,
                });
            }
            if !was_open && reliable.writer.window_open() {
                events.push_back(Event::WindowOpen {
                    producer: self.entity,
                });
            }
            self.drain(tx);
        }
        self.reschedule();
    }

    fn reschedule(&mut self) {
        self.due = self
            .outbox
            .next_due(self.spec.batching)
            .into_iter()
            .chain(self.reliable.as_ref().and_then(|r| r.writer.poll_timeout()))
            .chain(self.believed.poll_timeout())
            .min();
    }

    /// Queues what the reliable writer asked for: per reader, its gaps, resends and
    /// heartbeat, in datagrams addressed to that reader only.
    fn drain(&mut self, tx: &mut Tx<'_>) {
        let ProducerCore {
            outbox,
            reliable,
            entity,
            ..
        } = self;
        let Some(reliable) = reliable else {
            return;
        };
        reliable.outputs.clear();
        while let Some(output) = reliable.writer.poll_output() {
            reliable.outputs.push(output);
        }
        let whole = tx.whole_limit();
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
                    && sample.bytes.len() > whole
                {
                    let count = split(tx.max_datagram, sample.bytes.len()).map_or(1, |s| s.count());
                    let last = count.saturating_sub(1);
                    let mut only_last = std::iter::once(last);
                    let pieces: Option<&mut dyn Iterator<Item = u32>> =
                        (count > FULL_RESEND_PIECES).then_some(&mut only_last);
                    dest.send_fragments(
                        tx,
                        *entity,
                        Some(reader.entity),
                        sample.meta,
                        &sample.bytes,
                        pieces,
                    );
                }
            }
            let subs = group.iter().filter_map(|output| match output {
                WriterOutput::Resend { sample, .. } => (sample.bytes.len() <= whole).then(|| {
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
            dest.send_now(tx, *entity, Some(reader.entity), subs);
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

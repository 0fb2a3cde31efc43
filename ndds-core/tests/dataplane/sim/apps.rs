//! The applications around the simulated cores: producers that write at a pace (and may
//! wait for the window), consumers that take what they are handed at once, slowly or never.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use ndds_core::arbitration::{Notification, SampleStatus};
use ndds_core::participant::{RawSample, WriteRefused};
use ndds_core::wire::Guid;

use super::check::{check_payload, tag_of};

/// How a consumer's application takes the samples it is handed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum App {
    /// Takes each sample at once.
    Eager,
    /// Takes up to `batch` samples every `every`.
    Slow {
        /// Period.
        every: Duration,
        /// Samples per period.
        batch: usize,
    },
    /// Never takes anything.
    Never,
}

/// A sample the application took.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Got {
    /// Virtual time the core handed it out.
    pub delivered: Duration,
    /// Virtual time the application took it.
    pub taken: Duration,
    /// Its producer.
    pub writer: Guid,
    /// The producer's seq (from the sample info).
    pub seq: u64,
    /// Fresh or a takeover.
    pub status: SampleStatus,
    /// Payload bytes.
    pub len: usize,
    /// The payload is intact and carries the seq and writer tag of the info.
    pub intact: bool,
}

/// One consumer's application and what it saw.
#[derive(Debug)]
pub struct ConsumerLog {
    /// How it takes samples.
    pub app: App,
    /// True for a reliable consumer.
    pub reliable: bool,
    /// Every sample it took, in order.
    pub got: Vec<Got>,
    /// Every notification, with its virtual time.
    pub notifications: Vec<(Duration, Notification)>,
    /// Handed out, not taken yet.
    pub(super) pending: VecDeque<Got>,
    /// The most samples ever handed out and not taken.
    pub max_pending: usize,
    pub(super) next_take: Instant,
}

impl ConsumerLog {
    /// The seqs taken from `writer`, in order.
    pub fn seqs_from(&self, writer: Guid) -> Vec<u64> {
        self.got
            .iter()
            .filter(|g| g.writer == writer)
            .map(|g| g.seq)
            .collect()
    }

    /// Every `SamplesLost` range reported, in order.
    pub fn lost(&self) -> Vec<(Guid, u64, u64)> {
        self.notifications
            .iter()
            .filter_map(|(_, n)| match n {
                Notification::SamplesLost { writer, from, to } => Some((*writer, *from, *to)),
                _ => None,
            })
            .collect()
    }

    /// The notifications other than `OldData` (duplicates), with their times.
    pub fn notable(&self) -> Vec<(Duration, Notification)> {
        self.notifications
            .iter()
            .filter(|(_, n)| !matches!(n, Notification::OldData { .. }))
            .cloned()
            .collect()
    }
}

/// A producing application: writes `total` samples, one every `interval` (zero: as fast as
/// allowed), sizes taken in turn from `sizes`.
#[derive(Clone, Debug)]
pub struct WriterApp {
    /// Its node.
    pub node: usize,
    /// Its producer's entity.
    pub entity: u32,
    /// Samples to write.
    pub total: u64,
    /// Time between writes.
    pub interval: Duration,
    /// Payload sizes, in turn.
    pub sizes: Vec<usize>,
    /// Wait while the producer's window is closed (else write anyway).
    pub respect_window: bool,
    /// When it writes first.
    pub start: Duration,
    /// Virtual time each sample was written, by seq - 1.
    pub written_at: Vec<Duration>,
    /// Writes the core refused.
    pub refused: Vec<WriteRefused>,
    /// Virtual time spent waiting for the window.
    pub blocked_for: Duration,
    /// Each period it waited: (from, to).
    pub blocked: Vec<(Duration, Duration)>,
    /// False: it pauses (it writes nothing until set again).
    pub active: bool,
    pub(super) next_write: Option<Instant>,
    pub(super) blocked_since: Option<Instant>,
}

impl WriterApp {
    /// `total` samples of `size` bytes from producer `entity` of `node`, one every
    /// `interval`, waiting for the window.
    pub fn new(node: usize, entity: u32, total: u64, interval: Duration, size: usize) -> Self {
        WriterApp {
            node,
            entity,
            total,
            interval,
            sizes: vec![size],
            respect_window: true,
            start: Duration::ZERO,
            written_at: Vec::new(),
            refused: Vec::new(),
            blocked_for: Duration::ZERO,
            blocked: Vec::new(),
            active: true,
            next_write: None,
            blocked_since: None,
        }
    }

    /// Samples written so far.
    pub fn written(&self) -> u64 {
        self.written_at.len() as u64
    }

    /// True when it wrote everything.
    pub fn finished(&self) -> bool {
        self.written() >= self.total
    }
}

pub(super) fn describe(elapsed: Duration, sample: &RawSample) -> Got {
    let info = sample.info;
    let intact = check_payload(&sample.payload) == Some((tag_of(info.writer), info.seq));
    Got {
        delivered: elapsed,
        taken: elapsed,
        writer: info.writer,
        seq: info.seq,
        status: info.status,
        len: sample.payload.len(),
        intact,
    }
}

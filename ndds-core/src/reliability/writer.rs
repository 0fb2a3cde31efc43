//! The writer side of a reliable stream: one per reliable producer, serving all its reliable
//! readers. It keeps the history, answers AckNacks with resends and gaps, heartbeats, and
//! decides the flow-control window. It never sends the original samples: the driver does
//! that, and tells the writer with [`ReliableWriter::write`].
//!
//! # Call order
//! - Discovery: [`ReliableWriter::add_reader`] when a reliable reader matches,
//!   [`ReliableWriter::remove_reader`] when it goes away.
//! - Writing: wait (with a timeout) while [`ReliableWriter::window_open`] is false; then
//!   [`ReliableWriter::write`] and send the sample to every matched reader.
//! - Feedback: [`ReliableWriter::handle_acknack`] for each AckNack received.
//! - Time: [`ReliableWriter::handle_timeout`] once [`ReliableWriter::poll_timeout`] is reached.
//! - After any of these: drain [`ReliableWriter::poll_output`] and re-arm the timer.
//!
//! See the [module docs](super) for the protocol rules.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Debug;
use std::hash::Hash;
use std::time::{Duration, Instant};

use super::bitmap;
use super::history::History;
use super::ranges::RangeSet;

/// Most disjoint gap ranges queued for one reader; beyond that the newest are dropped (the
/// reader asks again, or learns them from the next heartbeat).
const MAX_PENDING_GAPS: usize = 64;

/// Shortest heartbeat period accepted; shorter configured periods are raised to it.
const MIN_PERIOD: Duration = Duration::from_millis(1);
/// Shortest first heartbeat period while the window is closed.
const MIN_BLOCKED_PERIOD: Duration = Duration::from_micros(100);

/// Settings of one reliable writer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriterConfig {
    /// Most samples in the history, which is also the flow-control window (default 256; at
    /// least 1).
    pub depth: usize,
    /// Byte budget of the history, not counting its newest sample (default 64 MiB).
    pub max_bytes: usize,
    /// Heartbeat period towards readers that have not acknowledged everything (default 20 ms;
    /// at least 1 ms).
    pub heartbeat_period: Duration,
    /// Heartbeat period towards all readers when none is behind (default 1 s; at least 1 ms).
    pub idle_heartbeat_period: Duration,
    /// First heartbeat period while the window is closed (default 250 µs; at least 100 µs).
    /// The writer then waits for acknowledgements, and a lost heartbeat or a lost last sample
    /// would otherwise hold it up for a whole `heartbeat_period`; the period doubles while
    /// no acknowledgement moves the window, up to `heartbeat_period`.
    pub blocked_heartbeat_period: Duration,
    /// A reader that owes acknowledgements and sends none for this long is *silent*: it
    /// stops holding samples in the history and the window (so one stopped reader does not
    /// stall the writer), gets only the idle heartbeats, and joins again with its next
    /// AckNack, learning what it missed as lost. `None`: readers are never silenced
    /// (default 1 s).
    pub reader_liveness: Option<Duration>,
    /// The newest this many samples are kept for readers that match later (DDS's
    /// TRANSIENT_LOCAL, ROS 2's latched topics): a new reader is owed them first, in order,
    /// before what is written after its match. Kept apart from the history until a reader
    /// joins (so they never close the window by themselves); then they are in the history
    /// until that reader has them (default 0: a new reader is owed only what follows its
    /// match).
    pub late_joiners: usize,
}

impl Default for WriterConfig {
    fn default() -> Self {
        WriterConfig {
            depth: 256,
            max_bytes: 64 << 20,
            heartbeat_period: Duration::from_millis(20),
            idle_heartbeat_period: Duration::from_secs(1),
            blocked_heartbeat_period: Duration::from_micros(250),
            reader_liveness: Some(Duration::from_secs(1)),
            late_joiners: 0,
        }
    }
}

/// What the writer asks its driver to send; every output is for one reader.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WriterOutput<K, S> {
    /// Send this sample again to `reader`.
    Resend {
        /// The reader that asked.
        reader: K,
        /// Its sequence number.
        seq: u64,
        /// The sample, from the history.
        sample: S,
    },
    /// Tell `reader` that seqs `from..to` will never come.
    Gap {
        /// The reader.
        reader: K,
        /// First missing seq.
        from: u64,
        /// One past the last missing seq.
        to: u64,
    },
    /// Send a heartbeat to `reader`: it can have `first..=last` repaired; seqs below `first`
    /// are not coming to it.
    Heartbeat {
        /// The reader.
        reader: K,
        /// First seq the reader can still get.
        first: u64,
        /// Newest seq written.
        last: u64,
    },
}

/// Counters of one writer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WriterStats {
    /// Samples accepted by [`ReliableWriter::write`].
    pub written: u64,
    /// Writes refused because their seq was not after the last one.
    pub stale_writes: u64,
    /// Resends emitted.
    pub resends: u64,
    /// Gap messages emitted.
    pub gaps: u64,
    /// Heartbeats emitted (one per reader addressed).
    pub heartbeats: u64,
    /// Writes that closed the flow-control window.
    pub window_full: u64,
    /// Samples evicted from the history while a reader still needed them.
    pub evicted_unacked: u64,
    /// AckNacks from readers that are not (or no longer) matched.
    pub unknown_reader: u64,
    /// AckNacks acknowledging or naming seqs never written (clamped or ignored).
    pub invalid_feedback: u64,
    /// Readers found silent (see [`WriterConfig::reader_liveness`]).
    pub silenced: u64,
}

/// Why a write was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum WriteError {
    /// Sequence numbers must increase.
    #[error("sequence number {seq} is not after the last one written ({last})")]
    NotAfterLast {
        /// The refused seq.
        seq: u64,
        /// The last seq written.
        last: u64,
    },
}

/// What the writer knows of one reader.
#[derive(Clone, Debug)]
struct ReaderState {
    /// Every seq below this is settled for the reader (initially the next seq to write).
    acked: u64,
    /// When its last AckNack arrived (`None`: never heard from).
    heard: Option<Instant>,
    /// Since when it owes an answer: its last AckNack, or the write that put it behind, or
    /// its match, whichever came last.
    owes_since: Instant,
    /// Silent: it holds nothing in the history until it answers again.
    silent: bool,
    /// A heartbeat is due to it.
    heartbeat: bool,
    /// Seqs to resend.
    resend: BTreeSet<u64>,
    /// Ranges to announce as gaps.
    gaps: RangeSet,
}

impl ReaderState {
    fn new(acked: u64, now: Instant) -> Self {
        ReaderState {
            acked,
            heard: None,
            owes_since: now,
            silent: false,
            heartbeat: true,
            resend: BTreeSet::new(),
            gaps: RangeSet::default(),
        }
    }

    /// Behind the newest write, or not yet heard from: heartbeats go to it every period.
    fn needy(&self, last: u64) -> bool {
        !self.silent && (self.acked <= last || self.heard.is_none())
    }

    fn queue_gap(&mut self, from: u64, to: u64) {
        self.gaps.insert(from, to);
        if self.gaps.len() > MAX_PENDING_GAPS {
            self.gaps.pop_last();
        }
    }
}

/// An ordered set of reader keys in a sorted vector: unlike a `BTreeSet`, it keeps its
/// allocation when emptied, so marking readers dirty write after write allocates nothing.
#[derive(Debug)]
struct KeySet<K>(Vec<K>);

impl<K> Default for KeySet<K> {
    fn default() -> Self {
        KeySet(Vec::new())
    }
}

impl<K: Ord + Copy> KeySet<K> {
    fn insert(&mut self, key: K) {
        if let Err(at) = self.0.binary_search(&key) {
            self.0.insert(at, key);
        }
    }

    fn remove(&mut self, key: &K) {
        if let Ok(at) = self.0.binary_search(key) {
            self.0.remove(at);
        }
    }

    fn first(&self) -> Option<&K> {
        self.0.first()
    }
}

/// A reliable writer: `K` names a reader, `S` is a stored sample (cheap to clone, e.g. an
/// `Arc`'d encoding).
#[derive(Debug)]
pub struct ReliableWriter<K, S> {
    config: WriterConfig,
    last: u64,
    history: History<S>,
    readers: BTreeMap<K, ReaderState>,
    /// Readers with queued output.
    dirty: KeySet<K>,
    period_due: Option<Instant>,
    idle_due: Option<Instant>,
    /// Samples and bytes written since the last heartbeat to the readers behind.
    since_heartbeat: (usize, usize),
    /// The heartbeat period while the window is closed: starts at
    /// `blocked_heartbeat_period`, doubles at each heartbeat that finds the window still
    /// closed, and starts again when an acknowledgement makes progress.
    blocked_period: Duration,
    /// Readers found silent, for the driver to report.
    silenced: Vec<K>,
    /// The newest `late_joiners` samples written, oldest first, with their sizes.
    kept: std::collections::VecDeque<(u64, S, usize)>,
    stats: WriterStats,
}

impl<K, S> ReliableWriter<K, S>
where
    K: Copy + Ord + Hash + Debug,
    S: Clone,
{
    /// A writer that has written nothing (its first seq will be 1).
    pub fn new(config: WriterConfig) -> Self {
        let config = WriterConfig {
            depth: config.depth.max(1),
            heartbeat_period: config.heartbeat_period.max(MIN_PERIOD),
            idle_heartbeat_period: config.idle_heartbeat_period.max(MIN_PERIOD),
            blocked_heartbeat_period: config
                .blocked_heartbeat_period
                .max(MIN_BLOCKED_PERIOD)
                .min(config.heartbeat_period.max(MIN_PERIOD)),
            ..config
        };
        ReliableWriter {
            config,
            last: 0,
            history: History::new(),
            readers: BTreeMap::new(),
            dirty: KeySet::default(),
            period_due: None,
            idle_due: None,
            since_heartbeat: (0, 0),
            blocked_period: config.blocked_heartbeat_period,
            silenced: Vec::new(),
            kept: std::collections::VecDeque::with_capacity(config.late_joiners.min(1024)),
            stats: WriterStats::default(),
        }
    }

    /// The settings in force (after clamping).
    pub fn config(&self) -> WriterConfig {
        self.config
    }

    /// Counters.
    pub fn stats(&self) -> WriterStats {
        self.stats
    }

    /// The newest seq written (0 before the first write).
    pub fn last_seq(&self) -> u64 {
        self.last
    }

    /// Samples in the history.
    pub fn history_len(&self) -> usize {
        self.history.len()
    }

    /// Bytes in the history.
    pub fn history_bytes(&self) -> usize {
        self.history.bytes()
    }

    /// Matched readers.
    pub fn readers(&self) -> impl Iterator<Item = K> + '_ {
        self.readers.keys().copied()
    }

    /// The seq below which everything is settled for `reader`, if matched.
    pub fn acked(&self, reader: K) -> Option<u64> {
        self.readers.get(&reader).map(|r| r.acked)
    }

    /// When `reader`'s last AckNack arrived (`None`: unknown or never heard from). A driver
    /// may drop readers silent for much longer than the heartbeat period.
    pub fn last_heard(&self, reader: K) -> Option<Instant> {
        self.readers.get(&reader).and_then(|r| r.heard)
    }

    /// A reliable reader matched. It is owed every sample written from now on (and, with
    /// [`WriterConfig::late_joiners`], the samples kept for late joiners), not the rest of
    /// the history; a heartbeat to it is queued at once. Returns false if it was already
    /// known (its state is kept).
    pub fn add_reader(&mut self, now: Instant, reader: K) -> bool {
        if self.readers.contains_key(&reader) {
            return false;
        }
        // The samples kept for late joiners go (back) into the history, which holds them
        // until this reader has them.
        for (seq, sample, bytes) in self.kept.iter().rev() {
            if self.history.first_seq().is_none_or(|first| *seq < first) {
                self.history.push_older(*seq, sample.clone(), *bytes);
            }
        }
        let next = self
            .kept
            .front()
            .map_or_else(|| self.last.saturating_add(1), |(seq, _, _)| *seq);
        self.readers.insert(reader, ReaderState::new(next, now));
        self.dirty.insert(reader);
        self.arm_period(now);
        if self.idle_due.is_none() {
            self.idle_due = now.checked_add(self.config.idle_heartbeat_period);
        }
        true
    }

    /// A reader went away: it no longer holds samples in the history or the window. Returns
    /// false if it was unknown.
    pub fn remove_reader(&mut self, reader: K) -> bool {
        let known = self.readers.remove(&reader).is_some();
        self.dirty.remove(&reader);
        if self.readers.is_empty() {
            self.period_due = None;
            self.idle_due = None;
        }
        self.evict();
        known
    }

    /// True while a write cannot evict a sample some reader still needs: the history holds
    /// fewer than `depth` samples and fewer than `max_bytes` bytes. The history only keeps
    /// samples some reader has not acknowledged, so the slowest reader closes the window.
    pub fn window_open(&self) -> bool {
        self.history.len() < self.config.depth && self.history.bytes() < self.config.max_bytes
    }

    /// Records a sample the driver sends to every matched reader. `seq` must exceed the last
    /// one; skipped seqs are announced as gaps. Written while the window is closed, it evicts
    /// the oldest samples, which become gaps for the readers still needing them.
    pub fn write(
        &mut self,
        now: Instant,
        seq: u64,
        sample: S,
        bytes: usize,
    ) -> Result<(), WriteError> {
        if seq <= self.last {
            self.stats.stale_writes += 1;
            return Err(WriteError::NotAfterLast {
                seq,
                last: self.last,
            });
        }
        let skipped_from = self.last.saturating_add(1);
        if seq > skipped_from {
            self.gap_to_readers(skipped_from, seq);
        }
        self.last = seq;
        self.stats.written += 1;
        if self.config.late_joiners > 0 {
            if self.kept.len() >= self.config.late_joiners {
                self.kept.pop_front();
            }
            self.kept.push_back((seq, sample.clone(), bytes));
        }
        if self.readers.is_empty() {
            return Ok(());
        }
        let was_open = self.window_open();
        for state in self.readers.values_mut() {
            if state.acked == seq {
                // It had everything: from now on it owes an acknowledgement.
                state.owes_since = now;
            }
        }
        self.history.push(seq, sample, bytes);
        self.evict();
        self.arm_period(now);
        self.since_heartbeat.0 += 1;
        self.since_heartbeat.1 = self.since_heartbeat.1.saturating_add(bytes);
        let closed_now = was_open && !self.window_open();
        if closed_now {
            self.stats.window_full += 1;
        }
        if closed_now || self.heartbeat_wanted() {
            self.heartbeat_needy(now);
        }
        Ok(())
    }

    /// An AckNack from `reader`: everything below `acked` is settled for it; the set bits of
    /// `missing` (bit `i` = `acked + i`) are seqs to repair. Seqs in the history are queued
    /// for resending (once, however often they are asked for before the driver drains the
    /// output); others are queued as gaps.
    pub fn handle_acknack(&mut self, now: Instant, reader: K, acked: u64, missing: &[u8]) {
        let last = self.last;
        let next = last.saturating_add(1);
        let Some(state) = self.readers.get_mut(&reader) else {
            self.stats.unknown_reader += 1;
            return;
        };
        state.heard = Some(now);
        state.owes_since = now;
        if std::mem::take(&mut state.silent) {
            // Back: it holds the history again from what it acknowledges (what was dropped
            // meanwhile reaches it as lost through the next heartbeat).
            state.heartbeat = true;
            self.dirty.insert(reader);
        }
        if acked > next {
            // Acknowledges seqs never written: settle what exists, ignore the bitmap.
            self.stats.invalid_feedback += 1;
            Self::advance(state, next);
            self.evict();
            return;
        }
        if acked > state.acked {
            self.blocked_period = self.config.blocked_heartbeat_period;
        }
        Self::advance(state, acked);
        let mut queued = false;
        for seq in bitmap::ones(missing).filter_map(|i| acked.checked_add(i as u64)) {
            if seq > last {
                self.stats.invalid_feedback += 1;
                break;
            }
            if seq < state.acked {
                continue;
            }
            if self.history.contains(seq) {
                state.resend.insert(seq);
            } else {
                state.queue_gap(seq, seq.saturating_add(1));
            }
            queued = true;
        }
        if queued {
            // A heartbeat after the repairs makes the reader report at once what they fixed.
            state.heartbeat = true;
            self.dirty.insert(reader);
        }
        self.evict();
    }

    /// Sends the heartbeats that are due at `now`, and silences readers that stopped
    /// answering (checked at each heartbeat period while someone is behind).
    pub fn handle_timeout(&mut self, now: Instant) {
        self.silence_quiet(now);
        if self.period_due.is_some_and(|due| due <= now) {
            self.period_due = None;
            self.heartbeat_needy(now);
        }
        if self.idle_due.is_some_and(|due| due <= now) {
            self.idle_due = None;
            for (&key, state) in &mut self.readers {
                state.heartbeat = true;
                self.dirty.insert(key);
            }
            if !self.readers.is_empty() {
                self.idle_due = now.checked_add(self.config.idle_heartbeat_period);
            }
        }
    }

    /// The next reader found silent since the last call (to report).
    pub fn poll_silenced(&mut self) -> Option<K> {
        self.silenced.pop()
    }

    /// Whether `reader` is silent now.
    pub fn is_silent(&self, reader: K) -> bool {
        self.readers.get(&reader).is_some_and(|r| r.silent)
    }

    /// Silences the readers behind that owed an answer for longer than the liveness.
    fn silence_quiet(&mut self, now: Instant) {
        let Some(liveness) = self.config.reader_liveness else {
            return;
        };
        let last = self.last;
        let mut any = false;
        for (&key, state) in &mut self.readers {
            if !state.silent
                && state.acked <= last
                && now.saturating_duration_since(state.owes_since) >= liveness
            {
                state.silent = true;
                self.stats.silenced += 1;
                self.silenced.push(key);
                any = true;
            }
        }
        if any {
            self.evict();
        }
    }

    /// When [`ReliableWriter::handle_timeout`] must next run.
    pub fn poll_timeout(&self) -> Option<Instant> {
        match (self.period_due, self.idle_due) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The sample `seq`, while the history holds it (for repairs finer than a whole resend,
    /// such as the missing pieces of a large sample).
    pub fn sample(&self, seq: u64) -> Option<&S> {
        self.history.get(seq)
    }

    /// The next output. For each reader: gaps first, then resends in seq order, then the
    /// heartbeat (computed now, so it carries the newest range).
    pub fn poll_output(&mut self) -> Option<WriterOutput<K, S>> {
        while let Some(&key) = self.dirty.first() {
            if let Some(output) = self.output_for(key) {
                return Some(output);
            }
            self.dirty.remove(&key);
        }
        None
    }

    fn output_for(&mut self, key: K) -> Option<WriterOutput<K, S>> {
        let oldest = self.first_available();
        let last = self.last;
        let state = self.readers.get_mut(&key)?;
        let output = Self::repair(&self.history, state, key)
            .or_else(|| Self::heartbeat(state, key, oldest, last))?;
        match output {
            WriterOutput::Resend { .. } => self.stats.resends += 1,
            WriterOutput::Gap { .. } => self.stats.gaps += 1,
            WriterOutput::Heartbeat { .. } => self.stats.heartbeats += 1,
        }
        Some(output)
    }

    /// The next gap or resend queued for a reader.
    fn repair(history: &History<S>, state: &mut ReaderState, key: K) -> Option<WriterOutput<K, S>> {
        if let Some((from, to)) = state.gaps.pop_first() {
            return Some(WriterOutput::Gap {
                reader: key,
                from,
                to,
            });
        }
        let seq = state.resend.pop_first()?;
        Some(match history.get(seq) {
            Some(sample) => WriterOutput::Resend {
                reader: key,
                seq,
                sample: sample.clone(),
            },
            None => WriterOutput::Gap {
                reader: key,
                from: seq,
                to: seq.saturating_add(1),
            },
        })
    }

    /// The heartbeat queued for a reader, if any. Until the reader answered, `first` is where
    /// its stream starts, so that it learns what it missed since as gaps instead of silently
    /// starting later.
    fn heartbeat(
        state: &mut ReaderState,
        key: K,
        oldest: u64,
        last: u64,
    ) -> Option<WriterOutput<K, S>> {
        if !std::mem::take(&mut state.heartbeat) {
            return None;
        }
        let first = match state.heard {
            Some(_) => oldest.max(state.acked),
            None => state.acked,
        };
        Some(WriterOutput::Heartbeat {
            reader: key,
            first,
            last,
        })
    }

    /// Oldest seq still available (`last + 1` when the history is empty).
    fn first_available(&self) -> u64 {
        self.history
            .first_seq()
            .unwrap_or_else(|| self.last.saturating_add(1))
    }

    /// Raises a reader's acknowledgement (never lowers it) and forgets what it no longer needs.
    fn advance(state: &mut ReaderState, acked: u64) {
        if acked <= state.acked {
            return;
        }
        state.acked = acked;
        state.resend = state.resend.split_off(&acked);
        state.gaps.remove_below(acked);
    }

    /// Drops samples every reader has acknowledged, then, beyond `depth` or the byte budget,
    /// the oldest samples, turning them into gaps for the readers that still need them.
    fn evict(&mut self) {
        let floor = self
            .readers
            .values()
            .filter(|r| !r.silent)
            .map(|r| r.acked)
            .min()
            .unwrap_or_else(|| self.last.saturating_add(1));
        while let Some(oldest) = self.history.first_seq() {
            if oldest >= floor && !self.overfull() {
                return;
            }
            self.history.pop_front();
            if oldest >= floor {
                self.stats.evicted_unacked += 1;
                self.gap_to_readers(oldest, oldest.saturating_add(1));
            }
        }
    }

    fn overfull(&self) -> bool {
        self.history.len() > self.config.depth
            || (self.history.len() > 1
                && self.history.bytes_before_newest() > self.config.max_bytes)
    }

    /// Queues the gap `from..to` for every reader that has not settled `from`.
    fn gap_to_readers(&mut self, from: u64, to: u64) {
        for (&key, state) in &mut self.readers {
            if state.acked <= from {
                state.resend.remove(&from);
                state.queue_gap(from, to);
                self.dirty.insert(key);
            }
        }
    }

    /// True when enough was written since the last heartbeat to ask for acknowledgements
    /// before the period ends: a quarter of the window in samples or bytes.
    fn heartbeat_wanted(&self) -> bool {
        let (samples, bytes) = self.since_heartbeat;
        samples >= (self.config.depth / 4).max(1) || bytes >= (self.config.max_bytes / 4).max(1)
    }

    /// Queues a heartbeat to every reader that is behind or not yet heard from, and re-arms
    /// the period while there is one.
    fn heartbeat_needy(&mut self, now: Instant) {
        self.since_heartbeat = (0, 0);
        let mut any = false;
        for (&key, state) in &mut self.readers {
            if state.needy(self.last) {
                state.heartbeat = true;
                self.dirty.insert(key);
                any = true;
            }
        }
        let period = self.period();
        if !self.window_open() {
            // Still blocked at the next one: wait twice as long (up to the normal period).
            self.blocked_period = (self.blocked_period * 2).min(self.config.heartbeat_period);
        }
        self.period_due = if any { now.checked_add(period) } else { None };
    }

    /// The heartbeat period now: short while the window is closed (see
    /// [`WriterConfig::blocked_heartbeat_period`]), else the configured one.
    fn period(&self) -> Duration {
        if self.window_open() {
            self.config.heartbeat_period
        } else {
            self.blocked_period
        }
    }

    /// Makes sure a periodic heartbeat comes within one period (never postpones one).
    fn arm_period(&mut self, now: Instant) {
        let Some(due) = now.checked_add(self.period()) else {
            return;
        };
        self.period_due = Some(self.period_due.map_or(due, |d| d.min(due)));
    }
}

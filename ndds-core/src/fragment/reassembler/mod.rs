//! The reassembler: pieces of many writers' samples in, whole samples out, within a memory
//! budget. The rules are in the [module docs](super).

use std::collections::BTreeMap;
use std::fmt::Debug;
use std::mem::size_of;
use std::time::Instant;

use super::config::{Mode, ReassemblyConfig};
use super::partial::{Added, Missing, Partial};
use super::piece::Piece;
use super::result::{FragmentResult, Ignored, ReassemblyStats, Reject};
use super::split::Split;
use super::writers::Writers;

mod budget;

/// Why a partial sample goes away, for the counters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum End {
    Completed,
    Superseded,
    Evicted,
    TimedOut,
    /// By the caller (`forget_writer`, `skip_before`): not counted.
    Dismissed,
}

/// Reassembles the samples of many writers, keyed by `K` (for example the writer's GUID),
/// within the bounds of a [`ReassemblyConfig`]. Sans-IO: the caller passes `now`, calls
/// [`handle_timeout`](Self::handle_timeout) when [`poll_timeout`](Self::poll_timeout) is due,
/// and sends the `NackFrag`s [`missing`](Self::missing) describes.
///
/// ```
/// use std::time::Instant;
/// use ndds_core::fragment::{FragmentResult, Mode, Piece, Reassembler, Split};
///
/// let sample: Vec<u8> = (0..5000u32).map(|i| i as u8).collect();
/// let split = Split::new(sample.len(), 1024).unwrap();
/// let mut r = Reassembler::<u32>::default();
/// let now = Instant::now();
/// let mut done = None;
/// for (index, range) in split.pieces().rev() {
///     let piece = Piece { seq: 1, total_len: 5000, frag_size: 1024, index, chunk: &sample[range] };
///     if let FragmentResult::Complete(bytes) = r.handle_fragment(now, 7, Mode::LastIsBest, &piece) {
///         done = Some(bytes);
///     }
/// }
/// assert_eq!(done.as_deref(), Some(&sample[..]));
/// ```
pub struct Reassembler<K> {
    config: ReassemblyConfig,
    partials: BTreeMap<(K, u64), Partial>,
    /// How many of `partials` each writer has (kept so that admitting a sample does not
    /// count them: with thousands held under heavy loss, counting on every new sample made
    /// reassembly the receiving thread's main cost just when it was furthest behind).
    held: BTreeMap<K, usize>,
    /// Partial samples by (first piece's time, serial): the oldest first.
    age: BTreeMap<(Instant, u64), (K, u64)>,
    writers: Writers<K>,
    spares: Vec<Vec<u8>>,
    serial: u64,
    stats: ReassemblyStats,
}

impl<K: Debug> Debug for Reassembler<K> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let spares: Vec<usize> = self.spares.iter().map(Vec::capacity).collect();
        f.debug_struct("Reassembler")
            .field("config", &self.config)
            .field("partials", &self.partials.len())
            .field("spare_capacities", &spares)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl<K: Copy + Ord + Debug> Default for Reassembler<K> {
    fn default() -> Self {
        Reassembler::new(ReassemblyConfig::default())
    }
}

impl<K: Copy + Ord + Debug> Reassembler<K> {
    /// Bytes charged per partial sample for its bookkeeping (struct, index entries and their
    /// share of map nodes), on top of its buffer and bitmap.
    pub const PARTIAL_OVERHEAD: usize = 3
        * (size_of::<(K, u64)>() + size_of::<Partial>() + size_of::<((Instant, u64), (K, u64))>());

    /// Bytes charged per remembered writer (see the module docs: the floor of a
    /// `LastIsBest` writer, kept while it has no partial sample until room is needed).
    pub const WRITER_OVERHEAD: usize = Writers::<K>::RECORD_BYTES;

    /// An empty reassembler.
    pub fn new(config: ReassemblyConfig) -> Self {
        Reassembler {
            config,
            partials: BTreeMap::new(),
            held: BTreeMap::new(),
            age: BTreeMap::new(),
            writers: Writers::new(),
            spares: Vec::new(),
            serial: 0,
            stats: ReassemblyStats::default(),
        }
    }

    /// Its configuration.
    pub fn config(&self) -> &ReassemblyConfig {
        &self.config
    }

    /// Counters, and the bytes and partial samples held now.
    pub fn stats(&self) -> ReassemblyStats {
        ReassemblyStats {
            partials: self.partials.len(),
            ..self.stats
        }
    }

    /// Takes one piece of `writer`'s sample, reassembling by `mode`'s rules. Never panics,
    /// and allocates a sample's buffer only once its claimed length passed every bound.
    pub fn handle_fragment(
        &mut self,
        now: Instant,
        writer: K,
        mode: Mode,
        piece: &Piece<'_>,
    ) -> FragmentResult {
        let result = match self.check(piece) {
            Ok(split) => self.accept(now, writer, mode, piece, split),
            Err(reason) => FragmentResult::Rejected(reason),
        };
        self.count(&result);
        result
    }

    /// Drops the partial samples whose time ran out (see
    /// [`ReassemblyConfig::partial_timeout`]).
    pub fn handle_timeout(&mut self, now: Instant) {
        while let Some((&(started, _), &key)) = self.age.first_key_value() {
            if self.deadline(started).is_none_or(|d| d > now) {
                break;
            }
            self.end(key, End::TimedOut);
        }
    }

    /// When [`handle_timeout`](Self::handle_timeout) has work next, if ever.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let (&(started, _), _) = self.age.first_key_value()?;
        self.deadline(started)
    }

    /// The first missing pieces of `writer`'s partial sample `seq`, for a `NackFrag`; `None`
    /// when there is no such partial sample (never started, complete, or dropped).
    pub fn missing(&self, writer: K, seq: u64) -> Option<Missing> {
        self.partials.get(&(writer, seq)).map(Partial::missing)
    }

    /// Sequence numbers of `writer`'s partial samples, ascending.
    pub fn partial_seqs(&self, writer: K) -> impl DoubleEndedIterator<Item = u64> + '_ {
        self.partials
            .range((writer, 0)..=(writer, u64::MAX))
            .map(|(&(_, seq), _)| seq)
    }

    /// From now on pieces of `writer`'s samples below `seq` are stale; its partial samples
    /// below `seq` are dropped. A reliable reader calls this as its window advances (and for
    /// a `Gap`).
    pub fn skip_before(&mut self, writer: K, seq: u64) {
        let below: Vec<(K, u64)> = self
            .partials
            .range((writer, 0)..(writer, seq))
            .map(|(&key, _)| key)
            .collect();
        for key in below {
            self.end(key, End::Dismissed);
        }
        if self.ensure_record(writer) {
            self.raise_floor(writer, seq);
        }
    }

    /// Forgets everything about `writer` (it left): its partial samples and its record.
    pub fn forget_writer(&mut self, writer: K) {
        let keys: Vec<(K, u64)> = self.partial_seqs(writer).map(|s| (writer, s)).collect();
        for key in keys {
            self.end(key, End::Dismissed);
        }
        self.remove_record(writer);
    }

    // ----- input ------------------------------------------------------------------------------

    /// Checks a piece on its own: geometry and size bounds.
    fn check(&self, piece: &Piece<'_>) -> Result<Split, Reject> {
        let split = Split::new(piece.total_len as usize, piece.frag_size as usize)
            .map_err(|_| Reject::BadFragSize)?;
        if split.total_len() > self.config.max_sample_bytes {
            return Err(Reject::TooLarge);
        }
        match split.piece_len(piece.index) {
            None => Err(Reject::IndexOutOfRange),
            Some(len) if len != piece.chunk.len() => Err(Reject::WrongChunkLength),
            Some(_) => Ok(split),
        }
    }

    fn accept(
        &mut self,
        now: Instant,
        writer: K,
        mode: Mode,
        piece: &Piece<'_>,
        split: Split,
    ) -> FragmentResult {
        let key = (writer, piece.seq);
        if let Some(partial) = self.partials.get_mut(&key) {
            if partial.split != split {
                return FragmentResult::Rejected(Reject::Inconsistent);
            }
            return match partial.add(piece.index, piece.chunk) {
                Added::Duplicate => FragmentResult::Ignored(Ignored::Duplicate),
                Added::Pending => FragmentResult::Pending,
                Added::Complete => FragmentResult::Complete(self.end(key, End::Completed)),
            };
        }
        if piece.seq < self.writers.floor(writer) {
            return FragmentResult::Ignored(Ignored::Stale);
        }
        if let Err(outcome) = self.admit(writer, piece.seq, mode, split.count()) {
            return outcome;
        }
        if split.count() == 1 {
            return self.complete_single(writer, mode, piece);
        }
        self.start(now, writer, mode, piece, split)
    }

    /// Applies the mode's rules to a piece of a sample without a partial: may drop older
    /// partial samples, or refuse the piece.
    fn admit(&mut self, writer: K, seq: u64, mode: Mode, count: u32) -> Result<(), FragmentResult> {
        match mode {
            Mode::LastIsBest => {
                if self
                    .newest_partial(writer)
                    .is_some_and(|newest| newest > seq)
                {
                    return Err(FragmentResult::Ignored(Ignored::Stale));
                }
                while let Some(older) = self.newest_partial(writer) {
                    let buf = self.end((writer, older), End::Superseded);
                    self.recycle(buf);
                }
            }
            Mode::KeepAll { max_partials } if count > 1 => {
                while self.held.get(&writer).copied().unwrap_or(0) >= max_partials {
                    match self.newest_partial(writer) {
                        Some(newest) if newest > seq => {
                            self.end((writer, newest), End::Evicted);
                        }
                        _ => return Err(FragmentResult::Rejected(Reject::TooManyPartials)),
                    }
                }
            }
            Mode::KeepAll { .. } => {}
        }
        Ok(())
    }

    /// A sample of one piece: complete at once, without a partial.
    fn complete_single(&mut self, writer: K, mode: Mode, piece: &Piece<'_>) -> FragmentResult {
        let len = piece.chunk.len();
        let mut buf = self
            .take_spare(len, usize::MAX)
            .unwrap_or_else(|| Vec::with_capacity(len));
        buf.clear();
        buf.extend_from_slice(piece.chunk);
        if mode == Mode::LastIsBest && self.ensure_record(writer) {
            self.raise_floor(writer, piece.seq.saturating_add(1));
        }
        FragmentResult::Complete(buf)
    }

    /// The first piece of a sample of several: make room, then allocate.
    fn start(
        &mut self,
        now: Instant,
        writer: K,
        mode: Mode,
        piece: &Piece<'_>,
        split: Split,
    ) -> FragmentResult {
        let len = split.total_len();
        let fixed = Self::PARTIAL_OVERHEAD + Self::WRITER_OVERHEAD;
        let room = self.config.max_total_bytes.saturating_sub(fixed);
        let Some(max_cap) = room.checked_sub(Partial::heap_bytes(&split, 0)) else {
            return FragmentResult::Rejected(Reject::OverBudget);
        };
        if len > max_cap || !self.ensure_record(writer) {
            return FragmentResult::Rejected(Reject::OverBudget);
        }
        let spare = self.take_spare(len, max_cap);
        let capacity = spare.as_ref().map_or(len, Vec::capacity);
        if !self.make_room(
            Partial::heap_bytes(&split, capacity) + Self::PARTIAL_OVERHEAD,
            writer,
        ) {
            // Unreachable after the checks above (only `writer`'s record is left), but safe.
            self.settle(writer);
            return FragmentResult::Rejected(Reject::OverBudget);
        }
        let buf = spare.unwrap_or_else(|| Vec::with_capacity(len));
        self.serial += 1;
        let age = (now, self.serial);
        let mut partial = Partial::new(split, buf, age, mode == Mode::LastIsBest);
        partial.add(piece.index, piece.chunk);
        self.charge(partial.heap() + Self::PARTIAL_OVERHEAD);
        if self.partials.insert((writer, piece.seq), partial).is_none() {
            *self.held.entry(writer).or_insert(0) += 1;
        }
        self.age.insert(age, (writer, piece.seq));
        self.writers.set_active(writer);
        FragmentResult::Pending
    }

    fn count(&mut self, result: &FragmentResult) {
        let stats = &mut self.stats;
        match result {
            FragmentResult::Complete(_) => {
                stats.pieces += 1;
                stats.completed += 1;
            }
            FragmentResult::Pending => stats.pieces += 1,
            FragmentResult::Ignored(Ignored::Duplicate) => stats.duplicates += 1,
            FragmentResult::Ignored(Ignored::Stale) => stats.stale_pieces += 1,
            FragmentResult::Rejected(reason) => stats.rejected.count(*reason),
        }
    }

    // ----- partial samples --------------------------------------------------------------------

    fn newest_partial(&self, writer: K) -> Option<u64> {
        self.partial_seqs(writer).next_back()
    }

    fn deadline(&self, started: Instant) -> Option<Instant> {
        started.checked_add(self.config.partial_timeout)
    }

    /// Removes a partial sample, counts why, and settles its writer; returns its buffer.
    fn end(&mut self, key: (K, u64), why: End) -> Vec<u8> {
        let Some(partial) = self.partials.remove(&key) else {
            return Vec::new();
        };
        if let Some(held) = self.held.get_mut(&key.0) {
            *held -= 1;
            if *held == 0 {
                self.held.remove(&key.0);
            }
        }
        self.age.remove(&partial.age);
        self.uncharge(partial.heap() + Self::PARTIAL_OVERHEAD);
        match why {
            End::Superseded => self.stats.stale_dropped += 1,
            End::Evicted => self.stats.evicted += 1,
            End::TimedOut => self.stats.timed_out += 1,
            End::Completed | End::Dismissed => {}
        }
        if partial.last_is_best {
            self.raise_floor(key.0, key.1.saturating_add(1));
        }
        self.settle(key.0);
        partial.into_buf()
    }
}

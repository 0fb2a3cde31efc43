//! What a piece did, why one was refused, and the counters of a reassembler.

/// The outcome of [`Reassembler::handle_fragment`](super::Reassembler::handle_fragment).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FragmentResult {
    /// That was the last missing piece: the whole sample (length `total_len`; its capacity
    /// may be larger when a spare buffer was reused). Hand it back with
    /// [`Reassembler::recycle`](super::Reassembler::recycle) when done with it.
    Complete(Vec<u8>),
    /// Stored; pieces of the sample are still missing.
    Pending,
    /// A well-formed piece that changed nothing.
    Ignored(Ignored),
    /// A piece that breaks a rule or a bound; nothing changed.
    Rejected(Reject),
}

/// Why a well-formed piece changed nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Ignored {
    /// That piece of that partial sample had arrived already.
    Duplicate,
    /// Its sample is older than one the writer is being reassembled for (`LastIsBest`), or
    /// was completed or dropped already (`LastIsBest`), or lies below the writer's
    /// [`skip_before`](super::Reassembler::skip_before) floor.
    Stale,
}

/// Why a piece was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, thiserror::Error)]
#[repr(u8)]
pub enum Reject {
    /// `frag_size` outside
    /// [`MIN_FRAG_SIZE`](super::MIN_FRAG_SIZE)`..=`[`MAX_FRAG_SIZE`](super::MAX_FRAG_SIZE).
    #[error("fragment size out of range")]
    BadFragSize = 0,
    /// `total_len` above the configured maximum sample size.
    #[error("sample larger than the maximum")]
    TooLarge = 1,
    /// The sample would not fit the reassembly budget even with everything else evicted.
    #[error("sample larger than the reassembly budget")]
    OverBudget = 2,
    /// `index` at or beyond the sample's piece count.
    #[error("piece index out of range")]
    IndexOutOfRange = 3,
    /// The chunk is not exactly the length the geometry gives that piece.
    #[error("chunk length does not match the piece")]
    WrongChunkLength = 4,
    /// `total_len` or `frag_size` differ from earlier pieces of the same sample.
    #[error("inconsistent with earlier pieces of the sample")]
    Inconsistent = 5,
    /// `KeepAll`: the writer has its maximum of partial samples, all older than this one.
    #[error("too many partial samples for this writer")]
    TooManyPartials = 6,
}

impl Reject {
    /// Every reason, for counter tables.
    pub const ALL: [Reject; 7] = [
        Reject::BadFragSize,
        Reject::TooLarge,
        Reject::OverBudget,
        Reject::IndexOutOfRange,
        Reject::WrongChunkLength,
        Reject::Inconsistent,
        Reject::TooManyPartials,
    ];
}

/// Refused pieces, counted by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Rejections([u64; Reject::ALL.len()]);

impl Rejections {
    /// Pieces refused for `reason`.
    pub fn get(&self, reason: Reject) -> u64 {
        self.0[reason as usize]
    }

    /// Pieces refused for any reason.
    pub fn total(&self) -> u64 {
        self.0.iter().sum()
    }

    pub(super) fn count(&mut self, reason: Reject) {
        self.0[reason as usize] += 1;
    }
}

/// Counters and gauges of a reassembler.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReassemblyStats {
    /// Samples completed (returned as [`FragmentResult::Complete`]).
    pub completed: u64,
    /// New pieces stored.
    pub pieces: u64,
    /// Pieces that had arrived already.
    pub duplicates: u64,
    /// Pieces ignored as stale ([`Ignored::Stale`]).
    pub stale_pieces: u64,
    /// Partial samples dropped because a piece of a newer sample of their writer arrived
    /// (`LastIsBest`).
    pub stale_dropped: u64,
    /// Partial samples dropped to make room (budget, or a `KeepAll` writer's bound).
    pub evicted: u64,
    /// Partial samples dropped by the partial timeout.
    pub timed_out: u64,
    /// Refused pieces by reason.
    pub rejected: Rejections,
    /// Bytes currently charged against the budget.
    pub bytes_in_use: usize,
    /// Highest `bytes_in_use` so far.
    pub peak_bytes_in_use: usize,
    /// Partial samples currently held.
    pub partials: usize,
}

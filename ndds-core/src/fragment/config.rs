//! How much a [`Reassembler`](super::Reassembler) may hold, and for how long.

use std::time::Duration;

/// Default [`ReassemblyConfig::max_sample_bytes`]: 16 MiB.
pub const DEFAULT_MAX_SAMPLE_BYTES: usize = 16 << 20;

/// Default [`ReassemblyConfig::max_total_bytes`]: 65 MiB, room for four samples of the
/// default maximum size at once, with their bookkeeping.
pub const DEFAULT_MAX_TOTAL_BYTES: usize = 4 * DEFAULT_MAX_SAMPLE_BYTES + (1 << 20);

/// Default [`ReassemblyConfig::partial_timeout`]: 5 s.
pub const DEFAULT_PARTIAL_TIMEOUT: Duration = Duration::from_secs(5);

/// Default [`ReassemblyConfig::spare_buffers`].
pub const DEFAULT_SPARE_BUFFERS: usize = 2;

/// Default bound of [`Mode::KeepAll`] from [`Mode::reliable`].
pub const DEFAULT_MAX_PARTIALS: usize = 8;

/// The bounds of a reassembler.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReassemblyConfig {
    /// Largest sample accepted; a piece claiming a larger `total_len` is refused
    /// ([`Reject::TooLarge`](super::Reject::TooLarge)).
    pub max_sample_bytes: usize,
    /// Budget for everything the reassembler holds: partial samples of all writers (buffers,
    /// bitmaps, bookkeeping), per-writer records and spare buffers. Room for a new partial is
    /// made by evicting the oldest; a sample that cannot fit even in an empty reassembler is
    /// refused ([`Reject::OverBudget`](super::Reject::OverBudget)).
    pub max_total_bytes: usize,
    /// A partial sample not completed within this time of its first piece is dropped
    /// ([`Duration::MAX`]: never).
    pub partial_timeout: Duration,
    /// Buffers kept for reuse: given back with
    /// [`Reassembler::recycle`](super::Reassembler::recycle) or left by a partial sample
    /// superseded by a newer one. They count against `max_total_bytes` and go first when room
    /// is needed.
    pub spare_buffers: usize,
}

impl Default for ReassemblyConfig {
    fn default() -> Self {
        ReassemblyConfig {
            max_sample_bytes: DEFAULT_MAX_SAMPLE_BYTES,
            max_total_bytes: DEFAULT_MAX_TOTAL_BYTES,
            partial_timeout: DEFAULT_PARTIAL_TIMEOUT,
            spare_buffers: DEFAULT_SPARE_BUFFERS,
        }
    }
}

/// How the pieces of one writer are reassembled; chosen per call, normally from the writer's
/// and the reader's reliability.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Best effort: at most one partial sample per writer, the newest. A piece of a newer
    /// sample drops the partial one; pieces of older samples, and of a sample already
    /// completed or dropped, are ignored.
    LastIsBest,
    /// Reliable: up to `max_partials` partial samples per writer, each kept until complete,
    /// timed out, evicted for room, or skipped with
    /// [`Reassembler::skip_before`](super::Reassembler::skip_before).
    KeepAll {
        /// Partial samples one writer may have at once.
        max_partials: usize,
    },
}

impl Mode {
    /// [`Mode::KeepAll`] with [`DEFAULT_MAX_PARTIALS`].
    pub const fn reliable() -> Mode {
        Mode::KeepAll {
            max_partials: DEFAULT_MAX_PARTIALS,
        }
    }
}

//! Large samples without IO: cutting a sample into pieces ([`Split`]) and putting the pieces
//! back together within a memory budget ([`Reassembler`]).
//!
//! A sample too large for one datagram travels as `Fragment` submessages
//! ([`crate::wire::data::Fragment`]), each one piece; a reader missing pieces asks for them
//! with `NackFrag` ([`crate::wire::feedback::NackFrag`]). This module fixes the rules both
//! sides follow; it sends and receives nothing itself.
//!
//! # Geometry (writer and reader)
//! - A sample of `total_len` bytes (at most `u32::MAX`) is cut with a `frag_size` in
//!   [`MIN_FRAG_SIZE`]`..=`[`MAX_FRAG_SIZE`] (64 ..= 65 507) into
//!   `count = max(1, ⌈total_len / frag_size⌉)` pieces. Piece `i` covers bytes
//!   `i × frag_size .. min((i + 1) × frag_size, total_len)`: every piece but the last has exactly
//!   `frag_size` bytes, the last has `total_len − (count − 1) × frag_size` (zero only for an
//!   empty sample, which is one empty piece). Writers do not fragment a sample that fits one
//!   datagram, but a reader accepts a one-piece sample and completes it at once.
//! - A sample is identified by its writer and its sequence number (`SampleMeta::seq`). Every
//!   piece of it carries the same `total_len` and `frag_size`.
//! - A reader refuses (and counts, by [`Reject`] reason) a piece whose `frag_size` is out of
//!   range, whose `total_len` exceeds its maximum sample size, whose `index ≥ count`, whose chunk
//!   is not exactly the length above, or whose `total_len`/`frag_size` differ from the pieces of
//!   the same sample it holds. A refused piece changes nothing.
//!
//! # Repair (`NackFrag`)
//! [`Reassembler::missing`] names the first missing piece as `base` and a bitmap of at most
//! 64 bytes: bit `i` (byte `i / 8`, bit `i % 8`) set means piece `base + i` is missing. It
//! covers at most 512 pieces and ends at its last set bit; a writer resends the named pieces
//! (unchanged: same `total_len`, `frag_size`, `index` and bytes). A reader asks again for the
//! rest as pieces arrive. A sample the reader holds no piece of has no `NackFrag`: a reliable
//! reader asks for the whole sample with `AckNack`.
//!
//! # Last is best (best effort)
//! A best-effort reader ([`Mode::LastIsBest`]) reassembles at most one sample per writer: the
//! newest (highest `seq`) it has seen a piece of. For each writer:
//! - a piece of a sample newer than the one being reassembled drops that partial sample
//!   (counted `stale_dropped`; it will never be delivered) and starts the new one;
//! - a piece of an older sample is ignored, and so is a piece of a sample already completed,
//!   dropped, evicted or timed out (the reader remembers the floor `seq + 1` below which it
//!   ignores pieces);
//! - it repairs (sends `NackFrag` for) only the sample being reassembled.
//!
//! So a best-effort reader delivers, per writer, complete and intact samples in increasing
//! `seq` order, each at most once (while the writer's record is kept, see *Bounds*). A sample
//! still incomplete when a piece of the next one arrives is lost, never delivered late: the
//! application sees the newest data that arrived whole, never older data after newer. For
//! writers this means: send all pieces of a sample before any piece of the next one, and
//! answer a `NackFrag` of a best-effort reader only for the newest sample (repairs of older
//! ones are ignored).
//!
//! The mode is chosen per call ([`Reassembler::handle_fragment`]); a driver passes the same
//! mode for all pieces of a writer. (If it changes, each call's rules apply to the partial
//! samples as they are: a `LastIsBest` piece drops all older partial samples of its writer.)
//!
//! # Keep all (reliable)
//! A reliable reader ([`Mode::KeepAll`]) keeps up to `max_partials` partial samples per
//! writer, in any interleaving, and repairs every one. When a writer already has that many, a
//! piece of a sample newer than all of them is refused ([`Reject::TooManyPartials`]; the writer
//! resends it later), and a piece of an older sample evicts the newest partial one, so the
//! samples next in order complete first. The reassembler does not remember completed samples
//! in this mode: the reliable reader drops pieces of samples it already has, and calls
//! [`Reassembler::skip_before`] as its window advances or on a `Gap`.
//!
//! # Bounds
//! - A sample's buffer is allocated on its first accepted piece, only after `total_len` passed
//!   the maximum sample size and room was made for it in the budget. Pieces are copied into it
//!   once, in place; a piece arriving ahead of the written prefix zero-fills the gap before it
//!   (pieces in order zero nothing). The buffer is handed out as the completed sample, and may
//!   come back through [`Reassembler::recycle`] to be reused without allocating.
//! - Everything held (buffers by capacity, bitmaps, bookkeeping, writer records, spare
//!   buffers) is charged against [`ReassemblyConfig::max_total_bytes`]. Room is made by
//!   dropping spare buffers, then the records of the longest idle writers (a writer's record
//!   holds its floor; without it the writer's old pieces are no longer recognised as stale),
//!   then the oldest partial samples of any writer (counted `evicted`). A flood of first pieces
//!   from many writers therefore never holds more than the budget; it does evict the partial
//!   samples of genuine writers, so a driver feeds only pieces of matched writers.
//! - Per writer: one partial sample (`LastIsBest`) or `max_partials` (`KeepAll`), each at most
//!   the maximum sample size.
//! - A partial sample not completed within [`ReassemblyConfig::partial_timeout`] of its first
//!   piece is dropped (counted `timed_out`) by [`Reassembler::handle_timeout`].
//!
//! # Layout
//! - [`split`]: the geometry, [`Split`] and [`fragment_count`].
//! - [`config`]: [`ReassemblyConfig`] and [`Mode`].
//! - [`reassembler`]: [`Reassembler`]; its input is a [`Piece`].
//! - [`result`]: [`FragmentResult`], [`Reject`], [`ReassemblyStats`].
//! - `partial`: one sample being reassembled, and the [`Missing`] report.
//! - `writers`: what is remembered of each writer between samples.

pub mod config;
mod partial;
mod piece;
pub mod reassembler;
pub mod result;
pub mod split;
mod writers;

pub use config::{Mode, ReassemblyConfig};
pub use partial::{MISSING_SPAN, Missing};
pub use piece::Piece;
pub use reassembler::Reassembler;
pub use result::{FragmentResult, Ignored, ReassemblyStats, Reject, Rejections};
pub use split::{MAX_FRAG_SIZE, MIN_FRAG_SIZE, Split, SplitError, fragment_count};

#[cfg(test)]
mod tests;

//! Reliable streams without IO: a writer's history, heartbeats, repair and flow-control
//! window ([`ReliableWriter`]), and a reader's reordering, duplicate suppression,
//! acknowledgements and loss reports ([`ReliableReader`]). Neither sends anything nor reads a
//! clock: drivers feed them messages and `now`, and send what they output.
//!
//! # Protocol
//! Messages are the `Data` submessages `Sample`/`Fragment` (with [`FLAG_RELIABLE`]),
//! `Heartbeat` and `Gap` from writer to reader, and the `Feedback` submessage `AckNack` from
//! reader to writer (see [`crate::wire::data`], [`crate::wire::feedback`]).
//!
//! ## Sequence numbers
//! A writer numbers its samples 1, 2, 3, … (u64). It may skip numbers; skipped ones are
//! announced as a gap. Readers are keyed by the writer (`K`); a reader state exists per
//! (writer, reader) pair.
//!
//! ## Writer
//! - **History.** The writer keeps only samples that some matched reliable reader has not
//!   acknowledged: at most `depth` of them, and at most `max_bytes` besides the newest. A
//!   sample every reader acknowledged is dropped at once. With no reliable reader, nothing is
//!   kept.
//! - **Flow control.** The window is open while the history has room (fewer than `depth`
//!   samples and fewer than `max_bytes` bytes). Since acknowledgements only cover samples the
//!   reader's application has taken, a slow consumer closes its writer's window: the
//!   producer's `write` then blocks until the window opens or its timeout expires. A write
//!   made anyway evicts the oldest samples, which become gaps (and `samples lost` reports) for
//!   the readers that still needed them.
//! - **New readers** are owed every sample written after they matched, never older history.
//!   A heartbeat is sent to a new reader at once, with `first` = the next seq to be written.
//! - **Heartbeats** are addressed per reader: `Heartbeat{first, last}` with `last` the newest
//!   seq written and `first` the oldest seq this reader can still get: the oldest in the
//!   history, or the reader's acknowledgement if higher (`last + 1` when it is owed nothing).
//!   Until the writer has received an AckNack from the reader, `first` is instead the seq
//!   the reader's stream starts at (the next seq when it matched), even if the history no
//!   longer holds it: the reader starts there and learns what it missed as gaps. They are
//!   sent
//!   - to every reader that is behind (acknowledged below `last + 1`) or never heard from,
//!     `heartbeat_period` (20 ms) after the write that put it behind, then every period while
//!     it stays so; while the window is closed the period is `blocked_heartbeat_period`
//!     (250 µs), doubling at each heartbeat that finds the window still closed (up to
//!     `heartbeat_period`) and starting again when an acknowledgement makes progress;
//!   - to those readers right after a write once a quarter of the window (`depth / 4`
//!     samples or `max_bytes / 4` bytes) was written since the last heartbeat, and after the
//!     write that closes the window, so acknowledgements come before the window is full;
//!   - to a reader right after the resends and gaps that answer its AckNack, so that it
//!     reports at once what the repair fixed (and what is still missing);
//!   - to every reader every `idle_heartbeat_period` (1 s).
//! - **AckNack{acked, missing}.** `acked` only ever raises what the writer holds for the
//!   reader (a lower one is stale and only its bitmap is used). Each set bit naming a seq in
//!   the history queues one resend (a seq asked for several times before the driver drains
//!   the output is resent once); a seq no longer in the history (or skipped) queues a gap. An
//!   `acked` beyond `last + 1` settles everything and its bitmap is ignored; bits beyond
//!   `last` are ignored. Per reader, gaps go out before resends (in seq order), then the
//!   heartbeat. Feedback from a reader not matched is ignored. A gap is also sent, unasked,
//!   for every sample evicted while a reader still needed it, and for skipped seqs.
//! - **Removal.** A removed reader releases everything it held; nothing waits for a reader
//!   the driver removed (discovery removes dead ones).
//!
//! ## Reader
//! - **Start.** Before its first heartbeat a reader hands out and acknowledges nothing; it
//!   holds up to `depth` samples (the lowest seqs). The first heartbeat sets the start to its
//!   `first`: a late joiner starts at the writer's next seq and never asks for older ones.
//!   Held samples below the start are dropped.
//! - **Delivery** is in seq order without duplicates. Samples up to `depth` ahead of the
//!   first unsettled seq are held; further ones, old ones and duplicates are dropped
//!   (counted). Nothing is acknowledged before the application took it.
//! - **Lost seqs.** A `Gap{from, to}` makes `from..to` lost; a heartbeat whose `first` is
//!   above the first unsettled seq makes the seqs in between lost. Samples already held are
//!   still delivered. A run of consecutive lost seqs is reported once, as one
//!   [`Delivery::Lost`], in stream order, once the sample after it has arrived, or once a
//!   heartbeat with `first == last + 1` (the writer has nothing for this reader) said the run
//!   ends at that `first`. A writer always keeps its newest sample while a reader needs it,
//!   so a run is normally followed by a sample.
//! - **AckNack{acked, missing}.** `acked` is the first seq neither taken by the application
//!   nor known lost (samples held but not taken are not acknowledged); bit `i` of `missing`
//!   asks for `acked + i`. A seq is *missing* when it is at most the newest seq known (from
//!   samples and heartbeats), within `min(depth, 512)` of `acked`, and neither held nor
//!   lost. An AckNack asks for every missing seq except those asked for less than the retry
//!   time ago, so each missing seq is asked for at most once per retry time. The reader
//!   sends one
//!   - in answer to every heartbeat (a plain ack when nothing is to be asked), so the writer
//!     learns the reader's progress;
//!   - at once when a sample opens a new hole (its seq is beyond the highest received + 1),
//!     if there is something to ask;
//!   - when the retry time of a request passes while its seq is still missing;
//!   - once the application has taken half of what it had not taken when the last heartbeat
//!     was answered (so a writer blocked by a slow consumer resumes without waiting for its
//!     next heartbeat).
//!
//!   An AckNack not yet sent is replaced by a newer one, which keeps the requests of the
//!   older one that still stand.
//! - **Samples arriving in pieces** ([`ReliableReader::handle_partial`]): a seq some pieces
//!   of which arrived is not missing while pieces keep coming (within `partial_timeout`,
//!   100 ms, of the last one): the driver repairs its pieces itself. It counts as known, so
//!   the missing seqs before it are asked for at once.
//! - **Retry time** adapts like TCP's retransmission timer: the round trip from a request to
//!   the sample answering it (requests made once only) is smoothed, and the retry time is
//!   the smoothed value plus four mean deviations, within `nack_retry_min..=nack_retry`
//!   (200 µs, 20 ms); `nack_retry` before the first measurement. A request repeated
//!   before its first answer arrived makes the writer send the sample twice: the duplicate
//!   shows the repeat was early, and the time from the first request to the first answer is
//!   measured then (requests made once would otherwise be the only ones measured, which
//!   favours fast answers).

//! ## Guarantees
//! With the window respected, no sample is evicted before every reader acknowledged it, so
//! every reader gets every sample once, in order, whatever the loss, as long as the writer
//! and reader stay matched. When the writer writes past a closed window, exactly the evicted
//! samples a reader had not received are reported to it as lost.
//!
//! [`FLAG_RELIABLE`]: crate::wire::data::FLAG_RELIABLE

mod bitmap;
mod held;
mod history;
mod ranges;
pub mod reader;
mod rtt;
pub mod writer;

pub use bitmap::{Bitmap, MAX_BITS};
pub use reader::{AckNack, Delivery, ReaderConfig, ReaderStats, ReliableReader};
pub use rtt::RttEstimate;
pub use writer::{ReliableWriter, WriteError, WriterConfig, WriterOutput, WriterStats};

#[cfg(test)]
mod tests;

//! The reader side of a reliable stream: one per (reliable writer, reliable reader) pair. It
//! reorders, drops duplicates, reports what can no longer be repaired, and acknowledges.
//!
//! # Call order
//! - Input: [`ReliableReader::handle_sample`] (originals and resends alike),
//!   [`ReliableReader::handle_heartbeat`], [`ReliableReader::handle_gap`], and
//!   [`ReliableReader::handle_timeout`] once [`ReliableReader::poll_timeout`] is reached.
//! - Delivery: call [`ReliableReader::poll_deliver`] while the consumer has room. What it has
//!   not handed out is never acknowledged, which is how a slow consumer slows its writer.
//! - After any of these: drain [`ReliableReader::poll_output`] (AckNacks to send to the
//!   writer) and re-arm the timer.
//!
//! See the [module docs](super) for the protocol rules.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use super::bitmap::{Bitmap, MAX_BITS};
use super::held::Held;
use super::ranges::RangeSet;
use super::rtt::RttEstimate;

/// Settings of one reliable reader.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReaderConfig {
    /// Most samples held (received but not yet handed out), which is also how far ahead of
    /// the next expected seq samples are kept (default 256; at least 1). Should be at least
    /// the writer's depth, or samples beyond it are dropped and repaired later.
    pub depth: usize,
    /// Longest wait before a request for a missing sample is repeated (default 20 ms). The
    /// wait adapts to the measured round trip (time from request to repair) within
    /// `nack_retry_min..=nack_retry`, and is `nack_retry` until a round trip was measured.
    pub nack_retry: Duration,
    /// Shortest wait before a request is repeated (default 200 µs). A request repeated too
    /// early shows itself by the duplicate its two answers make, and the round trip of the
    /// first answer is then measured, so the retry time grows to what repairs really take.
    pub nack_retry_min: Duration,
    /// How long a sample being put together from pieces (see
    /// [`ReliableReader::handle_partial`]) is left to piece-level repair after its last piece
    /// arrived, before it is asked for again as a whole (default 100 ms).
    pub partial_timeout: Duration,
}

impl Default for ReaderConfig {
    fn default() -> Self {
        ReaderConfig {
            depth: 256,
            nack_retry: Duration::from_millis(20),
            nack_retry_min: Duration::from_micros(200),
            partial_timeout: Duration::from_millis(100),
        }
    }
}

/// What [`ReliableReader::poll_deliver`] hands out, in stream order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Delivery<S> {
    /// The next sample.
    Sample {
        /// Its sequence number.
        seq: u64,
        /// The sample.
        sample: S,
    },
    /// Seqs `from..to` will never be delivered (the `samples lost` status). Consecutive lost
    /// seqs are reported in one item, and a sample follows it.
    Lost {
        /// First lost seq.
        from: u64,
        /// One past the last lost seq.
        to: u64,
    },
}

/// An acknowledgement to send to the writer: every seq below `acked` was handed out or given
/// up; the set bits of `missing` (bit `i` = `acked + i`) are seqs to repair. With an empty
/// bitmap it is a plain ack, otherwise a nack.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AckNack {
    /// Everything below is settled.
    pub acked: u64,
    /// Seqs asked to be repaired.
    pub missing: Bitmap,
}

impl AckNack {
    /// The seqs asked for, ascending.
    pub fn asked(&self) -> impl Iterator<Item = u64> + '_ {
        let acked = self.acked;
        self.missing
            .ones()
            .filter_map(move |i| acked.checked_add(i as u64))
    }
}

/// Counters of one reader.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReaderStats {
    /// Samples given to [`ReliableReader::handle_sample`].
    pub received: u64,
    /// Samples handed out.
    pub delivered: u64,
    /// Samples dropped because they were already held, handed out, or given up.
    pub duplicates: u64,
    /// Samples dropped because they were too far ahead (`depth`).
    pub out_of_window: u64,
    /// Seqs reported lost.
    pub lost: u64,
    /// Requests repeated before their first answer could arrive: a seq asked for again got
    /// two answers (each measured the round trip the retry time had missed).
    pub early_retries: u64,
    /// [`Delivery::Lost`] items handed out.
    pub lost_reports: u64,
    /// AckNacks emitted with missing seqs.
    pub nacks: u64,
    /// AckNacks emitted without.
    pub acks: u64,
    /// Heartbeats and gaps that made no sense (`first > last + 1`, `from > to`).
    pub invalid: u64,
}

/// A request for one missing seq.
#[derive(Clone, Copy, Debug)]
struct Ask {
    /// When it was last made.
    at: Instant,
    /// When it was first made.
    first: Instant,
    /// Made more than once (its answer then measures no round trip: it may answer either).
    repeated: bool,
}

/// Seqs answered after a repeated request, watched for a second answer, at most.
const WATCHED_REPEATS: usize = 256;

/// The reader of one reliable writer; `S` is the sample it hands back (opaque to it).
#[derive(Debug)]
pub struct ReliableReader<S> {
    config: ReaderConfig,
    /// A heartbeat fixed the starting point.
    synced: bool,
    /// Next seq to hand out: everything below was handed out or reported lost.
    base: u64,
    /// Samples received and not handed out (once synced).
    buf: Held<S>,
    /// Samples received before the first heartbeat (see [`ReliableReader::hold_unsynced`]).
    unsynced: BTreeMap<u64, S>,
    /// Seqs the writer said will never come (at or above `base`).
    lost: RangeSet,
    /// Highest seq known to exist (from samples and heartbeats).
    known_last: u64,
    /// Highest seq received.
    highest: u64,
    /// `first` of the latest heartbeat that said the writer had nothing for us
    /// (`first == last + 1`): a lost run reaching it is complete.
    drained_at: Option<u64>,
    /// The AckNack to send (a newer one replaces an unsent one).
    pending: Option<AckNack>,
    /// When each missing seq was last asked for.
    asked: BTreeMap<u64, Ask>,
    /// Seqs arriving in pieces, with when their last piece came: not missing while fresh.
    partial: BTreeMap<u64, Instant>,
    /// When `partial` is next looked through for stale entries.
    partial_check: Option<Instant>,
    /// Round trip from request to repair.
    rtt: RttEstimate,
    /// Seqs whose request was repeated and that arrived, with the time from their first
    /// request to their arrival: if a second copy comes, the repeat was too early, and that
    /// time is the round trip it should have waited (Karn's problem: only requests made once
    /// measure otherwise, which favours the fast answers and keeps the retry time short).
    repeats: BTreeMap<u64, Duration>,
    /// When the oldest request still unanswered may be repeated.
    nack_due: Option<Instant>,
    /// Send an ack once `base` reaches this (progress held back by a slow consumer).
    catch_up_at: Option<u64>,
    stats: ReaderStats,
}

impl<S> ReliableReader<S> {
    /// A reader that has heard nothing from its writer yet.
    pub fn new(config: ReaderConfig) -> Self {
        ReliableReader {
            config: ReaderConfig {
                depth: config.depth.max(1),
                ..config
            },
            synced: false,
            base: 0,
            buf: Held::default(),
            unsynced: BTreeMap::new(),
            lost: RangeSet::default(),
            known_last: 0,
            highest: 0,
            drained_at: None,
            pending: None,
            asked: BTreeMap::new(),
            partial: BTreeMap::new(),
            partial_check: None,
            rtt: RttEstimate::default(),
            repeats: BTreeMap::new(),
            nack_due: None,
            catch_up_at: None,
            stats: ReaderStats::default(),
        }
    }

    /// The settings in force (after clamping).
    pub fn config(&self) -> ReaderConfig {
        self.config
    }

    /// Counters.
    pub fn stats(&self) -> ReaderStats {
        self.stats
    }

    /// True once a heartbeat fixed the starting point; before that nothing is handed out.
    pub fn is_synced(&self) -> bool {
        self.synced
    }

    /// The next seq [`ReliableReader::poll_deliver`] will hand out or report lost.
    pub fn next_seq(&self) -> u64 {
        self.base
    }

    /// The seq this reader acknowledges up to: everything below it was handed out or is
    /// known lost.
    pub fn acked(&self) -> u64 {
        self.front()
    }

    /// Samples held.
    pub fn buffered(&self) -> usize {
        self.buf.len() + self.unsynced.len()
    }

    /// A sample (original or resend) with sequence number `seq`.
    pub fn handle_sample(&mut self, now: Instant, seq: u64, sample: S) {
        self.stats.received += 1;
        if !self.synced {
            self.hold_unsynced(seq, sample);
            return;
        }
        let front = self.front();
        if seq < front || self.buf.contains(seq) {
            self.stats.duplicates += 1;
            if let Some(rtt) = self.repeats.remove(&seq) {
                self.stats.early_retries += 1;
                self.rtt.sample(rtt);
            }
            return;
        }
        self.partial.remove(&seq);
        let opens_hole = seq > self.highest.saturating_add(1).max(front);
        self.highest = self.highest.max(seq);
        self.known_last = self.known_last.max(seq);
        if seq - front >= self.config.depth as u64 {
            self.stats.out_of_window += 1;
        } else {
            self.buf.insert(seq, sample);
            self.measure(now, seq);
        }
        if opens_hole {
            let ack = self.build(Some(now));
            if !ack.missing.is_empty() {
                self.queue(now, ack);
            }
        }
    }

    /// A piece of sample `seq` arrived, and the sample is not complete yet (a large sample
    /// put together from fragments, whose missing pieces the driver asks for itself). While
    /// pieces keep coming (within `partial_timeout` of the last one), the seq is not asked
    /// for with AckNack, so the whole sample is not sent again for a missing piece; it counts
    /// as existing, so the seqs before it that are missing are asked for at once.
    pub fn handle_partial(&mut self, now: Instant, seq: u64) {
        if !self.synced {
            return;
        }
        let front = self.front();
        if seq < front || self.buf.contains(seq) || seq - front >= self.config.depth as u64 {
            return;
        }
        let opens_hole = seq > self.highest.saturating_add(1).max(front);
        self.highest = self.highest.max(seq);
        self.known_last = self.known_last.max(seq);
        self.partial.insert(seq, now);
        if self.partial_check.is_none() {
            self.partial_check = now.checked_add(self.config.partial_timeout);
        }
        if opens_hole {
            let ack = self.build(Some(now));
            if !ack.missing.is_empty() {
                self.queue(now, ack);
            }
        }
        self.rearm();
    }

    /// A heartbeat: the writer can repair `first..=last` for us. The first one fixes where
    /// the stream starts (`first`); later ones make the seqs below `first` lost. Always
    /// answered with one AckNack.
    pub fn handle_heartbeat(&mut self, now: Instant, first: u64, last: u64) {
        if first > last.saturating_add(1) {
            self.stats.invalid += 1;
            return;
        }
        if !self.synced {
            self.sync(first);
        }
        let front = self.front();
        if first > front {
            self.lost.insert(front, first);
        }
        self.known_last = self.known_last.max(last);
        if first == last.saturating_add(1) {
            self.drained_at = Some(first);
        }
        let ack = self.build(Some(now));
        self.queue(now, ack);
        let held = self.held();
        self.catch_up_at = (held > 0).then(|| self.base.saturating_add((held / 2).max(1)));
    }

    /// A gap: seqs `from..to` will never come. Those not already received are reported lost
    /// when delivery reaches them.
    pub fn handle_gap(&mut self, from: u64, to: u64) {
        if from > to {
            self.stats.invalid += 1;
            return;
        }
        if !self.synced {
            return;
        }
        let front = self.front();
        let from = from.max(front);
        if from >= to {
            return;
        }
        if from - front >= self.config.depth as u64 {
            // Too far ahead to remember; asked about again when the window gets there.
            return;
        }
        self.lost.insert(from, to);
    }

    /// Repeats the request for missing samples when its retry time has come; asks for
    /// samples whose pieces stopped coming.
    pub fn handle_timeout(&mut self, now: Instant) {
        let timeout = self.config.partial_timeout;
        let before = self.partial.len();
        if self.partial_check.is_some_and(|at| at <= now) {
            self.partial
                .retain(|_, last| last.checked_add(timeout).is_none_or(|stale| stale > now));
            self.partial_check = self
                .partial
                .values()
                .min()
                .and_then(|oldest| oldest.checked_add(timeout));
        }
        if self.partial.len() < before {
            let ack = self.build(Some(now));
            if !ack.missing.is_empty() {
                self.queue(now, ack);
                return;
            }
        }
        if self.nack_due.is_none_or(|due| due > now) {
            return;
        }
        let ack = self.build(Some(now));
        if ack.missing.is_empty() {
            self.rearm();
        } else {
            self.queue(now, ack);
        }
    }

    /// When [`ReliableReader::handle_timeout`] must next run.
    pub fn poll_timeout(&self) -> Option<Instant> {
        // The check may come early (a partial sample refreshed since); it then looks again
        // later.
        match (self.nack_due, self.partial_check) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The next in-order sample, or the report of a lost range, if available. A lost range is
    /// reported once the sample after it is here (or a heartbeat said the writer has nothing
    /// for us from the end of the range on), so that one report covers it.
    pub fn poll_deliver(&mut self) -> Option<Delivery<S>> {
        if let Some(sample) = self.buf.take_first(self.base) {
            let seq = self.base;
            self.stats.delivered += 1;
            self.advance(seq.saturating_add(1));
            return Some(Delivery::Sample { seq, sample });
        }
        let front = self.front();
        let complete = self.buf.contains(front) || self.drained_at == Some(front);
        if front > self.base && complete {
            let from = self.base;
            self.stats.lost = self.stats.lost.saturating_add(front - from);
            self.stats.lost_reports += 1;
            self.advance(front);
            return Some(Delivery::Lost { from, to: front });
        }
        None
    }

    /// True when an AckNack waits for [`ReliableReader::poll_output`].
    pub fn has_output(&self) -> bool {
        self.pending.is_some()
    }

    /// The next AckNack to send.
    pub fn poll_output(&mut self) -> Option<AckNack> {
        let ack = self.pending.take()?;
        if ack.missing.is_empty() {
            self.stats.acks += 1;
        } else {
            self.stats.nacks += 1;
        }
        Some(ack)
    }

    /// First seq that is neither handed out nor known lost: the end of the lost run at
    /// `base`, stopped by a held sample.
    fn front(&self) -> u64 {
        let Some((_, end)) = self.lost.containing(self.base) else {
            return self.base;
        };
        // Every held sample is at or above `base`.
        match self.buf.first() {
            Some(held) => held.min(end),
            None => end,
        }
    }

    /// Moves `base` forward and forgets what lies below it.
    fn advance(&mut self, base: u64) {
        self.base = base;
        // Nothing is held below `base` (samples are admitted at or above `front`); kept so
        // by construction rather than by that argument alone.
        self.buf.drop_below(base);
        self.lost.remove_below(base);
        self.asked = self.asked.split_off(&base);
        self.partial = self.partial.split_off(&base);
        if self.partial.is_empty() {
            self.partial_check = None;
        }
        if self.catch_up_at.is_some_and(|at| base >= at) {
            self.catch_up_at = None;
            let ack = self.build(None);
            self.replace_pending(ack);
        }
    }

    /// The AckNack describing our state. With `now`, it asks for every missing seq not asked
    /// for within the retry time; without, it is a plain ack.
    fn build(&self, now: Option<Instant>) -> AckNack {
        let front = self.front();
        let mut missing = Bitmap::new();
        let Some(now) = now else {
            return AckNack {
                acked: front,
                missing,
            };
        };
        let span = self.config.depth.min(MAX_BITS);
        let retry = self.retry();
        for i in 0..span {
            let Some(seq) = front.checked_add(i as u64) else {
                break;
            };
            if seq > self.known_last {
                break;
            }
            let asked_recently = self
                .asked
                .get(&seq)
                .is_some_and(|ask| ask.at.checked_add(retry).is_none_or(|again| again > now));
            if self.is_missing(seq) && !asked_recently {
                missing.set(i);
            }
        }
        AckNack {
            acked: front,
            missing,
        }
    }

    /// Neither held nor known lost (the caller bounds `seq` to the window).
    fn is_missing(&self, seq: u64) -> bool {
        !self.buf.contains(seq) && !self.lost.contains(seq) && !self.partial.contains_key(&seq)
    }

    /// Queues an AckNack, noting when its missing seqs were asked for.
    fn queue(&mut self, now: Instant, ack: AckNack) {
        for seq in ack.asked() {
            let (first, repeated) = self
                .asked
                .get(&seq)
                .map_or((now, false), |ask| (ask.first, true));
            self.asked.insert(
                seq,
                Ask {
                    at: now,
                    first,
                    repeated,
                },
            );
        }
        self.replace_pending(ack);
        self.rearm();
    }

    /// Makes `ack` the one to send, keeping the requests of an unsent one that still stand.
    fn replace_pending(&mut self, mut ack: AckNack) {
        if let Some(old) = self.pending.take() {
            for seq in old.asked() {
                let standing = seq >= ack.acked && self.is_missing(seq);
                if standing && let Ok(i) = usize::try_from(seq - ack.acked) {
                    ack.missing.set(i);
                }
            }
        }
        self.pending = Some(ack);
    }

    /// The retry timer: when the oldest request for a seq still missing may be repeated.
    fn rearm(&mut self) {
        let front = self.front();
        self.asked = self.asked.split_off(&front);
        let retry = self.retry();
        self.nack_due = self
            .asked
            .iter()
            .filter(|&(&seq, _)| self.is_missing(seq))
            .filter_map(|(_, ask)| ask.at.checked_add(retry))
            .min();
    }

    /// How long a request stands before it is repeated.
    fn retry(&self) -> Duration {
        self.rtt
            .timeout(self.config.nack_retry_min, self.config.nack_retry)
    }

    /// A sample arrived: if it answers a request, the request is settled (and a request made
    /// once measures a round trip).
    fn measure(&mut self, now: Instant, seq: u64) {
        let Some(ask) = self.asked.remove(&seq) else {
            return;
        };
        if !ask.repeated {
            self.rtt.sample(now.saturating_duration_since(ask.at));
        } else {
            self.repeats
                .insert(seq, now.saturating_duration_since(ask.first));
            if self.repeats.len() > WATCHED_REPEATS {
                self.repeats.pop_first();
            }
        }
        self.rearm();
    }

    /// Number of consecutive samples held from `base` on: received, not yet handed out.
    fn held(&self) -> u64 {
        self.buf.run_from(self.base)
    }

    /// A stream this reader followed before, up to `next` (its writer was lost, and is
    /// matched again): it starts at `next` instead of at the writer's first heartbeat, so
    /// what the writer shows as gone since is reported lost rather than silently skipped.
    /// Does nothing once the stream is synced.
    pub fn resume_at(&mut self, next: u64) {
        if !self.synced {
            self.sync(next.max(1));
        }
    }

    /// Before the first heartbeat: keep the lowest `depth` samples, hand out nothing.
    fn hold_unsynced(&mut self, seq: u64, sample: S) {
        if self.unsynced.contains_key(&seq) {
            self.stats.duplicates += 1;
            return;
        }
        if self.unsynced.len() >= self.config.depth {
            match self.unsynced.last_key_value() {
                Some((&top, _)) if top > seq => {
                    self.unsynced.pop_last();
                }
                _ => {
                    self.stats.out_of_window += 1;
                    return;
                }
            }
            self.stats.out_of_window += 1;
        }
        self.highest = self.highest.max(seq);
        self.unsynced.insert(seq, sample);
    }

    /// The first heartbeat: the stream starts at `first`.
    fn sync(&mut self, first: u64) {
        self.synced = true;
        self.base = first;
        let mut kept = std::mem::take(&mut self.unsynced).split_off(&first);
        let end = first.saturating_add(self.config.depth as u64);
        let beyond = kept.split_off(&end);
        self.stats.out_of_window += beyond.len() as u64;
        for (seq, sample) in kept {
            self.buf.insert(seq, sample);
        }
        self.highest = self.highest.max(first.saturating_sub(1));
        self.known_last = self.highest;
    }
}

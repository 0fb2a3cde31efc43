//! Reassembly of large samples for every writer the participant hears, and the requests for
//! their missing pieces (`NackFrag`), scheduled from the measured round trip.

use std::collections::{BTreeMap, BTreeSet};
use std::net::SocketAddrV4;
use std::time::{Duration, Instant};

use crate::fragment::{FragmentResult, Missing, Mode, Piece, Reassembler, ReassemblyConfig};
use crate::reliability::RttEstimate;
use crate::wire::data::{AddressToken, FLAG_RELIABLE, Fragment};
use crate::wire::feedback::{NackFrag, encode_feedback};
use crate::wire::{FeedbackSub, Guid};

use super::transmit::Transmits;

/// Partial samples held per reliable writer.
const RELIABLE_PARTIALS: usize = 4096;

/// How long after the last piece of an incomplete sample its missing pieces are requested,
/// and how often again while they stay missing.
pub(crate) const NACK_FRAG_DELAY: Duration = Duration::from_millis(5);
const NACK_FRAG_RETRY: Duration = Duration::from_millis(20);
/// At least 5 ms between requests for one sample's pieces: the round trip is measured to the
/// first piece of an answer, but an answer is up to 512 pieces, and on a loaded machine a
/// shorter floor asked again while the answer was still arriving, multiplying the traffic
/// until nothing completed (a 16 MiB reliable sample between two namespaces failed about one
/// run in four with a 1 ms floor; 6 of 6 passed with 5 ms).
const NACK_FRAG_RETRY_MIN: Duration = Duration::from_millis(5);

/// The most a `NackFrag` submessage takes besides its bitmap (kind, ids, seq, base and the
/// bitmap's length, as postcard varints at their longest).
const NACK_FRAG_BYTES: usize = 1 + 5 + 5 + 10 + 5 + 2;
/// A `Feedback` datagram's header, writer participant and token, at their longest.
const FEEDBACK_OVERHEAD: usize = 64;

/// A request due now (collected before the datagrams are made).
#[derive(Clone, Copy, Debug)]
struct Due {
    writer: Guid,
    seq: u64,
    from: SocketAddrV4,
    token: AddressToken,
    reader: u32,
    missing: Missing,
}

/// A partial sample whose missing pieces will be requested.
#[derive(Clone, Copy, Debug)]
struct Wanted {
    from: SocketAddrV4,
    /// The address token its pieces carried (echoed in the request).
    token: AddressToken,
    reader: u32,
    due: Instant,
    /// When its pieces were first asked for, and whether they were asked for again since
    /// (only an answer to a single request measures a round trip).
    asked: Option<(Instant, bool)>,
}

/// What became of one piece.
#[derive(Debug)]
pub(crate) enum PieceOutcome {
    /// The sample is whole.
    Complete(Vec<u8>),
    /// The sample still lacks pieces.
    Pending,
    /// Nothing to do (a duplicate, a stale piece).
    Ignored,
    /// Refused by reassembly (counted).
    Refused,
}

/// Large samples being put together, and the requests for their missing pieces.
#[derive(Debug)]
pub(crate) struct Repair {
    reassembler: Reassembler<Guid>,
    wanted: BTreeMap<(Guid, u64), Wanted>,
    /// The keys of `wanted` never asked for nor made due yet.
    unasked: BTreeSet<(Guid, u64)>,
    /// No entry of `wanted` is due before this (`None`: none is wanted). A lower bound, not
    /// the minimum: entries that complete leave it where it was, and the next
    /// [`Repair::handle_timeout`] makes it exact again. Under heavy loss thousands of
    /// samples are wanted, and the driver asks for the next timeout at every turn.
    next_due: Option<Instant>,
    feedback: Vec<u8>,
    /// The requests of one [`Repair::handle_timeout`] (kept for its allocation).
    due: Vec<Due>,
    /// Round trip from a piece request to the first piece answering it.
    rtt: RttEstimate,
}

impl Repair {
    /// Room for four samples of `max_sample` bytes being put together at once.
    pub(crate) fn new(max_sample: usize) -> Self {
        let config = ReassemblyConfig {
            max_sample_bytes: max_sample,
            max_total_bytes: max_sample
                .saturating_mul(4)
                .saturating_add(1 << 20)
                .max(ReassemblyConfig::default().max_total_bytes),
            ..ReassemblyConfig::default()
        };
        Repair {
            reassembler: Reassembler::new(config),
            wanted: BTreeMap::new(),
            unasked: BTreeSet::new(),
            next_due: None,
            feedback: Vec::new(),
            due: Vec::new(),
            rtt: RttEstimate::default(),
        }
    }

    /// Stops asking for the pieces of `writer`'s samples `from..to`.
    fn forget(&mut self, writer: Guid, from: u64, to: u64) {
        while let Some((&key, _)) = self.wanted.range((writer, from)..(writer, to)).next() {
            self.wanted.remove(&key);
            self.unasked.remove(&key);
        }
    }

    /// How long a piece request stands before it is repeated: adapted to the measured round
    /// trip, like a reliable reader's requests.
    fn retry(&self) -> Duration {
        self.rtt.timeout(NACK_FRAG_RETRY_MIN, NACK_FRAG_RETRY)
    }

    /// A piece of sample `key.1` arrived: a writer sends the pieces of one sample before
    /// those of the next, so earlier samples of the same writer that are still incomplete
    /// will get no more pieces of their first sending: their missing pieces are asked for
    /// now rather than after the quiet delay.
    fn ask_earlier(&mut self, key: (Guid, u64), now: Instant) {
        let (writer, seq) = key;
        while let Some(&earlier) = self.unasked.range((writer, 0)..(writer, seq)).next() {
            self.unasked.remove(&earlier);
            if let Some(want) = self.wanted.get_mut(&earlier) {
                want.due = want.due.min(now);
                lower(&mut self.next_due, now);
            }
        }
    }

    /// Takes one piece from `writer` at `from` (whose datagram carried `token`); returns the
    /// whole sample once it is complete. Missing pieces are asked for on behalf of consumer
    /// `asker` (whose id the requests carry); `None`: not asked for (no consumer here
    /// believes the writer yet).
    pub(crate) fn piece(
        &mut self,
        now: Instant,
        writer: Guid,
        (from, token): (SocketAddrV4, AddressToken),
        asker: Option<u32>,
        fragment: &Fragment<'_>,
    ) -> PieceOutcome {
        let mode = if fragment.meta.flags & FLAG_RELIABLE != 0 {
            // A reliable writer has a whole window of samples in flight, and under loss many
            // of them are incomplete at once: hold as many (the byte budget still bounds them).
            Mode::KeepAll {
                max_partials: RELIABLE_PARTIALS,
            }
        } else {
            Mode::LastIsBest
        };
        let key = (writer, fragment.meta.seq);
        match self
            .reassembler
            .handle_fragment(now, writer, mode, &Piece::from(fragment))
        {
            FragmentResult::Complete(bytes) => {
                if let Some(Wanted {
                    asked: Some((at, false)),
                    ..
                }) = self.wanted.remove(&key)
                {
                    self.rtt.sample(now.saturating_duration_since(at));
                }
                self.unasked.remove(&key);
                self.ask_earlier(key, now);
                PieceOutcome::Complete(bytes)
            }
            FragmentResult::Pending => {
                if mode == Mode::LastIsBest {
                    // Only the newest sample of a best-effort writer is worth repairing.
                    self.forget(writer, 0, key.1);
                    self.forget(writer, key.1.saturating_add(1), u64::MAX);
                }
                let Some(reader) = asker else {
                    return PieceOutcome::Pending;
                };
                let asked = self.wanted.get(&key).and_then(|w| w.asked);
                if let Some((at, false)) = asked {
                    self.rtt.sample(now.saturating_duration_since(at));
                }
                let wait = match asked {
                    Some(_) => self.retry(),
                    None => NACK_FRAG_DELAY,
                };
                lower(&mut self.next_due, now + wait);
                self.wanted.insert(
                    key,
                    Wanted {
                        from,
                        token,
                        reader,
                        due: now + wait,
                        // Measured once: later pieces of the same answer are no round trip.
                        asked: asked.map(|(at, _)| (at, true)),
                    },
                );
                if asked.is_none() {
                    self.unasked.insert(key);
                }
                self.ask_earlier(key, now);
                PieceOutcome::Pending
            }
            FragmentResult::Ignored(_) => PieceOutcome::Ignored,
            FragmentResult::Rejected(_) => PieceOutcome::Refused,
        }
    }

    /// Forgets partial samples of `writer` below `seq` and ignores their pieces from now on.
    pub(crate) fn skip_before(&mut self, writer: Guid, seq: u64) {
        self.reassembler.skip_before(writer, seq);
        self.forget(writer, 0, seq);
    }

    /// Asks for the missing pieces of samples that stopped progressing; drops partial samples
    /// that timed out. The requests to one writer go out together, as many to a datagram of
    /// at most `max_datagram` bytes as fit: under heavy loss hundreds of samples may be due
    /// at once, and one datagram each would cost the receiving thread (and the writer) a
    /// system call per sample just when it is furthest behind.
    pub(crate) fn handle_timeout(
        &mut self,
        now: Instant,
        (domain, participant, max_datagram): (u16, u64, usize),
        out: &mut Transmits,
    ) {
        let retry = self.retry();
        let Repair {
            reassembler,
            wanted,
            unasked,
            next_due,
            feedback,
            due,
            ..
        } = self;
        reassembler.handle_timeout(now);
        due.clear();
        *next_due = None;
        wanted.retain(|&(writer, seq), want| {
            if want.due > now {
                lower(next_due, want.due);
                return true;
            }
            unasked.remove(&(writer, seq));
            let Some(missing) = reassembler.missing(writer, seq) else {
                return false;
            };
            due.push(Due {
                writer,
                seq,
                from: want.from,
                token: want.token,
                reader: want.reader,
                missing,
            });
            want.due = now + retry;
            lower(next_due, want.due);
            want.asked = Some(match want.asked {
                Some((first, _)) => (first, true),
                None => (now, false),
            });
            true
        });
        // `wanted` is ordered by writer, so one writer's requests are together.
        let budget = max_datagram
            .saturating_sub(FEEDBACK_OVERHEAD)
            .max(NACK_FRAG_BYTES);
        let mut subs: Vec<FeedbackSub<'_>> = Vec::new();
        for group in due.chunk_by(|a, b| {
            (a.writer.participant, a.from, a.token) == (b.writer.participant, b.from, b.token)
        }) {
            let first = &group[0];
            let mut bytes = 0;
            for request in group {
                let size = NACK_FRAG_BYTES + request.missing.bitmap().len();
                if !subs.is_empty() && bytes + size > budget {
                    send(out, feedback, (domain, participant), first, &subs);
                    subs.clear();
                    bytes = 0;
                }
                subs.push(FeedbackSub::NackFrag(NackFrag {
                    reader: request.reader,
                    writer: request.writer.entity,
                    seq: request.seq,
                    base: request.missing.base,
                    missing: request.missing.bitmap(),
                }));
                bytes += size;
            }
            if !subs.is_empty() {
                send(out, feedback, (domain, participant), first, &subs);
                subs.clear();
            }
        }
    }

    /// When [`Repair::handle_timeout`] must run next (at the latest; it may find nothing
    /// due, see `next_due`).
    pub(crate) fn poll_timeout(&self) -> Option<Instant> {
        match (self.next_due, self.reassembler.poll_timeout()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// An entry of `wanted` is due at `at`: `next` stays at or before it.
fn lower(next: &mut Option<Instant>, at: Instant) {
    *next = Some(next.map_or(at, |next| next.min(at)));
}

/// Encodes `subs` (requests to `to.writer`'s participant) and queues the datagram.
fn send(
    out: &mut Transmits,
    buf: &mut Vec<u8>,
    (domain, participant): (u16, u64),
    to: &Due,
    subs: &[FeedbackSub<'_>],
) {
    let writer = to.writer.participant;
    if encode_feedback(domain, participant, writer, to.token, subs, buf).is_ok() {
        out.push(to.from, buf, None);
    }
}

#[cfg(test)]
mod tests {
    use std::net::Ipv4Addr;

    use super::*;
    use crate::wire::SampleMeta;
    use crate::wire::feedback::FeedbackDatagram;

    const DOMAIN: u16 = 7;
    const WRITER: Guid = Guid {
        participant: 0xAAAA,
        entity: 3,
    };

    fn first_piece(seq: u64, chunk: &[u8]) -> Fragment<'_> {
        Fragment {
            meta: SampleMeta {
                seq,
                timestamp_ns: 1,
                strength: 0,
                persistence_us: 0,
                flags: FLAG_RELIABLE,
            },
            total_len: 3 * chunk.len() as u32,
            frag_size: chunk.len() as u32,
            index: 0,
            chunk,
        }
    }

    /// Requests for the missing pieces of 300 samples of one writer, due at once, travel
    /// together: a few datagrams of at most the limit, carrying every request once.
    #[test]
    fn the_requests_due_at_once_to_one_writer_share_datagrams() {
        let from = SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, 1), 7400);
        let chunk = [1u8; 1000];
        let mut repair = Repair::new(1 << 20);
        let t0 = Instant::now();
        for seq in 1..=300 {
            let outcome = repair.piece(t0, WRITER, (from, 99), Some(5), &first_piece(seq, &chunk));
            assert!(matches!(outcome, PieceOutcome::Pending), "{outcome:?}");
        }
        let mut out = Transmits::default();
        repair.handle_timeout(t0 + NACK_FRAG_DELAY, (DOMAIN, 0xBBBB, 1472), &mut out);
        let mut seqs = Vec::new();
        let mut datagrams = 0;
        while let Some(transmit) = out.pop() {
            datagrams += 1;
            assert_eq!(transmit.to, from);
            let bytes = transmit.to_vec();
            assert!(bytes.len() <= 1472, "{} bytes", bytes.len());
            let parsed = FeedbackDatagram::parse(&bytes, DOMAIN).expect("parses");
            for sub in parsed.subs() {
                match sub.expect("decodes") {
                    FeedbackSub::NackFrag(nack) => {
                        assert_eq!((nack.reader, nack.writer, nack.base), (5, 3, 1));
                        seqs.push(nack.seq);
                    }
                    other => panic!("{other:?}"),
                }
            }
        }
        assert_eq!(seqs, (1..=300).collect::<Vec<u64>>());
        assert!(datagrams <= 8, "{datagrams} datagrams for 300 requests");
    }

    /// Pieces of a writer no consumer believes are put together but make no request.
    #[test]
    fn pieces_nobody_believes_are_never_asked_for() {
        let from = SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, 66), 7400);
        let chunk = [1u8; 1000];
        let mut repair = Repair::new(1 << 20);
        let t0 = Instant::now();
        for seq in 1..=10 {
            repair.piece(t0, WRITER, (from, 0), None, &first_piece(seq, &chunk));
        }
        let mut out = Transmits::default();
        repair.handle_timeout(
            t0 + Duration::from_secs(1),
            (DOMAIN, 0xBBBB, 1472),
            &mut out,
        );
        assert_eq!(out.len(), 0);
        assert_eq!(
            repair.poll_timeout().filter(|_| !repair.wanted.is_empty()),
            None
        );
    }

    /// The next timeout is never later than the earliest wanted request (it may be earlier:
    /// completed samples leave it behind until the next round makes it exact).
    #[test]
    fn the_next_timeout_never_passes_a_wanted_request() {
        let from = SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, 1), 7400);
        let chunk = [1u8; 1000];
        let mut repair = Repair::new(1 << 20);
        let t0 = Instant::now();
        let earliest = |repair: &Repair| repair.wanted.values().map(|w| w.due).min();
        let check = |repair: &Repair| {
            if let Some(due) = earliest(repair) {
                assert!(repair.poll_timeout().is_some_and(|at| at <= due));
            }
        };
        for seq in 1..=20 {
            let at = t0 + Duration::from_millis(seq);
            repair.piece(at, WRITER, (from, 99), Some(5), &first_piece(seq, &chunk));
            check(&repair);
        }
        let mut out = Transmits::default();
        let mut now = t0;
        for _ in 0..50 {
            now += Duration::from_millis(3);
            if repair.poll_timeout().is_some_and(|at| at <= now) {
                repair.handle_timeout(now, (DOMAIN, 0xBBBB, 1472), &mut out);
                // A round makes it exact.
                let exact = earliest(&repair);
                let reassembly = repair.reassembler.poll_timeout();
                let expected = match (exact, reassembly) {
                    (Some(a), Some(b)) => Some(a.min(b)),
                    (a, b) => a.or(b),
                };
                assert_eq!(repair.poll_timeout(), expected);
            }
            check(&repair);
        }
        assert!(out.pop().is_some(), "the requests went out");
        // Samples skipped stop being wanted; nothing due is ever left unscheduled.
        repair.skip_before(WRITER, 11);
        check(&repair);
        repair.skip_before(WRITER, 100);
        assert!(repair.wanted.is_empty());
    }
}

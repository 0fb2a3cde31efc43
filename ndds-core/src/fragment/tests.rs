//! Unit tests of the reassembler's rules; randomized round trips and floods are in
//! `tests/fragment.rs` and `tests/fragment_memory.rs`.

use std::time::{Duration, Instant};

use super::*;

const FS: u32 = 64;

fn sample(len: usize, seed: u8) -> Vec<u8> {
    (0..len)
        .map(|i| (i as u8).wrapping_mul(31) ^ seed)
        .collect()
}

fn piece(seq: u64, data: &[u8], index: u32) -> Piece<'_> {
    let split = Split::new(data.len(), FS as usize).unwrap();
    Piece {
        seq,
        total_len: data.len() as u32,
        frag_size: FS,
        index,
        chunk: &data[split.range(index).unwrap()],
    }
}

fn feed(
    r: &mut Reassembler<u8>,
    now: Instant,
    mode: Mode,
    seq: u64,
    data: &[u8],
    index: u32,
) -> FragmentResult {
    r.handle_fragment(now, 1, mode, &piece(seq, data, index))
}

#[test]
fn last_is_best_drops_the_stale_partial_and_ignores_older_pieces() {
    let now = Instant::now();
    let mut r = Reassembler::default();
    let (old, new) = (sample(300, 1), sample(200, 2));
    let lib = Mode::LastIsBest;
    assert_eq!(feed(&mut r, now, lib, 5, &old, 0), FragmentResult::Pending);
    assert_eq!(feed(&mut r, now, lib, 6, &new, 3), FragmentResult::Pending);
    assert_eq!(r.stats().stale_dropped, 1);
    assert_eq!(r.missing(1, 5), None);
    let stale = FragmentResult::Ignored(Ignored::Stale);
    assert_eq!(feed(&mut r, now, lib, 5, &old, 1), stale, "older sample");
    assert_eq!(feed(&mut r, now, lib, 4, &old, 1), stale, "older still");
    for i in 0..2 {
        assert_eq!(feed(&mut r, now, lib, 6, &new, i), FragmentResult::Pending);
    }
    assert_eq!(
        feed(&mut r, now, lib, 6, &new, 2),
        FragmentResult::Complete(new.clone())
    );
    assert_eq!(
        feed(&mut r, now, lib, 6, &new, 0),
        stale,
        "completed already"
    );
    let stats = r.stats();
    assert_eq!(
        (stats.completed, stats.stale_pieces, stats.partials),
        (1, 3, 0)
    );
}

#[test]
fn keep_all_holds_several_samples_up_to_its_bound() {
    let now = Instant::now();
    let mut r = Reassembler::default();
    let mode = Mode::KeepAll { max_partials: 2 };
    let data: Vec<_> = (0..4).map(|s| sample(150, s)).collect();
    assert_eq!(
        feed(&mut r, now, mode, 2, &data[2], 0),
        FragmentResult::Pending
    );
    assert_eq!(
        feed(&mut r, now, mode, 3, &data[3], 0),
        FragmentResult::Pending
    );
    let refused = FragmentResult::Rejected(Reject::TooManyPartials);
    assert_eq!(
        feed(&mut r, now, mode, 4, &data[0], 0),
        refused,
        "newer than all"
    );
    assert_eq!(
        feed(&mut r, now, mode, 1, &data[1], 0),
        FragmentResult::Pending
    );
    assert_eq!(
        r.partial_seqs(1).collect::<Vec<_>>(),
        [1, 2],
        "the newest was evicted"
    );
    assert_eq!(r.stats().evicted, 1);
    for seq in [1, 2] {
        let d = &data[seq as usize];
        assert_eq!(feed(&mut r, now, mode, seq, d, 1), FragmentResult::Pending);
        assert_eq!(
            feed(&mut r, now, mode, seq, d, 2),
            FragmentResult::Complete(d.clone())
        );
    }
    r.skip_before(1, 3);
    let stale = FragmentResult::Ignored(Ignored::Stale);
    assert_eq!(feed(&mut r, now, mode, 2, &data[2], 0), stale);
}

#[test]
fn inconsistent_and_malformed_pieces_are_refused_and_counted() {
    let now = Instant::now();
    let mut r = Reassembler::<u8>::default();
    let data = sample(1000, 3);
    let lib = Mode::LastIsBest;
    assert_eq!(feed(&mut r, now, lib, 1, &data, 0), FragmentResult::Pending);
    let mut other = piece(1, &data, 1);
    other.total_len = 999;
    let inconsistent = FragmentResult::Rejected(Reject::Inconsistent);
    assert_eq!(r.handle_fragment(now, 1, lib, &other), inconsistent);
    let cases = [
        (
            Piece {
                frag_size: 0,
                ..piece(1, &data, 1)
            },
            Reject::BadFragSize,
        ),
        (
            Piece {
                frag_size: u32::MAX,
                ..piece(1, &data, 1)
            },
            Reject::BadFragSize,
        ),
        (
            Piece {
                index: u32::MAX,
                ..piece(1, &data, 1)
            },
            Reject::IndexOutOfRange,
        ),
        (
            Piece {
                chunk: &data[..10],
                ..piece(1, &data, 1)
            },
            Reject::WrongChunkLength,
        ),
        (
            Piece {
                total_len: u32::MAX,
                ..piece(1, &data, 1)
            },
            Reject::TooLarge,
        ),
    ];
    for (p, reason) in cases {
        assert_eq!(
            r.handle_fragment(now, 1, lib, &p),
            FragmentResult::Rejected(reason)
        );
    }
    let rejected = r.stats().rejected;
    assert_eq!(rejected.total(), 6);
    assert_eq!(rejected.get(Reject::BadFragSize), 2);
    assert_eq!(r.missing(1, 1).unwrap().pieces().count(), 15, "unchanged");
}

#[test]
fn one_piece_and_empty_samples_complete_at_once() {
    let now = Instant::now();
    let mut r = Reassembler::<u8>::default();
    let empty = Piece {
        seq: 1,
        total_len: 0,
        frag_size: FS,
        index: 0,
        chunk: &[],
    };
    assert_eq!(
        r.handle_fragment(now, 1, Mode::reliable(), &empty),
        FragmentResult::Complete(vec![])
    );
    let small = sample(10, 4);
    let one = piece(2, &small, 0);
    assert_eq!(
        r.handle_fragment(now, 1, Mode::LastIsBest, &one),
        FragmentResult::Complete(small.clone())
    );
    let again = r.handle_fragment(now, 1, Mode::LastIsBest, &one);
    assert_eq!(again, FragmentResult::Ignored(Ignored::Stale));
    assert_eq!(r.stats().partials, 0);
}

#[test]
fn partial_samples_time_out() {
    let start = Instant::now();
    let config = ReassemblyConfig {
        partial_timeout: Duration::from_secs(1),
        ..Default::default()
    };
    let mut r = Reassembler::new(config);
    assert_eq!(r.poll_timeout(), None);
    let data = sample(500, 5);
    feed(&mut r, start, Mode::reliable(), 1, &data, 0);
    let later = start + Duration::from_millis(500);
    feed(&mut r, later, Mode::reliable(), 2, &data, 0);
    assert_eq!(r.poll_timeout(), Some(start + Duration::from_secs(1)));
    r.handle_timeout(start + Duration::from_millis(999));
    assert_eq!(r.stats().partials, 2);
    r.handle_timeout(start + Duration::from_secs(1));
    assert_eq!(r.partial_seqs(1).collect::<Vec<_>>(), [2]);
    assert_eq!(r.poll_timeout(), Some(later + Duration::from_secs(1)));
    r.handle_timeout(later + Duration::from_secs(1));
    assert_eq!((r.stats().timed_out, r.stats().partials), (2, 0));
}

#[test]
fn the_budget_evicts_the_oldest_partial_of_any_writer() {
    let now = Instant::now();
    let one = Reassembler::<u8>::PARTIAL_OVERHEAD + Reassembler::<u8>::WRITER_OVERHEAD + 1024 + 8;
    let config = ReassemblyConfig {
        max_total_bytes: 2 * one + 100,
        ..Default::default()
    };
    let mut r = Reassembler::new(config);
    let data = sample(1024, 6);
    for writer in 0..3u8 {
        let p = piece(1, &data, 0);
        assert_eq!(
            r.handle_fragment(now, writer, Mode::LastIsBest, &p),
            FragmentResult::Pending
        );
        assert!(r.stats().bytes_in_use <= config.max_total_bytes);
    }
    assert_eq!(r.missing(0, 1), None, "the oldest went");
    assert!(r.missing(1, 1).is_some() && r.missing(2, 1).is_some());
    assert_eq!(r.stats().evicted, 1);
    let big = sample(4096, 7);
    let refused = r.handle_fragment(now, 9, Mode::LastIsBest, &piece(1, &big, 0));
    assert_eq!(refused, FragmentResult::Rejected(Reject::OverBudget));
    assert!(
        r.missing(1, 1).is_some(),
        "a sample that can never fit evicts nothing"
    );
}

#[test]
fn recycled_buffers_are_reused_and_everything_is_uncharged() {
    let now = Instant::now();
    let mut r = Reassembler::<u8>::default();
    let data = sample(5000, 8);
    let split = Split::new(5000, FS as usize).unwrap();
    let mut done = None;
    for (i, _) in split.pieces() {
        if let FragmentResult::Complete(b) = feed(&mut r, now, Mode::LastIsBest, 1, &data, i) {
            done = Some(b);
        }
    }
    let buf = done.unwrap();
    let address = buf.as_ptr();
    r.recycle(buf);
    assert_eq!(
        r.stats().bytes_in_use,
        5000 + Reassembler::<u8>::WRITER_OVERHEAD
    );
    let shorter = sample(4000, 9);
    feed(&mut r, now, Mode::LastIsBest, 2, &shorter, 0);
    let mut out = None;
    for i in 1..Split::new(4000, FS as usize).unwrap().count() {
        if let FragmentResult::Complete(b) = feed(&mut r, now, Mode::LastIsBest, 2, &shorter, i) {
            out = Some(b);
        }
    }
    let out = out.unwrap();
    assert_eq!((out.as_ptr(), &out), (address, &shorter));
    r.forget_writer(1);
    assert_eq!(r.stats().bytes_in_use, 0);
}

// ----- random operations keep the books balanced --------------------------------------------

#[derive(Clone, Debug)]
enum Op {
    Piece {
        writer: u8,
        seq: u64,
        len: usize,
        frag_size: u32,
        index: u32,
        reliable: bool,
        max_partials: usize,
    },
    Time(u64),
    Skip(u8, u64),
    Forget(u8),
}

fn op() -> impl proptest::strategy::Strategy<Value = Op> {
    use proptest::prelude::*;
    let piece = (
        0u8..4,
        0u64..5,
        0usize..1200,
        prop_oneof![Just(64u32), Just(100)],
        0u32..20,
    )
        .prop_flat_map(|p| (Just(p), any::<bool>(), 0usize..3))
        .prop_map(
            |((writer, seq, len, frag_size, index), reliable, max_partials)| Op::Piece {
                writer,
                seq,
                len,
                frag_size,
                index,
                reliable,
                max_partials,
            },
        );
    prop_oneof![
        8 => piece,
        1 => (0u64..30).prop_map(Op::Time),
        1 => (0u8..4, 0u64..5).prop_map(|(w, s)| Op::Skip(w, s)),
        1 => (0u8..4).prop_map(Op::Forget),
    ]
}

/// The bytes of `writer`'s sample `seq`: a function of the position, so every piece of the
/// same sample agrees whatever length it claims.
fn content(writer: u8, seq: u64, range: std::ops::Range<usize>) -> Vec<u8> {
    range
        .map(|i| (i as u64 * 7 + seq * 13 + u64::from(writer)) as u8)
        .collect()
}

fn apply(r: &mut Reassembler<u8>, now: &mut Instant, op: Op) {
    match op {
        Op::Piece {
            writer,
            seq,
            len,
            frag_size,
            index,
            reliable,
            max_partials,
        } => {
            let range = Split::new(len, frag_size as usize)
                .ok()
                .and_then(|s| s.range(index))
                .unwrap_or(0..0);
            let chunk = content(writer, seq, range);
            let piece = Piece {
                seq,
                total_len: len as u32,
                frag_size,
                index,
                chunk: &chunk,
            };
            let mode = if reliable {
                Mode::KeepAll { max_partials }
            } else {
                Mode::LastIsBest
            };
            if let FragmentResult::Complete(bytes) = r.handle_fragment(*now, writer, mode, &piece) {
                assert_eq!(bytes, content(writer, seq, 0..len));
                r.recycle(bytes);
            }
        }
        Op::Time(ms) => {
            *now += Duration::from_millis(ms);
            r.handle_timeout(*now);
        }
        Op::Skip(writer, seq) => r.skip_before(writer, seq),
        Op::Forget(writer) => r.forget_writer(writer),
    }
}

proptest::proptest! {
    #[test]
    fn random_operations_keep_the_books_balanced(ops in proptest::collection::vec(op(), 1..300)) {
        let config = ReassemblyConfig {
            max_sample_bytes: 1200,
            max_total_bytes: 6000,
            partial_timeout: Duration::from_millis(50),
            spare_buffers: 2,
        };
        let mut r = Reassembler::new(config);
        let mut now = Instant::now();
        for op in ops {
            apply(&mut r, &mut now, op);
            let stats = r.stats();
            proptest::prop_assert_eq!(r.audit(), stats.bytes_in_use);
            proptest::prop_assert!(stats.bytes_in_use <= config.max_total_bytes);
            proptest::prop_assert!(r.poll_timeout().is_none_or(|t| t > now));
        }
        for writer in 0..4 {
            r.forget_writer(writer);
        }
        proptest::prop_assert_eq!(r.audit(), r.stats().bytes_in_use);
        proptest::prop_assert_eq!(r.stats().partials, 0);
    }
}

//! Fragmentation and reassembly end to end, over a simulated lossy link: random sample sizes
//! and frag sizes, random loss, reordering and duplication, repaired through `missing()` (what
//! a `NackFrag` carries) until complete; "last is best" across consecutive samples; hostile
//! pieces. The memory bound under a flood is in `fragment_memory.rs` (own allocator).

use std::time::{Duration, Instant};

use ndds_core::fragment::{
    FragmentResult, Ignored, MAX_FRAG_SIZE, MIN_FRAG_SIZE, Mode, Piece, Reassembler,
    ReassemblyConfig, Reject, Split,
};
use ndds_core::wire::feedback::{MAX_BITMAP_BYTES, bit};
use proptest::prelude::*;

// ----- a lossy link ------------------------------------------------------------------------

/// Loss, duplication and reordering of one batch of pieces, from a seed.
struct Link {
    rng: fastrand::Rng,
    loss: f64,
    dup: f64,
}

impl Link {
    fn new(seed: u64, loss: f64, dup: f64) -> Self {
        Link {
            rng: fastrand::Rng::with_seed(seed),
            loss,
            dup,
        }
    }

    /// What arrives of `sent`: each item lost with probability `loss`, duplicated with
    /// probability `dup`, all shuffled.
    fn carry<T: Copy>(&mut self, sent: &[T]) -> Vec<T> {
        let mut out = Vec::with_capacity(sent.len());
        for &item in sent {
            if self.rng.f64() >= self.loss {
                out.push(item);
                if self.rng.f64() < self.dup {
                    out.push(item);
                }
            }
        }
        self.rng.shuffle(&mut out);
        out
    }
}

fn payload(len: usize, seed: u64) -> Vec<u8> {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut bytes = vec![0; len];
    rng.fill(&mut bytes);
    bytes
}

/// A writer's sample, ready to be cut.
struct Outgoing {
    writer: u32,
    seq: u64,
    bytes: Vec<u8>,
    split: Split,
}

impl Outgoing {
    fn new(writer: u32, seq: u64, bytes: Vec<u8>, frag_size: usize) -> Self {
        let split = Split::new(bytes.len(), frag_size).unwrap();
        Outgoing {
            writer,
            seq,
            bytes,
            split,
        }
    }

    fn piece(&self, index: u32) -> Piece<'_> {
        Piece {
            seq: self.seq,
            total_len: self.split.total_len() as u32,
            frag_size: self.split.frag_size() as u32,
            index,
            chunk: &self.bytes[self.split.range(index).unwrap()],
        }
    }
}

/// The pieces the reader asks for: those `missing()` names (checked to be what a `NackFrag`
/// can carry), or all of them when the reader holds no piece of the sample.
fn wanted(r: &Reassembler<u32>, out: &Outgoing) -> Vec<u32> {
    let Some(missing) = r.missing(out.writer, out.seq) else {
        return (0..out.split.count()).collect();
    };
    let bitmap = missing.bitmap();
    assert!(!bitmap.is_empty() && bitmap.len() <= MAX_BITMAP_BYTES);
    assert!(bit(bitmap, 0), "base is missing");
    let pieces: Vec<u32> = missing.pieces().collect();
    let from_bits = (0..bitmap.len() * 8).filter(|&i| bit(bitmap, i)).count();
    assert_eq!(pieces.len(), from_bits);
    assert!(pieces.iter().all(|&p| p < out.split.count()));
    pieces
}

/// Sends every sample of `samples` until each completed, through `link`; returns the
/// completed samples in the order they completed, as (writer, seq, bytes). Duplicates keep
/// arriving after a sample completed, as on a real link.
fn deliver_all(
    r: &mut Reassembler<u32>,
    link: &mut Link,
    mode: Mode,
    samples: &[Outgoing],
) -> Vec<(u32, u64, Vec<u8>)> {
    let now = Instant::now();
    let mut done: Vec<(u32, u64, Vec<u8>)> = Vec::new();
    let mut open: Vec<usize> = (0..samples.len()).collect();
    for _round in 0..10_000 {
        let mut batch = Vec::new();
        for &s in &open {
            batch.extend(wanted(r, &samples[s]).into_iter().map(|i| (s, i)));
        }
        for (s, index) in link.carry(&batch) {
            let out = &samples[s];
            let have = done.iter().any(|d| (d.0, d.1) == (out.writer, out.seq));
            if have && mode != Mode::LastIsBest {
                // A reliable reader drops pieces of samples it has (the reassembler does not
                // remember them in this mode); a best-effort one relies on the reassembler.
                continue;
            }
            match r.handle_fragment(now, out.writer, mode, &out.piece(index)) {
                FragmentResult::Complete(bytes) => done.push((out.writer, out.seq, bytes)),
                FragmentResult::Pending | FragmentResult::Ignored(_) => {}
                FragmentResult::Rejected(reason) => panic!("{reason} for a valid piece"),
            }
        }
        open.retain(|&s| {
            !done
                .iter()
                .any(|d| (d.0, d.1) == (samples[s].writer, samples[s].seq))
        });
        if open.is_empty() {
            return done;
        }
    }
    panic!("not complete after 10 000 rounds");
}

fn frag_size() -> impl Strategy<Value = usize> {
    prop_oneof![
        Just(MIN_FRAG_SIZE as usize),
        MIN_FRAG_SIZE as usize..2048,
        Just(1400usize),
        8192usize..=MAX_FRAG_SIZE as usize,
    ]
}

/// Sample sizes from empty to a few MiB, most of them small enough to keep the test quick.
fn sample_len() -> impl Strategy<Value = usize> {
    prop_oneof![
        4 => 0usize..4096,
        4 => 4096usize..256 << 10,
        1 => (256usize << 10)..(3 << 20),
    ]
}

// ----- round trips -------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn samples_survive_loss_reordering_and_duplication(
        len in sample_len(),
        fs in frag_size(),
        loss in 0.0f64..0.6,
        dup in 0.0f64..0.3,
        reliable in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let mode = if reliable { Mode::reliable() } else { Mode::LastIsBest };
        let bytes = payload(len, seed);
        let samples = [Outgoing::new(3, 1, bytes.clone(), fs)];
        let mut r = Reassembler::default();
        let done = deliver_all(&mut r, &mut Link::new(seed, loss, dup), mode, &samples);
        prop_assert_eq!(done.len(), 1);
        prop_assert!(done[0].2 == bytes, "bytes differ");
        let stats = r.stats();
        prop_assert_eq!((stats.completed, stats.partials, stats.rejected.total()), (1, 0, 0));
    }

    #[test]
    fn interleaved_samples_of_several_writers_all_complete(
        lens in proptest::collection::vec(0usize..200_000, 1..6),
        fs in frag_size(),
        loss in 0.0f64..0.4,
        seed in any::<u64>(),
    ) {
        // Writers 0..n each one sample, and writer 100 several samples at once (reliable).
        let mut samples: Vec<Outgoing> = lens.iter().enumerate()
            .map(|(i, &len)| Outgoing::new(i as u32, 7, payload(len, seed ^ i as u64), fs))
            .collect();
        samples.extend(lens.iter().enumerate()
            .map(|(i, &len)| Outgoing::new(100, 10 + i as u64, payload(len / 2, !seed ^ i as u64), fs)));
        let mut r = Reassembler::default();
        let mode = Mode::KeepAll { max_partials: lens.len() };
        let done = deliver_all(&mut r, &mut Link::new(seed, loss, 0.1), mode, &samples);
        prop_assert_eq!(done.len(), samples.len());
        for s in &samples {
            let got = done.iter().find(|d| (d.0, d.1) == (s.writer, s.seq)).unwrap();
            prop_assert!(got.2 == s.bytes);
        }
        prop_assert_eq!(r.stats().partials, 0);
    }
}

// ----- last is best ------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// A best-effort writer sends samples 1..=n one after the other over a link that loses,
    /// duplicates and reorders across sample boundaries (a window of `spread` pieces). The
    /// reader delivers intact samples in increasing order, never one twice, and every sample
    /// it started and did not deliver was dropped as stale (or is the one still partial).
    #[test]
    fn last_is_best_delivers_increasing_intact_samples(
        n in 2u64..12,
        len in 1000usize..40_000,
        loss in 0.0f64..0.2,
        spread in 1usize..40,
        seed in any::<u64>(),
    ) {
        let samples: Vec<Outgoing> = (1..=n)
            .map(|seq| Outgoing::new(1, seq, payload(len, seed ^ seq), 512))
            .collect();
        let stream: Vec<(usize, u32)> = samples.iter().enumerate()
            .flat_map(|(s, o)| (0..o.split.count()).map(move |i| (s, i)))
            .collect();
        let mut rng = fastrand::Rng::with_seed(seed);
        let mut arrivals: Vec<(usize, (usize, u32))> = Vec::new();
        for (at, &p) in stream.iter().enumerate() {
            if rng.f64() >= loss {
                arrivals.push((at + rng.usize(0..spread), p));
            }
        }
        arrivals.sort_by_key(|a| a.0);
        let mut r = Reassembler::default();
        let now = Instant::now();
        let mut delivered = Vec::new();
        for (_, (s, index)) in arrivals {
            let piece = samples[s].piece(index);
            if let FragmentResult::Complete(bytes) = r.handle_fragment(now, 1, Mode::LastIsBest, &piece) {
                prop_assert!(bytes == samples[s].bytes, "sample {} corrupted", s + 1);
                delivered.push(samples[s].seq);
            }
        }
        prop_assert!(delivered.windows(2).all(|w| w[0] < w[1]), "{:?}", delivered);
        let stats = r.stats();
        prop_assert!(stats.partials <= 1);
        prop_assert_eq!(stats.completed, delivered.len() as u64);
        prop_assert!(stats.completed + stats.stale_dropped + stats.partials as u64 <= n);
        if loss == 0.0 && spread == 1 {
            prop_assert_eq!(delivered, (1..=n).collect::<Vec<_>>(), "in order, nothing lost");
        }
    }
}

#[test]
fn a_newer_sample_arriving_mid_way_drops_the_stale_partial() {
    let now = Instant::now();
    let mut r = Reassembler::<u32>::default();
    let old = Outgoing::new(9, 41, payload(10_000, 1), 1000);
    let new = Outgoing::new(9, 42, payload(10_000, 2), 1000);
    for i in 0..5 {
        assert_eq!(
            r.handle_fragment(now, 9, Mode::LastIsBest, &old.piece(i)),
            FragmentResult::Pending
        );
    }
    assert_eq!(
        r.missing(9, 41).unwrap().pieces().collect::<Vec<_>>(),
        [5, 6, 7, 8, 9]
    );
    assert_eq!(
        r.handle_fragment(now, 9, Mode::LastIsBest, &new.piece(0)),
        FragmentResult::Pending
    );
    assert_eq!(r.stats().stale_dropped, 1);
    assert_eq!(
        r.missing(9, 41),
        None,
        "the stale sample is no longer repaired"
    );
    for i in 5..10 {
        let late = r.handle_fragment(now, 9, Mode::LastIsBest, &old.piece(i));
        assert_eq!(late, FragmentResult::Ignored(Ignored::Stale));
    }
    let mut result = FragmentResult::Pending;
    for i in 1..10 {
        result = r.handle_fragment(now, 9, Mode::LastIsBest, &new.piece(i));
    }
    assert_eq!(result, FragmentResult::Complete(new.bytes.clone()));
    let stats = r.stats();
    assert_eq!(
        (stats.completed, stats.stale_pieces, stats.partials),
        (1, 5, 0)
    );
}

// ----- hostile pieces ----------------------------------------------------------------------

#[test]
fn hostile_pieces_are_rejected_and_counted() {
    let now = Instant::now();
    let config = ReassemblyConfig {
        max_sample_bytes: 1 << 20,
        ..Default::default()
    };
    let mut r = Reassembler::<u32>::new(config);
    let good = Outgoing::new(1, 1, payload(5000, 3), 1000);
    assert_eq!(
        r.handle_fragment(now, 1, Mode::reliable(), &good.piece(0)),
        FragmentResult::Pending
    );
    let chunk = [0u8; 1000];
    let hostile = [
        (
            Piece {
                frag_size: 0,
                ..good.piece(1)
            },
            Reject::BadFragSize,
        ),
        (
            Piece {
                frag_size: MIN_FRAG_SIZE - 1,
                ..good.piece(1)
            },
            Reject::BadFragSize,
        ),
        (
            Piece {
                frag_size: MAX_FRAG_SIZE + 1,
                ..good.piece(1)
            },
            Reject::BadFragSize,
        ),
        (
            Piece {
                index: u32::MAX,
                ..good.piece(1)
            },
            Reject::IndexOutOfRange,
        ),
        (
            Piece {
                index: 5,
                ..good.piece(1)
            },
            Reject::IndexOutOfRange,
        ),
        (
            Piece {
                chunk: &chunk[..999],
                ..good.piece(1)
            },
            Reject::WrongChunkLength,
        ),
        (
            Piece {
                chunk: &[],
                ..good.piece(4)
            },
            Reject::WrongChunkLength,
        ),
        (
            Piece {
                total_len: 5001,
                ..good.piece(1)
            },
            Reject::Inconsistent,
        ),
        (
            Piece {
                frag_size: 1250,
                chunk: &chunk[..1000],
                ..good.piece(1)
            },
            Reject::WrongChunkLength,
        ),
        (
            Piece {
                total_len: u32::MAX,
                ..good.piece(1)
            },
            Reject::TooLarge,
        ),
        (
            Piece {
                total_len: (1 << 20) + 1,
                ..good.piece(1)
            },
            Reject::TooLarge,
        ),
    ];
    for (piece, reason) in &hostile {
        let result = r.handle_fragment(now, 1, Mode::reliable(), piece);
        assert_eq!(result, FragmentResult::Rejected(*reason), "{piece:?}");
    }
    // A well-formed piece on its own (four pieces of 1250), but the sample is held as five
    // pieces of 1000.
    let chunk1250 = [0u8; 1250];
    let inconsistent = Piece {
        frag_size: 1250,
        chunk: &chunk1250,
        ..good.piece(0)
    };
    let result = r.handle_fragment(now, 1, Mode::reliable(), &inconsistent);
    assert_eq!(result, FragmentResult::Rejected(Reject::Inconsistent));
    let stats = r.stats();
    assert_eq!(stats.rejected.total(), hostile.len() as u64 + 1);
    assert_eq!(stats.rejected.get(Reject::BadFragSize), 3);
    assert_eq!(stats.rejected.get(Reject::Inconsistent), 2);
    let mut rest = FragmentResult::Pending;
    for i in 1..5 {
        rest = r.handle_fragment(now, 1, Mode::reliable(), &good.piece(i));
    }
    assert_eq!(
        rest,
        FragmentResult::Complete(good.bytes.clone()),
        "the sample is unharmed"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Arbitrary pieces from a handful of writers, both modes, time moving on: no panic, the
    /// budget holds, every piece is counted once, and everything goes when the writers do.
    #[test]
    fn arbitrary_pieces_never_break_the_bounds(
        pieces in proptest::collection::vec(
            (0u32..4, 0u64..6, any::<u32>(), 0u32..5000, any::<u32>(), 0usize..3000, any::<bool>(), 0u64..3),
            1..200,
        ),
    ) {
        let config = ReassemblyConfig {
            max_sample_bytes: 1 << 20,
            max_total_bytes: 2 << 20,
            partial_timeout: Duration::from_millis(2),
            spare_buffers: 1,
        };
        let mut r = Reassembler::new(config);
        let chunk = vec![0xA5u8; 3000];
        let start = Instant::now();
        let mut now = start;
        for (writer, seq, total_len, frag_size, index, chunk_len, reliable, dt) in pieces {
            // Mostly plausible claims (small total_len, index in range), sometimes absurd.
            let total_len = if total_len % 4 == 0 { total_len } else { total_len % 300_000 };
            let index = if index % 4 == 0 { index } else { index % 50 };
            let piece = Piece { seq, total_len, frag_size, index, chunk: &chunk[..chunk_len] };
            let mode = if reliable { Mode::KeepAll { max_partials: 2 } } else { Mode::LastIsBest };
            now += Duration::from_millis(dt);
            r.handle_timeout(now);
            if let FragmentResult::Complete(bytes) = r.handle_fragment(now, writer, mode, &piece) {
                prop_assert_eq!(bytes.len(), total_len as usize);
                r.recycle(bytes);
            }
            prop_assert!(r.stats().bytes_in_use <= config.max_total_bytes);
        }
        for writer in 0..4 {
            r.forget_writer(writer);
        }
        let stats = r.stats();
        prop_assert_eq!(stats.partials, 0);
        prop_assert!(stats.bytes_in_use <= 2 * (1 << 20) + 2 * 65_507, "only the spare remains");
    }
}

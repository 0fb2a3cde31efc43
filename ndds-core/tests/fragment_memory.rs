//! Reassembly memory stays within its budget under a flood of first pieces from many fake
//! writers, measured twice: by the reassembler's own `bytes_in_use`, and by a counting global
//! allocator that sees every byte the test thread really allocates.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::time::Instant;

use ndds_core::fragment::{
    FragmentResult, MAX_FRAG_SIZE, MIN_FRAG_SIZE, Mode, Piece, Reassembler, ReassemblyConfig,
};

// ----- counting allocator ------------------------------------------------------------------

/// The system allocator, counting per thread the bytes live now and their high-water mark.
struct Counting;

thread_local! {
    // Const-initialised and without destructors, so the allocator may touch them.
    static LIVE: Cell<usize> = const { Cell::new(0) };
    static HIGH: Cell<usize> = const { Cell::new(0) };
}

fn grew(bytes: usize) {
    let _ = LIVE.try_with(|live| {
        let now = live.get().saturating_add(bytes);
        live.set(now);
        let _ = HIGH.try_with(|high| high.set(high.get().max(now)));
    });
}

fn shrank(bytes: usize) {
    let _ = LIVE.try_with(|live| live.set(live.get().saturating_sub(bytes)));
}

// SAFETY: every call is forwarded unchanged to `System`; the counters only observe sizes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        grew(layout.size());
        // SAFETY: the caller upholds `alloc`'s contract, which `System` shares.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        grew(layout.size());
        // SAFETY: as for `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        shrank(layout.size());
        // SAFETY: `ptr` was allocated by `System` with `layout` (through this wrapper).
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // Counted as if the block moved: both live for a moment.
        grew(new_size);
        shrank(layout.size());
        // SAFETY: as for `dealloc`, and `new_size` is the caller's valid request.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static COUNTING: Counting = Counting;

/// Runs `f` and returns its result and the highest number of bytes this thread had allocated
/// during it beyond what was live before.
fn peak_during<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = LIVE.with(Cell::get);
    HIGH.with(|h| h.set(base));
    let result = f();
    let peak = HIGH.with(Cell::get) - base;
    (result, peak)
}

// ----- floods ------------------------------------------------------------------------------

/// Slack beyond the budget for what the reassembler does not charge: the few temporary
/// allocations of a single call (map node splits).
const SLACK: usize = 16 << 10;

/// `writers` fake writers each send one first piece claiming `total_len` bytes in pieces of
/// `frag_size`; returns the reassembler and the peak bytes allocated meanwhile.
fn flood(
    config: ReassemblyConfig,
    mode: Mode,
    writers: u64,
    total_len: u32,
    frag_size: u32,
) -> (Reassembler<u64>, usize) {
    let chunk = vec![0x5A; frag_size.min(total_len) as usize];
    let mut r = Reassembler::new(config);
    let now = Instant::now();
    let ((), peak) = peak_during(|| {
        for writer in 0..writers {
            let piece = Piece {
                seq: writer % 7,
                total_len,
                frag_size,
                index: 0,
                chunk: &chunk,
            };
            let result = r.handle_fragment(now, writer, mode, &piece);
            assert!(
                matches!(
                    result,
                    FragmentResult::Pending | FragmentResult::Complete(_)
                ),
                "{result:?}"
            );
            assert!(r.stats().bytes_in_use <= config.max_total_bytes);
        }
    });
    (r, peak)
}

fn assert_bounded(r: &Reassembler<u64>, peak: usize, config: &ReassemblyConfig, what: &str) {
    let stats = r.stats();
    eprintln!(
        "{what}: peak allocated {peak} B, peak charged {} B, budget {} B, {} partials, {} evicted",
        stats.peak_bytes_in_use, config.max_total_bytes, stats.partials, stats.evicted
    );
    assert!(
        stats.peak_bytes_in_use <= config.max_total_bytes,
        "{what}: charged"
    );
    assert!(
        peak <= config.max_total_bytes + SLACK,
        "{what}: allocated {peak} B"
    );
}

#[test]
fn a_flood_of_maximum_claims_stays_within_the_budget() {
    let config = ReassemblyConfig::default();
    let max = config.max_sample_bytes as u32;
    for (mode, frag_size) in [
        (Mode::LastIsBest, MAX_FRAG_SIZE),
        (Mode::reliable(), 1400),
        (Mode::LastIsBest, MIN_FRAG_SIZE),
    ] {
        let (r, peak) = flood(config, mode, 300, max, frag_size);
        let what = format!("16 MiB claims, {mode:?}, frag_size {frag_size}");
        assert_bounded(&r, peak, &config, &what);
        let stats = r.stats();
        assert!(stats.partials >= 3, "{what}: the budget is used");
        assert_eq!(stats.evicted, 300 - stats.partials as u64, "{what}");
    }
}

#[test]
fn a_flood_of_small_claims_from_many_writers_stays_within_the_budget() {
    let config = ReassemblyConfig {
        max_total_bytes: 4 << 20,
        ..ReassemblyConfig::default()
    };
    let (r, peak) = flood(config, Mode::LastIsBest, 200_000, 4096, 1024);
    assert_bounded(&r, peak, &config, "4 KiB claims, LastIsBest");
    assert!(r.stats().evicted > 190_000);
    let (r, peak) = flood(config, Mode::reliable(), 100_000, 65, 64);
    assert_bounded(&r, peak, &config, "65 B claims, KeepAll");
}

#[test]
fn a_flood_of_one_piece_samples_keeps_writer_records_within_the_budget() {
    // Each completes at once, leaving only the writer's record (its "last is best" floor).
    let config = ReassemblyConfig {
        max_total_bytes: 1 << 20,
        ..ReassemblyConfig::default()
    };
    let (r, peak) = flood(config, Mode::LastIsBest, 200_000, 100, 1024);
    assert_bounded(&r, peak, &config, "one-piece samples");
    assert_eq!(r.stats().completed, 200_000);
}

#[test]
fn a_genuine_sample_completes_after_a_flood() {
    let config = ReassemblyConfig {
        max_total_bytes: 8 << 20,
        ..ReassemblyConfig::default()
    };
    let (mut r, _) = flood(config, Mode::LastIsBest, 10_000, 4 << 20, 8192);
    let sample: Vec<u8> = (0..3_000_000u32).map(|i| (i % 251) as u8).collect();
    let now = Instant::now();
    let mut complete = None;
    for (index, chunk) in sample.chunks(8192).enumerate() {
        let piece = Piece {
            seq: 1,
            total_len: sample.len() as u32,
            frag_size: 8192,
            index: index as u32,
            chunk,
        };
        if let FragmentResult::Complete(bytes) =
            r.handle_fragment(now, u64::MAX, Mode::LastIsBest, &piece)
        {
            complete = Some(bytes);
        }
    }
    assert!(
        complete == Some(sample),
        "the genuine sample arrived intact"
    );
}

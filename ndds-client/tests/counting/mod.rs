//! A counting global allocator for the allocation tests: it counts the allocations made on the
//! threads that turned tracking on, and the bytes live on all threads, and forwards everything
//! to the system allocator.
//!
//! A test file that includes this module (`mod counting;`) gets it as its global allocator.

#![allow(dead_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};

struct Counting;

thread_local! {
    static TRACKED: Cell<bool> = const { Cell::new(false) };
}

/// Allocations counted so far, process-wide.
pub static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

/// Bytes allocated and not yet freed, on every thread (tracked or not).
pub static LIVE_BYTES: AtomicI64 = AtomicI64::new(0);

fn live(delta: i64) {
    LIVE_BYTES.fetch_add(delta, Ordering::Relaxed);
}

fn count() {
    if TRACKED.try_with(Cell::get).unwrap_or(false) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // Where a counted allocation comes from, with NDDS_ALLOC_BACKTRACE set (untracked
        // while the variable is read and the backtrace taken: both allocate).
        TRACKED.with(|t| t.set(false));
        if std::env::var_os("NDDS_ALLOC_BACKTRACE").is_some() {
            eprintln!(
                "counted allocation on {:?}:\n{}",
                std::thread::current().name(),
                std::backtrace::Backtrace::force_capture()
            );
        }
        TRACKED.with(|t| t.set(true));
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator; counting touches only
// an atomic and a const-initialised thread-local, neither of which allocates.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        live(layout.size() as i64);
        // SAFETY: the caller's contract is passed on.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        live(layout.size() as i64);
        // SAFETY: the caller's contract is passed on.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        live(new_size as i64 - layout.size() as i64);
        // SAFETY: the caller's contract is passed on.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        live(-(layout.size() as i64));
        // SAFETY: the caller's contract is passed on.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The counter is process-wide: the tests take turns.
pub fn turn() -> std::sync::MutexGuard<'static, ()> {
    static TURN: std::sync::Mutex<()> = std::sync::Mutex::new(());
    TURN.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Counts (or stops counting) this thread's allocations.
pub fn track(on: bool) {
    TRACKED.with(|t| t.set(on));
}

/// Allocations counted so far.
pub fn allocations() -> u64 {
    ALLOCATIONS.load(Ordering::Relaxed)
}

/// Allocations made on this thread while `work` runs.
pub fn allocations_during(work: impl FnOnce()) -> u64 {
    let before = allocations();
    track(true);
    work();
    track(false);
    allocations() - before
}

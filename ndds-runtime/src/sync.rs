//! The one lock helper of the runtime. Every mutex here guards data that stays consistent if
//! a holder panicked (maps and flags updated in one step; routines' panics are caught before
//! they reach a lock), so a poisoned lock is taken as it is.

use std::sync::{Mutex, MutexGuard, PoisonError};

/// Locks `mutex`, ignoring poisoning.
pub(crate) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

//! [`Mat`]: a shared handle to a named CSMat, as the linking database hands it out.
//!
//! Every module that names a CSMat holds a clone of the same handle, so a writer's values are
//! what its readers see. A handle may exist before its matrix does ("reference before
//! creation"): it is then *unbound*, an empty 0 × 0 matrix, until an output declaration or
//! [`Runtime::create_mat`](super::Runtime::create_mat) gives it a shape.
//!
//! # Two copies, and who takes a lock
//! Every CSMat has a *shared* copy behind a mutex: the one tools, other threads and modules of
//! other habitats read and write, one short lock per access. A CSMat that only the modules of
//! one habitat name (the runtime works this out at every install and removal) is also *owned*
//! by that habitat, which then keeps a *local* copy of it. While the habitat's sampler (its
//! thread, or the caller of `step`) runs a routine, [`read`](Mat::read) and
//! [`write`](Mat::write) reach the local copy with no lock at all: only the holder of the
//! habitat's list lock ever touches it.
//!
//! The habitat never waits for anyone to keep the copies together. After a sample it
//! publishes what its modules wrote into a sequence lock (plain atomic stores, no
//! read-modify-write), from which a reader elsewhere refreshes the shared copy under its
//! mutex; before a sample it takes in what others wrote to the shared copy since (their write
//! wins, for the whole matrix; `try_lock`, retried at the next boundary if busy). So others see
//! an owned CSMat as it was at the end of the habitat's last sample, and a value they write
//! reaches the habitat's modules at its next sample. CSMats that cross habitats keep the lock
//! per access.

use std::cell::{Cell, UnsafeCell};
use std::collections::HashSet;
use std::fmt;
use std::marker::PhantomData;
use std::ops::{Deref, DerefMut};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering, fence};
use std::sync::{Arc, Mutex, MutexGuard};

use super::csmat::CsMat;
use super::sync::{lock, try_lock};

thread_local! {
    /// The id of the habitat whose sampler this thread is right now (0: none).
    static SAMPLER: Cell<u64> = const { Cell::new(0) };
}

/// Marks the calling thread as the sampler of the list with `id` until the returned value
/// is dropped. Only a holder of that list's lock may call it.
pub(crate) fn as_sampler(id: u64) -> SamplerScope {
    SamplerScope(SAMPLER.with(|s| s.replace(id)))
}

/// Restores the thread's previous sampler when dropped.
pub(crate) struct SamplerScope(u64);

impl Drop for SamplerScope {
    fn drop(&mut self) {
        SAMPLER.with(|s| s.set(self.0));
    }
}

/// A shared handle to one named CSMat. Cloning is cheap (a reference count).
#[derive(Clone)]
pub struct Mat(Arc<Inner>);

struct Inner {
    name: Box<str>,
    bound: AtomicBool,
    shared: Mutex<Shared>,
    /// Bumped under `shared`'s lock by every write through it.
    writes: AtomicU64,
    /// The `writes` the owner has taken in (a shared copy with writes beyond it holds a
    /// value newer than the owner's, which publication must not overwrite).
    taken: AtomicU64,
    /// The id of the habitat that owns it, or 0. Set (from 0) only with `shared` locked, by
    /// a holder of the new owner's list lock; reset to 0 only by a holder of the owner's list
    /// lock (with `shared` locked, except when a list going away or an escaped guard cannot
    /// wait for it).
    owner: AtomicU64,
    /// Set when a guard outlived the routine that took it: the local copy is left to that
    /// guard, and no habitat owns this CSMat again.
    abandoned: AtomicBool,
    /// The owner's values after its last sample.
    published: Published,
    local: Local,
}

/// The shared copy, and which publication it reflects.
struct Shared {
    value: CsMat,
    /// `published.seq` when `value` was last refreshed from it.
    synced: u64,
    /// Where a publication is read before it is known whole (it goes into `value` only
    /// then): as long as the matrix, allocated again only when its shape changes.
    scratch: Vec<f64>,
}

/// A sequence lock written only by the owner: `seq` is odd while it writes.
struct Published {
    seq: AtomicU64,
    /// The values in the DMatrix's (column-major) order, as bits. The box is replaced only by
    /// the owner with `shared` locked; readers read it only with `shared` locked.
    values: UnsafeCell<Box<[AtomicU64]>>,
}

/// The owning habitat's copy. Touched only by the thread holding the owner's list lock.
struct Local {
    value: UnsafeCell<CsMat>,
    /// The last value published: a change of shape or fields is published through the
    /// shared copy's lock, values alone through `published`.
    last: UnsafeCell<CsMat>,
    /// Live guards: > 0 readers, -1 a writer.
    borrows: Cell<isize>,
    /// Written since it was last published.
    dirty: Cell<bool>,
    /// `writes` when the owner last took the shared copy in.
    seen: Cell<u64>,
}

// SAFETY: `Local`'s cells are reached only by a thread whose `SAMPLER` equals `owner` (or by
// `Owned`, under the same list lock). `owner` is set to a list's id (from 0) and back to 0
// only by a holder of that list's lock, and `SAMPLER` takes a list's id only while its lock is
// held, so at most one thread at a time touches `Local`, and the lock (with `owner`'s
// release/acquire for a change of owner) orders one holder's accesses before the next one's.
// A guard is tied to its `Mat`'s lifetime, not to the sampler's turn; one that outlives its
// routine (a `'static` handle's guard stashed away) is found alive after the routine by
// `Owned::publish`, which then abandons the CSMat to it: nobody else touches that `Local`
// again. `published.values` is read by the owner
// without a lock and by others with `shared` locked, and replaced only by the owner with
// `shared` locked. Everything else is atomics and a mutex.
unsafe impl Sync for Inner {}

impl Mat {
    /// An unbound placeholder named `name` (bound when a CSMat of that name is created).
    pub fn placeholder(name: &str) -> Self {
        Self(Arc::new(Inner {
            name: name.into(),
            bound: AtomicBool::new(false),
            shared: Mutex::new(Shared {
                value: CsMat::zeros(name, 0, 0),
                synced: 0,
                scratch: Vec::new(),
            }),
            writes: AtomicU64::new(0),
            taken: AtomicU64::new(0),
            owner: AtomicU64::new(0),
            abandoned: AtomicBool::new(false),
            published: Published {
                seq: AtomicU64::new(0),
                values: UnsafeCell::new(Box::new([])),
            },
            local: Local {
                value: UnsafeCell::new(CsMat::zeros(name, 0, 0)),
                last: UnsafeCell::new(CsMat::zeros(name, 0, 0)),
                borrows: Cell::new(0),
                dirty: Cell::new(false),
                seen: Cell::new(0),
            },
        }))
    }

    /// A handle to a matrix of its own, not registered anywhere (for tests and tools).
    pub fn standalone(value: CsMat) -> Self {
        let mat = Self::placeholder(value.name());
        mat.bind(value);
        mat
    }

    /// Gives the placeholder its matrix (keeping the handle's name).
    pub(crate) fn bind(&self, mut value: CsMat) {
        value.set_name(&*self.0.name);
        *self.write() = value;
        self.0.bound.store(true, Ordering::Release);
    }

    /// Makes it a placeholder again (an install that failed undoes what it created).
    pub(crate) fn unbind(&self) {
        let name = self.0.name.to_string();
        *self.write() = CsMat::zeros(name, 0, 0);
        self.0.bound.store(false, Ordering::Release);
    }

    /// The name it is registered under.
    pub fn name(&self) -> &str {
        &self.0.name
    }

    /// Whether the matrix exists yet (a placeholder is unbound and 0 × 0).
    pub fn is_bound(&self) -> bool {
        self.0.bound.load(Ordering::Acquire)
    }

    /// The matrix, for reading. In a routine of the habitat that owns it, no lock is taken;
    /// anywhere else the shared copy's lock is held until the guard drops (see the module
    /// doc). Hold a guard only inside one routine; a sample never sees another writer's
    /// half-written values.
    ///
    /// # Panics
    /// In a routine of its owning habitat, when the same routine holds a
    /// [`write`](Self::write) guard of this CSMat (elsewhere that deadlocks, as any mutex
    /// taken twice does).
    #[inline]
    pub fn read(&self) -> MatRef<'_> {
        let inner = &*self.0;
        let access = if inner.is_mine() {
            let borrows = inner.local.borrows.get();
            assert!(
                borrows >= 0,
                "CSMat `{}` is read while this routine writes it",
                inner.name
            );
            inner.local.borrows.set(borrows + 1);
            RefAccess::Local(inner)
        } else {
            RefAccess::Shared(inner.lock_shared())
        };
        MatRef {
            access,
            _not_send: PhantomData,
        }
    }

    /// The matrix, for writing: like [`read`](Self::read), without a lock in a routine of the
    /// owning habitat. Written elsewhere, an owned CSMat's new value reaches the owner's
    /// modules at its next sample boundary (and replaces what they wrote meanwhile).
    ///
    /// # Panics
    /// In a routine of its owning habitat, when the same routine holds another guard of this
    /// CSMat.
    #[inline]
    pub fn write(&self) -> MatMut<'_> {
        let inner = &*self.0;
        let access = if inner.is_mine() {
            assert!(
                inner.local.borrows.get() == 0,
                "CSMat `{}` is written while this routine holds another guard of it",
                inner.name
            );
            inner.local.borrows.set(-1);
            MutAccess::Local(inner)
        } else {
            let guard = inner.lock_shared();
            inner.writes.fetch_add(1, Ordering::Release);
            MutAccess::Shared(guard)
        };
        MatMut {
            access,
            _not_send: PhantomData,
        }
    }

    /// `(rows, cols)` now.
    pub fn shape(&self) -> (usize, usize) {
        self.read().shape()
    }

    /// A copy of the matrix now.
    pub fn snapshot(&self) -> CsMat {
        self.read().clone()
    }

    /// Element `(row, col)`, or `NaN` when out of range (convenient in tests and printing;
    /// use [`CsMat::get`] through [`read`](Self::read) for a checked access).
    pub fn value(&self, row: usize, col: usize) -> f64 {
        self.read().get(row, col).unwrap_or(f64::NAN)
    }

    /// Whether two handles name the same matrix.
    pub fn same(&self, other: &Mat) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }

    /// Whether a habitat owns it now (its modules reach it without a lock).
    pub fn is_owned(&self) -> bool {
        self.0.owner.load(Ordering::Acquire) != 0
    }

    fn key(&self) -> usize {
        Arc::as_ptr(&self.0) as usize
    }
}

impl Inner {
    #[inline]
    fn is_mine(&self) -> bool {
        let owner = self.owner.load(Ordering::Relaxed);
        owner != 0 && owner == SAMPLER.with(Cell::get)
    }

    /// Locks the shared copy, brought up to the owner's last publication.
    fn lock_shared(&self) -> MutexGuard<'_, Shared> {
        let mut shared = lock(&self.shared);
        self.refresh(&mut shared);
        shared
    }

    /// With `shared` locked: copies the (last) owner's last publication in, unless the
    /// shared copy holds a write the owner has not taken in (that one is newer). A CSMat
    /// never owned has no publication (`seq` and `synced` both 0).
    fn refresh(&self, shared: &mut Shared) {
        if self.taken.load(Ordering::Acquire) != self.writes.load(Ordering::Relaxed)
            || self.published.seq.load(Ordering::Acquire) == shared.synced
        {
            return;
        }
        // SAFETY: `shared` is locked, so the owner does not replace the box meanwhile.
        let values = unsafe { &*self.published.values.get() };
        let Shared {
            value,
            synced,
            scratch,
        } = shared;
        let target = value.matrix_mut().as_mut_slice();
        if target.len() != values.len() {
            // A change of shape is published through the shared copy itself.
            return;
        }
        scratch.resize(values.len(), 0.0);
        // The owner writes a publication in a few stores and never waits for us; should it be
        // preempted in the middle (a real-time reader on its CPU would never let it go on),
        // the shared copy stays as it is: whole, one publication older. So a publication is
        // read into `scratch`, and copied into the shared copy only once the sequence shows
        // it was not being written meanwhile.
        for spin in 0..256_u32 {
            let before = self.published.seq.load(Ordering::Acquire);
            if before & 1 == 0 {
                for (to, from) in scratch.iter_mut().zip(values.iter()) {
                    *to = f64::from_bits(from.load(Ordering::Relaxed));
                }
                fence(Ordering::Acquire);
                if self.published.seq.load(Ordering::Relaxed) == before {
                    target.copy_from_slice(scratch);
                    *synced = before;
                    return;
                }
            }
            if spin < 64 {
                std::hint::spin_loop();
            } else {
                std::thread::yield_now();
            }
        }
    }

    /// The local copy. Callers are the owner's sampler and hold no guard of this CSMat.
    #[allow(clippy::mut_from_ref)]
    unsafe fn local_mut(&self) -> &mut CsMat {
        // SAFETY: see `unsafe impl Sync for Inner`; the caller guarantees no other reference.
        unsafe { &mut *self.local.value.get() }
    }

    /// Owner, after a sample: publishes the local copy's values without a lock when shape and
    /// fields are as last published; otherwise through the shared copy (if nobody holds it).
    #[inline]
    fn publish(&self) {
        // SAFETY: the owner's sampler, between routines.
        let local = unsafe { &*self.local.value.get() };
        let last = unsafe { &*self.local.last.get() };
        if local.shape() == last.shape() && local.same_fields(last) {
            // SAFETY: only the owner replaces the box, and it is the owner.
            let values = unsafe { &*self.published.values.get() };
            let seq = self.published.seq.load(Ordering::Relaxed);
            self.published.seq.store(seq + 1, Ordering::Relaxed);
            fence(Ordering::Release);
            for (to, from) in values.iter().zip(local.matrix().as_slice()) {
                to.store(from.to_bits(), Ordering::Relaxed);
            }
            self.published.seq.store(seq + 2, Ordering::Release);
            self.local.dirty.set(false);
        } else if let Some(mut shared) = try_lock(&self.shared) {
            self.publish_locked(&mut shared);
        }
    }

    /// Owner, with `shared` locked: makes the shared copy and the publication the local
    /// copy, unless someone wrote the shared copy since the owner last took it in (theirs is
    /// newer and is taken in at the next boundary).
    fn publish_locked(&self, shared: &mut Shared) {
        if self.writes.load(Ordering::Relaxed) != self.local.seen.get() {
            return;
        }
        // SAFETY: the owner's sampler, between routines; `shared` is locked.
        let local = unsafe { &*self.local.value.get() };
        assign(&mut shared.value, local);
        assign(unsafe { &mut *self.local.last.get() }, local);
        self.republish(&shared.value);
        shared.synced = self.published.seq.load(Ordering::Relaxed);
        self.local.dirty.set(false);
    }

    /// Owner, with `shared` locked: the publication becomes `value` (its box resized if
    /// need be).
    fn republish(&self, value: &CsMat) {
        let data = value.matrix().as_slice();
        // SAFETY: the owner, with `shared` locked: no reader looks at the box.
        let values = unsafe { &mut *self.published.values.get() };
        if values.len() != data.len() {
            *values = data.iter().map(|v| AtomicU64::new(v.to_bits())).collect();
        } else {
            for (to, from) in values.iter().zip(data) {
                to.store(from.to_bits(), Ordering::Relaxed);
            }
        }
        self.published.seq.fetch_add(2, Ordering::Release);
    }

    /// Owner, with `shared` locked: takes the shared copy in (brought up to the last
    /// publication first, for a new owner after one that let go without the lock).
    fn take_in_locked(&self, shared: &mut Shared) {
        self.refresh(shared);
        // SAFETY: the owner's sampler (or the new owner), between routines.
        assign(unsafe { self.local_mut() }, &shared.value);
        assign(unsafe { &mut *self.local.last.get() }, &shared.value);
        self.republish(&shared.value);
        shared.synced = self.published.seq.load(Ordering::Relaxed);
        let writes = self.writes.load(Ordering::Relaxed);
        self.local.seen.set(writes);
        self.taken.store(writes, Ordering::Release);
        self.local.dirty.set(false);
    }
}

/// A read guard of a [`Mat`] (dereferences to the [`CsMat`]).
pub struct MatRef<'a> {
    access: RefAccess<'a>,
    /// The local copy belongs to this thread's turn as sampler.
    _not_send: PhantomData<*const ()>,
}

enum RefAccess<'a> {
    Local(&'a Inner),
    Shared(MutexGuard<'a, Shared>),
}

impl Deref for MatRef<'_> {
    type Target = CsMat;

    #[inline]
    fn deref(&self) -> &CsMat {
        match &self.access {
            // SAFETY: this thread is the owner's sampler and no writer lives (checked).
            RefAccess::Local(inner) => unsafe { &*inner.local.value.get() },
            RefAccess::Shared(guard) => &guard.value,
        }
    }
}

impl Drop for MatRef<'_> {
    #[inline]
    fn drop(&mut self) {
        if let RefAccess::Local(inner) = self.access {
            inner.local.borrows.set(inner.local.borrows.get() - 1);
        }
    }
}

/// A write guard of a [`Mat`] (dereferences mutably to the [`CsMat`]).
pub struct MatMut<'a> {
    access: MutAccess<'a>,
    _not_send: PhantomData<*const ()>,
}

enum MutAccess<'a> {
    Local(&'a Inner),
    Shared(MutexGuard<'a, Shared>),
}

impl Deref for MatMut<'_> {
    type Target = CsMat;

    #[inline]
    fn deref(&self) -> &CsMat {
        match &self.access {
            // SAFETY: this thread is the owner's sampler and this guard is the only one.
            MutAccess::Local(inner) => unsafe { &*inner.local.value.get() },
            MutAccess::Shared(guard) => &guard.value,
        }
    }
}

impl DerefMut for MatMut<'_> {
    #[inline]
    fn deref_mut(&mut self) -> &mut CsMat {
        match &mut self.access {
            // SAFETY: as in `deref`; `&mut self` keeps the reference unique.
            MutAccess::Local(inner) => unsafe { inner.local_mut() },
            MutAccess::Shared(guard) => &mut guard.value,
        }
    }
}

impl Drop for MatMut<'_> {
    #[inline]
    fn drop(&mut self) {
        if let MutAccess::Local(inner) = self.access {
            inner.local.borrows.set(0);
            inner.local.dirty.set(true);
        }
    }
}

impl fmt::Debug for Mat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (rows, cols) = self.shape();
        write!(f, "Mat({} {rows}x{cols}", self.name())?;
        if !self.is_bound() {
            f.write_str(" unbound")?;
        }
        f.write_str(")")
    }
}

/// The CSMats one habitat owns, and those it should own. Lives in the habitat's list; every
/// method is called by a holder of the list's lock, and only `release_all` (the list going
/// away) waits for a CSMat's lock: what cannot be done now is done at a later boundary.
pub(crate) struct Owned {
    id: u64,
    mats: Vec<Mat>,
    /// A new set to own, until every change is made.
    wanted: Option<Vec<Mat>>,
}

impl Owned {
    pub(crate) fn new() -> Self {
        static NEXT: AtomicU64 = AtomicU64::new(1);
        Self {
            id: NEXT.fetch_add(1, Ordering::Relaxed),
            mats: Vec::new(),
            wanted: None,
        }
    }

    /// The id `as_sampler` takes for this habitat.
    pub(crate) fn id(&self) -> u64 {
        self.id
    }

    /// How many CSMats it owns now.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.mats.len()
    }

    /// Asks to own exactly `mats` from now on (taken over and given back by `settle`).
    pub(crate) fn want(&mut self, mats: Vec<Mat>) {
        self.wanted = Some(mats);
        self.settle();
    }

    /// Gives everything back (the list is going away), without waiting: a shared copy that
    /// someone holds is refreshed from the last publication by its next reader.
    pub(crate) fn release_all(&mut self) {
        self.wanted = None;
        for mat in std::mem::take(&mut self.mats) {
            let inner = &*mat.0;
            match try_lock(&inner.shared) {
                Some(mut shared) => Self::give_back(inner, &mut shared),
                None => {
                    if inner.local.dirty.get() {
                        inner.publish();
                    }
                    inner.owner.store(0, Ordering::Release);
                }
            }
        }
    }

    fn give_back(inner: &Inner, shared: &mut Shared) {
        if inner.local.dirty.get() {
            inner.publish_locked(shared);
        } else {
            inner.refresh(shared);
        }
        inner.owner.store(0, Ordering::Release);
    }

    /// Makes what changes of ownership it can without waiting.
    pub(crate) fn settle(&mut self) {
        let Some(wanted) = self.wanted.take() else {
            return;
        };
        let keep: HashSet<usize> = wanted.iter().map(Mat::key).collect();
        let mut pending = false;
        self.mats.retain(|mat| {
            if keep.contains(&mat.key()) {
                return true;
            }
            match try_lock(&mat.0.shared) {
                Some(mut shared) => {
                    Self::give_back(&mat.0, &mut shared);
                    false
                }
                None => {
                    pending = true;
                    true
                }
            }
        });
        let have: HashSet<usize> = self.mats.iter().map(Mat::key).collect();
        for mat in &wanted {
            if have.contains(&mat.key()) {
                continue;
            }
            let inner = &*mat.0;
            if inner.abandoned.load(Ordering::Relaxed) {
                continue;
            }
            let Some(mut shared) = try_lock(&inner.shared) else {
                pending = true;
                continue;
            };
            // Another habitat may not have given it back yet.
            if inner
                .owner
                .compare_exchange(0, self.id, Ordering::Acquire, Ordering::Relaxed)
                .is_err()
            {
                pending = true;
                continue;
            }
            inner.take_in_locked(&mut shared);
            self.mats.push(mat.clone());
        }
        if pending {
            self.wanted = Some(wanted);
        }
    }

    /// Before a sample: takes in what others wrote to the shared copies.
    #[inline]
    pub(crate) fn take_in(&mut self) {
        if self.wanted.is_some() {
            self.settle();
        }
        for mat in &self.mats {
            let inner = &*mat.0;
            if inner.writes.load(Ordering::Acquire) != inner.local.seen.get()
                && let Some(mut shared) = try_lock(&inner.shared)
            {
                inner.take_in_locked(&mut shared);
            }
        }
    }

    /// After routines ran: publishes what they wrote. A guard still alive now outlived its
    /// routine (stashed with a `'static` handle): its CSMat is abandoned to it and shared
    /// from now on, so that no other thread ever touches the copy it points into.
    #[inline]
    pub(crate) fn publish(&mut self) {
        let mut escaped = false;
        for mat in &self.mats {
            let local = &mat.0.local;
            if local.borrows.get() != 0 {
                escaped = true;
            } else if local.dirty.get() {
                mat.0.publish();
            }
        }
        if escaped {
            self.abandon_escaped();
        }
    }

    #[cold]
    fn abandon_escaped(&mut self) {
        self.mats.retain(|mat| {
            let inner = &*mat.0;
            if inner.local.borrows.get() == 0 {
                return true;
            }
            tracing::error!(mat = %inner.name,
                "a guard of CSMat outlived the routine that took it; the CSMat is no longer owned by its habitat (its modules now take its lock)");
            inner.abandoned.store(true, Ordering::Relaxed);
            inner.owner.store(0, Ordering::Release);
            false
        });
    }
}

impl Drop for Owned {
    fn drop(&mut self) {
        self.release_all();
    }
}

/// `*to = from.clone()`, reusing `to`'s storage when the shapes and fields agree.
fn assign(to: &mut CsMat, from: &CsMat) {
    if to.shape() == from.shape() && to.same_fields(from) {
        to.matrix_mut().copy_from(from.matrix());
    } else {
        to.clone_from(from);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scalar(name: &str, value: f64) -> Mat {
        Mat::standalone(CsMat::from_row_slice(name, 1, 1, &[value]).expect("1x1"))
    }

    #[test]
    fn an_unowned_mat_is_the_shared_copy_everywhere() {
        let mat = scalar("u", 1.0);
        let sampler = as_sampler(7);
        mat.write().set(0, 0, 2.0).expect("in range");
        assert!(!mat.is_owned());
        drop(sampler);
        assert_eq!(mat.value(0, 0), 2.0);
    }

    #[test]
    fn the_owner_writes_locally_and_others_see_it_after_publish() {
        let mat = scalar("y", 1.0);
        let mut owned = Owned::new();
        owned.want(vec![mat.clone()]);
        assert!(mat.is_owned());
        {
            let _sampler = as_sampler(owned.id());
            owned.take_in();
            mat.write().set(0, 0, 5.0).expect("in range");
            assert_eq!(mat.value(0, 0), 5.0, "the owner reads its own write");
        }
        assert_eq!(mat.value(0, 0), 1.0, "others see the last published value");
        owned.publish();
        assert_eq!(mat.value(0, 0), 5.0);
    }

    #[test]
    fn a_foreign_write_reaches_the_owner_at_the_next_boundary_and_wins() {
        let mat = scalar("k", 1.0);
        let mut owned = Owned::new();
        owned.want(vec![mat.clone()]);
        {
            let _sampler = as_sampler(owned.id());
            owned.take_in();
            mat.write().set(0, 0, 3.0).expect("in range");
        }
        // Someone else writes during the sample: their value wins over the owner's.
        mat.write().set(0, 0, 9.0).expect("in range");
        owned.publish();
        assert_eq!(mat.value(0, 0), 9.0);
        let _sampler = as_sampler(owned.id());
        owned.take_in();
        assert_eq!(mat.value(0, 0), 9.0, "the owner sees the foreign write");
    }

    #[test]
    fn a_busy_shared_copy_delays_the_change_of_owner_without_waiting() {
        let mat = scalar("m", 4.0);
        let mut owned = Owned::new();
        let guard = mat.read();
        owned.want(vec![mat.clone()]);
        assert!(!mat.is_owned(), "taken over only when nobody holds it");
        drop(guard);
        owned.take_in();
        assert!(mat.is_owned());
        owned.want(Vec::new());
        assert!(!mat.is_owned(), "given back");
        assert_eq!(owned.len(), 0);
    }

    #[test]
    fn giving_back_publishes_the_last_local_value() {
        let mat = scalar("z", 0.0);
        let mut owned = Owned::new();
        owned.want(vec![mat.clone()]);
        {
            let _sampler = as_sampler(owned.id());
            mat.write().set(0, 0, 7.0).expect("in range");
        }
        drop(owned);
        assert!(!mat.is_owned());
        assert_eq!(mat.value(0, 0), 7.0);
    }

    #[test]
    fn two_habitats_never_own_one_mat() {
        let mat = scalar("x", 0.0);
        let mut first = Owned::new();
        let mut second = Owned::new();
        first.want(vec![mat.clone()]);
        second.want(vec![mat.clone()]);
        assert_eq!(second.len(), 0, "waits until the first gives it back");
        first.want(Vec::new());
        second.settle();
        assert_eq!(second.len(), 1);
    }

    #[test]
    fn readers_elsewhere_never_see_half_a_publication() {
        let mat = Mat::standalone(CsMat::zeros("q", 4, 4));
        let mut owned = Owned::new();
        owned.want(vec![mat.clone()]);
        let done = std::sync::Arc::new(AtomicBool::new(false));
        let readers: Vec<_> = (0..2)
            .map(|_| {
                let (mat, done) = (mat.clone(), done.clone());
                std::thread::spawn(move || {
                    let mut seen = 0.0_f64;
                    while !done.load(Ordering::Relaxed) {
                        let value = mat.snapshot();
                        let first = value.get(0, 0).expect("4x4");
                        assert!(
                            value.matrix().iter().all(|&v| v == first),
                            "a torn read: {value:?}"
                        );
                        assert!(first >= seen, "values go back: {first} after {seen}");
                        seen = first;
                    }
                    seen
                })
            })
            .collect();
        for sample in 1..=20_000 {
            let _sampler = as_sampler(owned.id());
            owned.take_in();
            mat.write().fill(f64::from(sample));
            owned.publish();
        }
        done.store(true, Ordering::Relaxed);
        for reader in readers {
            assert!(reader.join().expect("no torn read") <= 20_000.0);
        }
        assert_eq!(mat.value(3, 3), 20_000.0);
    }

    #[test]
    fn a_change_of_shape_is_published_too() {
        let mat = scalar("s", 1.0);
        let mut owned = Owned::new();
        owned.want(vec![mat.clone()]);
        {
            let _sampler = as_sampler(owned.id());
            *mat.write() = CsMat::zeros("other name", 2, 3);
            owned.publish();
        }
        assert_eq!(mat.shape(), (2, 3));
        assert_eq!(mat.snapshot().name(), "other name");
    }

    #[test]
    fn a_guard_that_outlives_its_routine_leaves_the_mat_to_it() {
        let mat: &'static Mat = Box::leak(Box::new(scalar("e", 1.0)));
        let mut owned = Owned::new();
        owned.want(vec![mat.clone()]);
        {
            let _sampler = as_sampler(owned.id());
            std::mem::forget(mat.write());
            owned.publish();
        }
        assert!(!mat.is_owned(), "abandoned to the escaped guard");
        owned.want(vec![mat.clone()]);
        assert!(!mat.is_owned(), "and never owned again");
        mat.write().set(0, 0, 2.0).expect("in range");
        assert_eq!(
            mat.value(0, 0),
            2.0,
            "the shared copy works as for any CSMat"
        );
    }

    #[test]
    #[should_panic(expected = "is read while this routine writes it")]
    fn reading_while_writing_in_the_owner_panics_instead_of_aliasing() {
        let mat = scalar("w", 0.0);
        let mut owned = Owned::new();
        owned.want(vec![mat.clone()]);
        let _sampler = as_sampler(owned.id());
        let _write = mat.write();
        let _read = mat.read();
    }
}

//! [`Mat`]: a shared handle to a named CSMat, as the linking database hands it out.
//!
//! Every module that names a CSMat holds a clone of the same handle, so a writer's values are
//! what its readers see. A handle may exist before its matrix does ("reference before
//! creation"): it is then *unbound*, an empty 0 × 0 matrix, until an output declaration or
//! [`Runtime::create_mat`](super::Runtime::create_mat) gives it a shape.

use std::fmt;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use super::csmat::CsMat;

/// A shared handle to one named CSMat. Cloning is cheap (a reference count).
#[derive(Clone)]
pub struct Mat(Arc<Cell>);

struct Cell {
    name: Box<str>,
    value: Mutex<CsMat>,
    bound: AtomicBool,
}

impl Mat {
    /// An unbound placeholder named `name` (bound when a CSMat of that name is created).
    pub fn placeholder(name: &str) -> Self {
        Self(Arc::new(Cell {
            name: name.into(),
            value: Mutex::new(CsMat::zeros(name, 0, 0)),
            bound: AtomicBool::new(false),
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

    /// Locks the matrix for reading. A module holds the lock only inside one entry routine;
    /// a sample never sees another writer's half-written values.
    pub fn read(&self) -> MutexGuard<'_, CsMat> {
        self.0.value.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Locks the matrix for writing (the same lock as [`read`](Self::read)).
    pub fn write(&self) -> MutexGuard<'_, CsMat> {
        self.read()
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

//! CSMat: ControlShell's named matrix of `f64`, whose rows and columns may carry a field name
//! and a unit.
//!
//! A [`CsMat`] is a name, a dense `nalgebra` matrix and, per axis, either no fields or exactly
//! one [`Field`] per row (column). Controllers address entries by position ([`CsMat::get`]) or
//! by field names ([`CsMat::get_named`]), and slice by names ([`CsMat::rows_named`]).
//!
//! ```
//! use ndds_runtime::CsMat;
//!
//! let gain = CsMat::from_rows("K", &[&[2.0, 0.0], &[0.0, 3.0]])?
//!     .with_row_fields([("tau1", "N.m"), ("tau2", "N.m")])?
//!     .with_col_fields([("q1", "rad"), ("q2", "rad")])?;
//! let state = CsMat::from_row_slice("x", 2, 1, &[0.5, -1.0])?
//!     .with_row_fields([("q1", "rad"), ("q2", "rad")])?;
//! let torque = gain.mul(&state)?;
//! assert_eq!(torque.get_named("tau2", "")?, -3.0);
//! # Ok::<(), ndds_runtime::MatError>(())
//! ```
//!
//! ## Unit rules
//! Units are compared as exact strings (`""` only equals `""`), and only where *both* operands
//! carry fields on the axes being compared; a matrix without fields is unitless and fits any.
//! - [`add`](CsMat::add), [`sub`](CsMat::sub) (and `_to`): equal shapes; on each axis where both
//!   operands carry fields, unit `i` of the left equals unit `i` of the right. The result takes
//!   the left operand's fields on each axis, or the right's where the left has none.
//! - [`mul`](CsMat::mul) (and `mul_to`): `lhs.cols == rhs.rows`; where `lhs` has column fields
//!   and `rhs` has row fields, lhs column unit `k` equals rhs row unit `k` (a gain matrix's
//!   column unit names the unit of the input it consumes). The product takes `lhs`'s row fields
//!   and `rhs`'s column fields.
//! - [`solve`](CsMat::solve) (`A x = b`): where `A` and `b` both have row fields, their units
//!   agree row by row; `x` takes `A`'s column fields as row fields and `b`'s column fields.
//! - [`transpose`](CsMat::transpose) and [`inverse`](CsMat::inverse) swap the axes' fields (the
//!   inverse consumes what `A` produces and produces what `A` consumes).
//! - [`scale`](CsMat::scale) keeps the fields.
//! - A mismatch is [`MatError::UnitMismatch`], naming both matrices, fields and units.
//!
//! The `_to` versions ([`add_to`](CsMat::add_to), [`sub_to`](CsMat::sub_to),
//! [`mul_to`](CsMat::mul_to)) check the same rules and `out`'s shape, then write values only:
//! they never allocate and leave `out`'s name and fields alone (set those once, e.g. with
//! [`set_fields_from`](CsMat::set_fields_from)).
//!
//! ## Result names
//! `a+b`, `a-b`, `a*b`, `k*a` (scale, `k` printed with `{}`), `a'` (transpose), `inv(a)`,
//! `a\b` (solve). Slices ([`rows_named`](CsMat::rows_named), [`cols_named`](CsMat::cols_named))
//! keep the source's name.
//!
//! ## Wire format
//! CSMat is a built-in topic type. It is the serde struct `CsMat` with fields `name: String`,
//! `rows: u32`, `cols: u32`, `data: Vec<f64>` (row-major), `row_fields: Vec<CsMatField>`,
//! `col_fields: Vec<CsMatField>`, where `CsMatField` is `{ name: String, unit: String }`.
//! Decoding checks `data.len() == rows * cols` (at most [`MAX_WIRE_ELEMENTS`]) and that each
//! field list is empty or has one entry per row (column). [`CsMat::decode_into`] decodes a
//! postcard sample into an existing matrix without allocating when the shape is unchanged.
//!
//! Nothing here panics on bad input: shapes, indices and units are checked before nalgebra is
//! called. Only [`CsMat::zeros`] and [`CsMat::resize`] can abort, like `Vec::with_capacity`,
//! when asked for more memory than exists.

mod decode;
mod display;
mod error;
mod named;
mod ops;
mod wire;

#[cfg(test)]
mod tests;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

pub use error::{Axis, MatError, UnitMismatch};
pub use wire::MAX_WIRE_ELEMENTS;

/// The name and unit of one row or column of a [`CsMat`]; either may be empty.
#[derive(Clone, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename = "CsMatField")]
pub struct Field {
    /// Field name, e.g. `q1`.
    pub name: String,
    /// Unit, e.g. `rad`.
    pub unit: String,
}

impl Field {
    fn new(name: &str, unit: &str) -> Self {
        Field {
            name: name.to_owned(),
            unit: unit.to_owned(),
        }
    }
}

/// A named matrix of `f64` whose rows and columns may carry [`Field`]s (see the module docs).
///
/// Invariant: `row_fields` is empty or has `rows()` entries, `col_fields` is empty or has
/// `cols()` entries.
#[derive(Clone, Debug, PartialEq)]
pub struct CsMat {
    name: String,
    m: DMatrix<f64>,
    row_fields: Vec<Field>,
    col_fields: Vec<Field>,
}

impl CsMat {
    /// A `rows` x `cols` matrix of zeros, without fields.
    ///
    /// Aborts like `Vec::with_capacity` if `rows * cols` values cannot be allocated.
    pub fn zeros(name: impl Into<String>, rows: usize, cols: usize) -> Self {
        Self::from_matrix(name.into(), DMatrix::zeros(rows, cols))
    }

    /// A `rows` x `cols` matrix from `data` in row-major order; `data.len()` must be
    /// `rows * cols` ([`MatError::DataLength`]).
    pub fn from_row_slice(
        name: impl Into<String>,
        rows: usize,
        cols: usize,
        data: &[f64],
    ) -> Result<Self, MatError> {
        let name = name.into();
        if rows.checked_mul(cols) != Some(data.len()) {
            return Err(MatError::DataLength {
                mat: name,
                rows,
                cols,
                got: data.len(),
            });
        }
        Ok(Self::from_matrix(
            name,
            DMatrix::from_row_slice(rows, cols, data),
        ))
    }

    /// A matrix from its rows, which must all have the same length ([`MatError::Ragged`]).
    /// No rows gives a 0 x 0 matrix.
    pub fn from_rows(name: impl Into<String>, rows: &[&[f64]]) -> Result<Self, MatError> {
        let name = name.into();
        let cols = rows.first().map_or(0, |row| row.len());
        if let Some((row, bad)) = rows.iter().enumerate().find(|(_, r)| r.len() != cols) {
            return Err(MatError::Ragged {
                mat: name,
                row,
                len: bad.len(),
                expected: cols,
            });
        }
        let m = DMatrix::from_fn(rows.len(), cols, |r, c| rows[r][c]);
        Ok(Self::from_matrix(name, m))
    }

    /// Wraps an existing nalgebra matrix, without fields.
    pub fn from_matrix(name: impl Into<String>, m: DMatrix<f64>) -> Self {
        CsMat {
            name: name.into(),
            m,
            row_fields: Vec::new(),
            col_fields: Vec::new(),
        }
    }

    /// Sets the row fields from `(name, unit)` pairs, one per row ([`MatError::FieldCount`]).
    pub fn with_row_fields<'a>(
        mut self,
        fields: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Result<Self, MatError> {
        self.row_fields = self.collect_fields(Axis::Row, fields)?;
        Ok(self)
    }

    /// Sets the column fields from `(name, unit)` pairs, one per column
    /// ([`MatError::FieldCount`]).
    pub fn with_col_fields<'a>(
        mut self,
        fields: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Result<Self, MatError> {
        self.col_fields = self.collect_fields(Axis::Col, fields)?;
        Ok(self)
    }

    fn collect_fields<'a>(
        &self,
        axis: Axis,
        fields: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Result<Vec<Field>, MatError> {
        let expected = self.len_of(axis);
        let mut out = Vec::new(); // not `with_capacity(expected)`: a dimension may be huge
        let mut got = 0usize;
        for (name, unit) in fields {
            got = got.saturating_add(1);
            if got <= expected {
                out.push(Field::new(name, unit));
            }
        }
        if got != expected {
            return Err(MatError::FieldCount {
                mat: self.name.clone(),
                axis,
                expected,
                got,
            });
        }
        Ok(out)
    }

    /// The matrix's name.
    #[inline]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Renames the matrix.
    pub fn set_name(&mut self, name: impl Into<String>) {
        self.name = name.into();
    }

    /// Number of rows.
    #[inline]
    pub fn rows(&self) -> usize {
        self.m.nrows()
    }

    /// Number of columns.
    #[inline]
    pub fn cols(&self) -> usize {
        self.m.ncols()
    }

    /// `(rows, cols)`.
    #[inline]
    pub fn shape(&self) -> (usize, usize) {
        self.m.shape()
    }

    /// True when the matrix has no elements (a dimension is 0).
    pub fn is_empty(&self) -> bool {
        self.m.is_empty()
    }

    /// The row fields: empty, or one per row.
    pub fn row_fields(&self) -> &[Field] {
        &self.row_fields
    }

    /// The column fields: empty, or one per column.
    pub fn col_fields(&self) -> &[Field] {
        &self.col_fields
    }

    /// The values.
    #[inline]
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.m
    }

    /// The values, mutably. The shape cannot change through this reference (use
    /// [`resize`](Self::resize)), so the fields stay consistent.
    #[inline]
    pub fn matrix_mut(&mut self) -> &mut DMatrix<f64> {
        &mut self.m
    }

    /// The value at (`row`, `col`), or [`MatError::OutOfRange`].
    #[inline]
    pub fn get(&self, row: usize, col: usize) -> Result<f64, MatError> {
        self.m
            .get((row, col))
            .copied()
            .ok_or_else(|| self.out_of_range(row, col))
    }

    /// Sets the value at (`row`, `col`), or [`MatError::OutOfRange`].
    #[inline]
    pub fn set(&mut self, row: usize, col: usize, value: f64) -> Result<(), MatError> {
        match self.m.get_mut((row, col)) {
            Some(slot) => {
                *slot = value;
                Ok(())
            }
            None => Err(self.out_of_range(row, col)),
        }
    }

    fn out_of_range(&self, row: usize, col: usize) -> MatError {
        MatError::OutOfRange {
            mat: self.name.clone(),
            row,
            col,
            shape: self.shape(),
        }
    }

    /// Sets every value to `value`.
    pub fn fill(&mut self, value: f64) {
        self.m.fill(value);
    }

    /// Whether `other` has the same name and fields (the values and shape aside).
    #[inline]
    pub(crate) fn same_fields(&self, other: &CsMat) -> bool {
        self.name == other.name
            && self.row_fields == other.row_fields
            && self.col_fields == other.col_fields
    }

    /// Copies `other`'s values (not its name or fields) into this matrix without allocating;
    /// the shapes must be equal ([`MatError::ShapeMismatch`]).
    pub fn copy_from(&mut self, other: &CsMat) -> Result<(), MatError> {
        if self.shape() != other.shape() {
            return Err(MatError::shape("copy_from", self, other));
        }
        self.m.copy_from(&other.m);
        Ok(())
    }

    /// Copies row-major values into this matrix without allocating; `row_major.len()` must be
    /// `rows * cols` ([`MatError::DataLength`]).
    pub fn copy_from_slice(&mut self, row_major: &[f64]) -> Result<(), MatError> {
        let (rows, cols) = self.shape();
        if rows.checked_mul(cols) != Some(row_major.len()) {
            return Err(MatError::DataLength {
                mat: self.name.clone(),
                rows,
                cols,
                got: row_major.len(),
            });
        }
        write_row_major(&mut self.m, row_major.iter().copied());
        Ok(())
    }

    /// Makes this a `rows` x `cols` matrix of zeros without fields (for placeholders that a
    /// sample or [`set_fields_from`](Self::set_fields_from) fills later). Reuses the storage
    /// when the shape is unchanged; aborts like [`zeros`](Self::zeros) on absurd sizes.
    pub fn resize(&mut self, rows: usize, cols: usize) {
        if self.shape() == (rows, cols) {
            self.m.fill(0.0);
        } else {
            self.m = DMatrix::zeros(rows, cols);
        }
        self.row_fields.clear();
        self.col_fields.clear();
    }

    /// Copies `other`'s field names and units, reusing this matrix's strings where it can. An
    /// axis whose length differs from `other`'s is left without fields.
    pub fn set_fields_from(&mut self, other: &CsMat) {
        if self.rows() == other.rows() {
            self.row_fields.clone_from(&other.row_fields);
        } else {
            self.row_fields.clear();
        }
        if self.cols() == other.cols() {
            self.col_fields.clone_from(&other.col_fields);
        } else {
            self.col_fields.clear();
        }
    }

    fn fields(&self, axis: Axis) -> &[Field] {
        match axis {
            Axis::Row => &self.row_fields,
            Axis::Col => &self.col_fields,
        }
    }

    fn len_of(&self, axis: Axis) -> usize {
        match axis {
            Axis::Row => self.rows(),
            Axis::Col => self.cols(),
        }
    }
}

/// Writes row-major `values` into `m`, stopping at whichever ends first.
fn write_row_major(m: &mut DMatrix<f64>, values: impl IntoIterator<Item = f64>) {
    let cols = m.ncols();
    if cols == 0 {
        return;
    }
    for (i, value) in values.into_iter().enumerate() {
        if let Some(slot) = m.get_mut((i / cols, i % cols)) {
            *slot = value;
        }
    }
}

//! What can go wrong with a [`CsMat`]: every message names the matrices involved.

use std::fmt;

use super::CsMat;

/// A matrix axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Axis {
    /// The rows (row fields).
    Row,
    /// The columns (column fields).
    Col,
}

impl Axis {
    /// The other axis.
    pub fn other(self) -> Axis {
        match self {
            Axis::Row => Axis::Col,
            Axis::Col => Axis::Row,
        }
    }
}

impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Axis::Row => "row",
            Axis::Col => "column",
        })
    }
}

/// An error of a [`CsMat`] operation.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum MatError {
    /// The operands' (or the output's) shapes do not fit the operation.
    #[error(
        "{op}: shapes do not fit: `{left}` is {}x{}, `{right}` is {}x{}",
        left_shape.0, left_shape.1, right_shape.0, right_shape.1
    )]
    ShapeMismatch {
        /// The operation (`add`, `mul_to`, ...).
        op: &'static str,
        /// The left operand's name (for an output check: the output's).
        left: String,
        /// Its shape.
        left_shape: (usize, usize),
        /// The right operand's name (for an output check: the result's, e.g. `a*b`).
        right: String,
        /// Its shape.
        right_shape: (usize, usize),
    },
    /// Fields that meet in an operation carry different units (see the module docs). Boxed
    /// to keep `MatError` small on the success path of every operation.
    #[error("{0}")]
    UnitMismatch(Box<UnitMismatch>),
    /// No row (column) of the matrix has this field name.
    #[error("`{mat}` has no {axis} field named `{field}`")]
    UnknownField {
        /// The matrix.
        mat: String,
        /// The axis searched.
        axis: Axis,
        /// The name asked for.
        field: String,
    },
    /// An index outside the matrix.
    #[error("({row}, {col}) is outside `{mat}`, which is {}x{}", shape.0, shape.1)]
    OutOfRange {
        /// The matrix.
        mat: String,
        /// The row asked for.
        row: usize,
        /// The column asked for.
        col: usize,
        /// The matrix's shape.
        shape: (usize, usize),
    },
    /// The matrix has no (finite) inverse.
    #[error("`{mat}` is singular (no finite inverse)")]
    Singular {
        /// The matrix.
        mat: String,
    },
    /// The operation needs a square matrix.
    #[error("{op}: `{mat}` is {}x{}, not square", shape.0, shape.1)]
    NotSquare {
        /// The operation.
        op: &'static str,
        /// The matrix.
        mat: String,
        /// Its shape.
        shape: (usize, usize),
    },
    /// A field list whose length is neither 0 nor the number of rows (columns).
    #[error("`{mat}` has {expected} {axis}s but {got} {axis} fields were given")]
    FieldCount {
        /// The matrix.
        mat: String,
        /// The axis.
        axis: Axis,
        /// The number of rows (columns).
        expected: usize,
        /// The number of fields given.
        got: usize,
    },
    /// A value list whose length is not `rows * cols`.
    #[error("`{mat}` is {rows}x{cols} but {got} values were given")]
    DataLength {
        /// The matrix.
        mat: String,
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
        /// The number of values given.
        got: usize,
    },
    /// A matrix too large for a CSMat sample (more than
    /// [`MAX_WIRE_ELEMENTS`](super::MAX_WIRE_ELEMENTS) values, or a dimension above `u32::MAX`).
    #[error(
        "`{mat}` is {rows}x{cols}: a CSMat sample carries at most {} values and dimensions up \
         to {}",
        super::MAX_WIRE_ELEMENTS,
        u32::MAX
    )]
    TooLarge {
        /// The matrix.
        mat: String,
        /// Rows.
        rows: u64,
        /// Columns.
        cols: u64,
    },
    /// Rows of different lengths.
    #[error("row {row} of `{mat}` has {len} values but row 0 has {expected}")]
    Ragged {
        /// The matrix.
        mat: String,
        /// The first row of another length.
        row: usize,
        /// Its length.
        len: usize,
        /// The length of row 0.
        expected: usize,
    },
    /// A sample that is not a valid CSMat encoding (truncated, bad UTF-8, inconsistent, ...).
    #[error("invalid CSMat sample: {0}")]
    Invalid(String),
}

/// The details of a [`MatError::UnitMismatch`].
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
#[error(
    "{op}: {axis} {index} of `{left}` is `{left_field}` [{left_unit}] but {} {index} of \
     `{right}` is `{right_field}` [{right_unit}]",
    right_axis(op, *axis)
)]
pub struct UnitMismatch {
    /// The operation (`add`, `mul_to`, ...).
    pub op: &'static str,
    /// The axis of the left operand (for `mul`, the right operand's is the other one).
    pub axis: Axis,
    /// The row or column index.
    pub index: usize,
    /// The left operand's name.
    pub left: String,
    /// The left operand's field name.
    pub left_field: String,
    /// The left operand's unit.
    pub left_unit: String,
    /// The right operand's name.
    pub right: String,
    /// The right operand's field name.
    pub right_field: String,
    /// The right operand's unit.
    pub right_unit: String,
}

fn right_axis(op: &str, axis: Axis) -> Axis {
    if op.starts_with("mul") {
        axis.other()
    } else {
        axis
    }
}

impl MatError {
    /// A [`MatError::ShapeMismatch`] between two matrices.
    pub(super) fn shape(op: &'static str, left: &CsMat, right: &CsMat) -> MatError {
        MatError::ShapeMismatch {
            op,
            left: left.name().to_owned(),
            left_shape: left.shape(),
            right: right.name().to_owned(),
            right_shape: right.shape(),
        }
    }
}

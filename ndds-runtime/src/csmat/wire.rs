//! The CSMat wire format (see the module docs of [`super`]): a hand-written `Serialize` that
//! neither clones nor allocates, and a validating `Deserialize`. Decoding in place is in
//! `decode`.

use nalgebra::DMatrix;
use serde::de;
use serde::ser::{self, SerializeSeq, SerializeStruct};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::{Axis, CsMat, Field, MatError};

/// The most values (`rows * cols`) a CSMat sample may carry: 2^24, i.e. 128 MiB of `f64`.
pub const MAX_WIRE_ELEMENTS: usize = 1 << 24;

/// Bytes one `f64` takes in postcard.
pub(super) const F64_BYTES: usize = 8;

pub(super) const FIELDS: &[&str] = &["name", "rows", "cols", "data", "row_fields", "col_fields"];
pub(super) const FIELD_FIELDS: &[&str] = &["name", "unit"];

impl Serialize for CsMat {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let (rows, cols) = wire_dims(&self.name, self.rows(), self.cols())
            .map_err(<S::Error as ser::Error>::custom)?;
        let mut st = serializer.serialize_struct("CsMat", FIELDS.len())?;
        st.serialize_field("name", self.name.as_str())?;
        st.serialize_field("rows", &rows)?;
        st.serialize_field("cols", &cols)?;
        st.serialize_field("data", &RowMajor(&self.m))?;
        st.serialize_field("row_fields", self.row_fields.as_slice())?;
        st.serialize_field("col_fields", self.col_fields.as_slice())?;
        st.end()
    }
}

/// The dimensions as sent, or [`MatError::TooLarge`].
fn wire_dims(name: &str, rows: usize, cols: usize) -> Result<(u32, u32), MatError> {
    let fits = rows
        .checked_mul(cols)
        .is_some_and(|n| n <= MAX_WIRE_ELEMENTS);
    match (u32::try_from(rows), u32::try_from(cols)) {
        (Ok(r), Ok(c)) if fits => Ok((r, c)),
        _ => Err(MatError::TooLarge {
            mat: name.to_owned(),
            rows: u64::try_from(rows).unwrap_or(u64::MAX),
            cols: u64::try_from(cols).unwrap_or(u64::MAX),
        }),
    }
}

/// The dimensions received, checked against [`MAX_WIRE_ELEMENTS`].
pub(super) fn local_dims(name: &str, rows: u32, cols: u32) -> Result<(usize, usize), MatError> {
    let too_large = || MatError::TooLarge {
        mat: name.to_owned(),
        rows: rows.into(),
        cols: cols.into(),
    };
    let r = usize::try_from(rows).map_err(|_| too_large())?;
    let c = usize::try_from(cols).map_err(|_| too_large())?;
    match r.checked_mul(c) {
        Some(n) if n <= MAX_WIRE_ELEMENTS => Ok((r, c)),
        _ => Err(too_large()),
    }
}

/// A matrix's values as a row-major sequence.
struct RowMajor<'a>(&'a DMatrix<f64>);

impl Serialize for RowMajor<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut seq = serializer.serialize_seq(Some(self.0.len()))?;
        for row in self.0.row_iter() {
            for value in row.iter() {
                seq.serialize_element(value)?;
            }
        }
        seq.end()
    }
}

/// The wire form, validated into a [`CsMat`] by `TryFrom`.
#[derive(Deserialize)]
#[serde(rename = "CsMat")]
pub(super) struct CsMatWire {
    pub(super) name: String,
    pub(super) rows: u32,
    pub(super) cols: u32,
    pub(super) data: Vec<f64>,
    pub(super) row_fields: Vec<Field>,
    pub(super) col_fields: Vec<Field>,
}

impl TryFrom<CsMatWire> for CsMat {
    type Error = MatError;

    fn try_from(wire: CsMatWire) -> Result<Self, MatError> {
        let (rows, cols) = local_dims(&wire.name, wire.rows, wire.cols)?;
        let mat = CsMat::from_row_slice(wire.name, rows, cols, &wire.data)?;
        check_field_count(&mat, Axis::Row, wire.row_fields.len())?;
        check_field_count(&mat, Axis::Col, wire.col_fields.len())?;
        Ok(CsMat {
            row_fields: wire.row_fields,
            col_fields: wire.col_fields,
            ..mat
        })
    }
}

fn check_field_count(mat: &CsMat, axis: Axis, got: usize) -> Result<(), MatError> {
    let expected = mat.len_of(axis);
    if got == 0 || got == expected {
        return Ok(());
    }
    Err(MatError::FieldCount {
        mat: mat.name.clone(),
        axis,
        expected,
        got,
    })
}

impl<'de> Deserialize<'de> for CsMat {
    /// Decodes and validates (see [`TryFrom<CsMatWire>`]).
    ///
    /// Exception: serde-reflection's tracer, which `TypeDescription::of` runs to learn the
    /// layout, feeds every sequence one element and every number 0, an inconsistent matrix.
    /// For that deserializer only, the traced value is replaced by an empty matrix instead of
    /// being rejected, so that CSMat gets a structural layout rather than an opaque one.
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let wire = CsMatWire::deserialize(deserializer)?;
        if is_layout_tracer::<D>() {
            return Ok(CsMat::zeros(wire.name, 0, 0));
        }
        CsMat::try_from(wire).map_err(de::Error::custom)
    }
}

/// True for serde-reflection's tracing deserializer (see `Deserialize for CsMat`).
fn is_layout_tracer<D>() -> bool {
    std::any::type_name::<D>().starts_with("serde_reflection::")
}

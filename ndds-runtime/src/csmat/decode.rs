//! [`CsMat::decode_into`]: decoding a postcard sample into an existing matrix with serde seeds,
//! so that a sample of the matrix's shape, name and fields allocates nothing.

use std::fmt;
use std::marker::PhantomData;

use nalgebra::DMatrix;
use serde::Deserializer;
use serde::de::{self, DeserializeSeed, SeqAccess, Visitor};

use super::wire::{F64_BYTES, FIELD_FIELDS, FIELDS, local_dims};
use super::{Axis, CsMat, Field, MatError};

impl CsMat {
    /// Decodes a postcard-encoded CSMat into `self` in place: values are copied without
    /// allocating when the sample's shape equals self's; names/fields are updated only if
    /// they differ (allocating then). A sample with another shape resizes self.
    ///
    /// The sample is validated like `Deserialize` does ([`MatError::DataLength`],
    /// [`MatError::FieldCount`], [`MatError::TooLarge`]; malformed bytes are
    /// [`MatError::Invalid`]). Bytes after the encoded matrix are ignored, as
    /// `postcard::from_bytes` does. On error `self` holds part of the sample but still keeps
    /// its invariants (a field list of the wrong length is dropped).
    pub fn decode_into(&mut self, bytes: &[u8]) -> Result<(), MatError> {
        let mut de = postcard::Deserializer::from_bytes(bytes);
        let mut target = InPlace {
            mat: self,
            max_elements: bytes.len() / F64_BYTES,
            error: None,
        };
        let result = (&mut target).deserialize(&mut de);
        let error = target.error.take();
        match result {
            Ok(()) => Ok(()),
            Err(err) => {
                self.drop_inconsistent_fields();
                Err(error.unwrap_or_else(|| MatError::Invalid(err.to_string())))
            }
        }
    }

    fn drop_inconsistent_fields(&mut self) {
        if !self.row_fields.is_empty() && self.row_fields.len() != self.rows() {
            self.row_fields.clear();
        }
        if !self.col_fields.is_empty() && self.col_fields.len() != self.cols() {
            self.col_fields.clear();
        }
    }
}

/// The seed and visitor of [`CsMat::decode_into`]. Postcard drops the text of custom errors,
/// so validation errors are kept in `error`.
struct InPlace<'m> {
    mat: &'m mut CsMat,
    /// The most values the sample's bytes can hold.
    max_elements: usize,
    error: Option<MatError>,
}

impl InPlace<'_> {
    fn fail<E: de::Error>(&mut self, err: MatError) -> E {
        let text = err.to_string();
        self.error = Some(err);
        E::custom(text)
    }
}

impl<'de> DeserializeSeed<'de> for &mut InPlace<'_> {
    type Value = ();

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<(), D::Error> {
        deserializer.deserialize_struct("CsMat", FIELDS, self)
    }
}

impl<'de> Visitor<'de> for &mut InPlace<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a CsMat struct")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        element(&mut seq, 0, StrInto(&mut self.mat.name))?;
        let rows: u32 = element(&mut seq, 1, PhantomData)?;
        let cols: u32 = element(&mut seq, 2, PhantomData)?;
        let (rows, cols) = local_dims(&self.mat.name, rows, cols).map_err(|e| self.fail(e))?;
        let n = rows * cols; // checked by local_dims
        // Allocate only what the sample's bytes can fill: a sample claiming more values than
        // that is read without storing them and refused below.
        if self.mat.shape() != (rows, cols) && n <= self.max_elements {
            self.mat.m = DMatrix::zeros(rows, cols);
        }
        let store = self.mat.shape() == (rows, cols);
        let got = element(
            &mut seq,
            3,
            Data {
                m: &mut self.mat.m,
                store,
            },
        )?;
        if got != n {
            let err = MatError::DataLength {
                mat: self.mat.name.clone(),
                rows,
                cols,
                got,
            };
            return Err(self.fail(err));
        }
        if !store {
            // Unreachable with postcard (n values take 8n bytes); kept so that no path accepts
            // a matrix that was not resized.
            let err = MatError::Invalid(format!("`{}` does not fit its bytes", self.mat.name));
            return Err(self.fail(err));
        }
        for (index, axis) in [(4, Axis::Row), (5, Axis::Col)] {
            let expected = self.mat.len_of(axis);
            let fields = match axis {
                Axis::Row => &mut self.mat.row_fields,
                Axis::Col => &mut self.mat.col_fields,
            };
            let got = element(&mut seq, index, Fields { fields, expected })?;
            if got != 0 && got != expected {
                let err = MatError::FieldCount {
                    mat: self.mat.name.clone(),
                    axis,
                    expected,
                    got,
                };
                return Err(self.fail(err));
            }
        }
        Ok(())
    }
}

/// The next element of a struct, decoded with `seed`; a missing one is an error.
fn element<'de, A: SeqAccess<'de>, S: DeserializeSeed<'de>>(
    seq: &mut A,
    index: usize,
    seed: S,
) -> Result<S::Value, A::Error> {
    seq.next_element_seed(seed)?
        .ok_or_else(|| de::Error::invalid_length(index, &"a CsMat struct of 6 fields"))
}

/// Decodes a string into an existing `String`, touching it only if the text differs.
struct StrInto<'a>(&'a mut String);

impl<'de> DeserializeSeed<'de> for StrInto<'_> {
    type Value = ();

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<(), D::Error> {
        deserializer.deserialize_str(self)
    }
}

impl Visitor<'_> for StrInto<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a string")
    }

    fn visit_str<E: de::Error>(self, text: &str) -> Result<(), E> {
        if self.0 != text {
            self.0.clear();
            self.0.push_str(text);
        }
        Ok(())
    }
}

/// Decodes the row-major values into a matrix of the announced shape (when `store`); yields
/// how many values the sample had (values beyond the matrix are counted, not stored).
struct Data<'a> {
    m: &'a mut DMatrix<f64>,
    store: bool,
}

impl<'de> DeserializeSeed<'de> for Data<'_> {
    type Value = usize;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<usize, D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for Data<'_> {
    type Value = usize;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence of f64")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<usize, A::Error> {
        let cols = self.m.ncols();
        let (mut count, mut row, mut col) = (0usize, 0usize, 0usize);
        while let Some(value) = seq.next_element::<f64>()? {
            if let Some(slot) = self.m.get_mut((row, col)).filter(|_| self.store) {
                *slot = value;
            }
            count += 1;
            col += 1;
            if col >= cols {
                col = 0;
                row += 1;
            }
        }
        Ok(count)
    }
}

/// Decodes a field list into an existing `Vec<Field>`, reusing its strings; yields how many
/// fields the sample had. Entries beyond `expected` are decoded into a scratch field (the
/// caller then rejects the sample).
struct Fields<'a> {
    fields: &'a mut Vec<Field>,
    expected: usize,
}

impl<'de> DeserializeSeed<'de> for Fields<'_> {
    type Value = usize;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<usize, D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for Fields<'_> {
    type Value = usize;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence of CsMatField")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<usize, A::Error> {
        let mut count = 0usize;
        let mut scratch = Field::default();
        loop {
            if count < self.expected && count == self.fields.len() {
                self.fields.push(Field::default());
            }
            let target = match self.fields.get_mut(count) {
                Some(field) if count < self.expected => field,
                _ => &mut scratch,
            };
            if seq.next_element_seed(FieldInto(target))?.is_none() {
                break;
            }
            count += 1;
        }
        self.fields.truncate(count.min(self.expected));
        Ok(count)
    }
}

/// Decodes one `CsMatField` into an existing [`Field`].
struct FieldInto<'a>(&'a mut Field);

impl<'de> DeserializeSeed<'de> for FieldInto<'_> {
    type Value = ();

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<(), D::Error> {
        deserializer.deserialize_struct("CsMatField", FIELD_FIELDS, self)
    }
}

impl<'de> Visitor<'de> for FieldInto<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a CsMatField struct")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let missing = |i| de::Error::invalid_length(i, &"a CsMatField struct of 2 fields");
        seq.next_element_seed(StrInto(&mut self.0.name))?
            .ok_or_else(|| missing(0))?;
        seq.next_element_seed(StrInto(&mut self.0.unit))?
            .ok_or_else(|| missing(1))?;
        Ok(())
    }
}

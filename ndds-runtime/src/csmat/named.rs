//! Access by field names: positions of named rows and columns, named entries and slices.

use super::{Axis, CsMat, Field, MatError};

impl CsMat {
    /// The value at the row and column with these field names (see
    /// [`row_index`](Self::row_index)).
    pub fn get_named(&self, row: &str, col: &str) -> Result<f64, MatError> {
        let (r, c) = (self.row_index(row)?, self.col_index(col)?);
        self.get(r, c)
    }

    /// Sets the value at the row and column with these field names.
    pub fn set_named(&mut self, row: &str, col: &str, value: f64) -> Result<(), MatError> {
        let (r, c) = (self.row_index(row)?, self.col_index(col)?);
        self.set(r, c, value)
    }

    /// The index of the first row whose field is named `name`.
    ///
    /// As a convenience for vectors, a matrix with exactly one row and no row fields accepts
    /// `""` for that row; otherwise an unknown name is [`MatError::UnknownField`].
    pub fn row_index(&self, name: &str) -> Result<usize, MatError> {
        self.index_of(Axis::Row, name)
    }

    /// The index of the first column whose field is named `name` (same rules as
    /// [`row_index`](Self::row_index), so `""` names the only column of a column vector).
    pub fn col_index(&self, name: &str) -> Result<usize, MatError> {
        self.index_of(Axis::Col, name)
    }

    fn index_of(&self, axis: Axis, name: &str) -> Result<usize, MatError> {
        let fields = self.fields(axis);
        if fields.is_empty() && name.is_empty() && self.len_of(axis) == 1 {
            return Ok(0);
        }
        fields
            .iter()
            .position(|f| f.name == name)
            .ok_or_else(|| MatError::UnknownField {
                mat: self.name.clone(),
                axis,
                field: name.to_owned(),
            })
    }

    /// A new matrix of the rows named `names`, in that order (repeats allowed), with their row
    /// fields, all columns and the column fields; it keeps this matrix's name.
    pub fn rows_named(&self, names: &[&str]) -> Result<CsMat, MatError> {
        let indices = self.indices(Axis::Row, names)?;
        Ok(CsMat {
            name: self.name.clone(),
            m: self.m.select_rows(indices.iter()),
            row_fields: pick(&self.row_fields, &indices),
            col_fields: self.col_fields.clone(),
        })
    }

    /// A new matrix of the columns named `names`, in that order (repeats allowed), with their
    /// column fields, all rows and the row fields; it keeps this matrix's name.
    pub fn cols_named(&self, names: &[&str]) -> Result<CsMat, MatError> {
        let indices = self.indices(Axis::Col, names)?;
        Ok(CsMat {
            name: self.name.clone(),
            m: self.m.select_columns(indices.iter()),
            row_fields: self.row_fields.clone(),
            col_fields: pick(&self.col_fields, &indices),
        })
    }

    fn indices(&self, axis: Axis, names: &[&str]) -> Result<Vec<usize>, MatError> {
        names.iter().map(|name| self.index_of(axis, name)).collect()
    }
}

/// The fields at `indices`, or none when `fields` is empty.
fn pick(fields: &[Field], indices: &[usize]) -> Vec<Field> {
    if fields.is_empty() {
        return Vec::new();
    }
    indices
        .iter()
        .filter_map(|&i| fields.get(i).cloned())
        .collect()
}

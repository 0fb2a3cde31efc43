//! Arithmetic on [`CsMat`]: allocating versions and the `_to` versions controllers call every
//! sample, which write into an existing output and never allocate. The unit rules are in the
//! module docs of [`super`].

use nalgebra::DMatrix;

use super::{Axis, CsMat, Field, MatError, UnitMismatch};

impl CsMat {
    /// `self + rhs`, named `a+b`: equal shapes and matching units on both axes.
    pub fn add(&self, rhs: &CsMat) -> Result<CsMat, MatError> {
        self.check_elementwise("add", rhs)?;
        Ok(self.elementwise_result(format!("{}+{}", self.name, rhs.name), &self.m + &rhs.m, rhs))
    }

    /// `self - rhs`, named `a-b`: equal shapes and matching units on both axes.
    pub fn sub(&self, rhs: &CsMat) -> Result<CsMat, MatError> {
        self.check_elementwise("sub", rhs)?;
        Ok(self.elementwise_result(format!("{}-{}", self.name, rhs.name), &self.m - &rhs.m, rhs))
    }

    /// `self * rhs`, named `a*b`: `self.cols() == rhs.rows()` and self's column units equal
    /// rhs's row units. The product has self's row fields and rhs's column fields.
    pub fn mul(&self, rhs: &CsMat) -> Result<CsMat, MatError> {
        self.check_mul("mul", rhs)?;
        Ok(CsMat {
            name: format!("{}*{}", self.name, rhs.name),
            m: &self.m * &rhs.m,
            row_fields: self.row_fields.clone(),
            col_fields: rhs.col_fields.clone(),
        })
    }

    /// `k * self`, named `k*a`, with the same fields.
    pub fn scale(&self, k: f64) -> CsMat {
        CsMat {
            name: format!("{k}*{}", self.name),
            m: &self.m * k,
            row_fields: self.row_fields.clone(),
            col_fields: self.col_fields.clone(),
        }
    }

    /// The transpose, named `a'`: row fields become column fields and vice versa.
    pub fn transpose(&self) -> CsMat {
        CsMat {
            name: format!("{}'", self.name),
            m: self.m.transpose(),
            row_fields: self.col_fields.clone(),
            col_fields: self.row_fields.clone(),
        }
    }

    /// The inverse, named `inv(a)`, with the axes' fields swapped.
    /// [`MatError::NotSquare`], or [`MatError::Singular`] when no finite inverse exists.
    pub fn inverse(&self) -> Result<CsMat, MatError> {
        self.check_square("inverse")?;
        let m = self
            .m
            .clone()
            .try_inverse()
            .filter(all_finite)
            .ok_or_else(|| self.singular())?;
        Ok(CsMat {
            name: format!("inv({})", self.name),
            m,
            row_fields: self.col_fields.clone(),
            col_fields: self.row_fields.clone(),
        })
    }

    /// Solves `self * x = b` by LU decomposition; `x` is named `a\b`, has self's column fields
    /// as row fields and b's column fields. Self must be square ([`MatError::NotSquare`]) with
    /// as many rows as `b` and the same row units, and not singular ([`MatError::Singular`]).
    pub fn solve(&self, b: &CsMat) -> Result<CsMat, MatError> {
        self.check_square("solve")?;
        if self.rows() != b.rows() {
            return Err(MatError::shape("solve", self, b));
        }
        self.check_units("solve", Axis::Row, b, Axis::Row)?;
        if self.rows() == 0 {
            // nalgebra's LU solve underflows an index on 0x0 systems.
            return Ok(CsMat {
                name: format!("{}\\{}", self.name, b.name),
                m: DMatrix::zeros(0, b.cols()),
                row_fields: Vec::new(),
                col_fields: b.col_fields.clone(),
            });
        }
        let m = self
            .m
            .clone()
            .lu()
            .solve(&b.m)
            .filter(all_finite)
            .ok_or_else(|| self.singular())?;
        Ok(CsMat {
            name: format!("{}\\{}", self.name, b.name),
            m,
            row_fields: self.col_fields.clone(),
            col_fields: b.col_fields.clone(),
        })
    }

    /// `out = self + rhs` without allocating; also checks `out`'s shape. Leaves `out`'s name
    /// and fields alone.
    pub fn add_to(&self, rhs: &CsMat, out: &mut CsMat) -> Result<(), MatError> {
        self.check_elementwise("add_to", rhs)?;
        self.check_out("add_to", '+', rhs, out, self.shape())?;
        self.m.add_to(&rhs.m, &mut out.m);
        Ok(())
    }

    /// `out = self - rhs` without allocating; also checks `out`'s shape. Leaves `out`'s name
    /// and fields alone.
    pub fn sub_to(&self, rhs: &CsMat, out: &mut CsMat) -> Result<(), MatError> {
        self.check_elementwise("sub_to", rhs)?;
        self.check_out("sub_to", '-', rhs, out, self.shape())?;
        self.m.sub_to(&rhs.m, &mut out.m);
        Ok(())
    }

    /// `out = self * rhs` without allocating, at any size; also checks `out`'s shape. Leaves
    /// `out`'s name and fields alone.
    ///
    /// The product is computed column by column with `gemv` (nalgebra's `gemm` hands large
    /// products to matrixmultiply, which allocates packing buffers on every call).
    pub fn mul_to(&self, rhs: &CsMat, out: &mut CsMat) -> Result<(), MatError> {
        self.check_mul("mul_to", rhs)?;
        self.check_out("mul_to", '*', rhs, out, (self.rows(), rhs.cols()))?;
        for (j, mut column) in out.m.column_iter_mut().enumerate() {
            column.gemv(1.0, &self.m, &rhs.m.column(j), 0.0);
        }
        Ok(())
    }

    fn check_elementwise(&self, op: &'static str, rhs: &CsMat) -> Result<(), MatError> {
        if self.shape() != rhs.shape() {
            return Err(MatError::shape(op, self, rhs));
        }
        self.check_units(op, Axis::Row, rhs, Axis::Row)?;
        self.check_units(op, Axis::Col, rhs, Axis::Col)
    }

    fn check_mul(&self, op: &'static str, rhs: &CsMat) -> Result<(), MatError> {
        if self.cols() != rhs.rows() {
            return Err(MatError::shape(op, self, rhs));
        }
        self.check_units(op, Axis::Col, rhs, Axis::Row)
    }

    fn check_square(&self, op: &'static str) -> Result<(), MatError> {
        if self.rows() != self.cols() {
            return Err(MatError::NotSquare {
                op,
                mat: self.name.clone(),
                shape: self.shape(),
            });
        }
        Ok(())
    }

    /// Checks that `out` has the result's shape `want`.
    fn check_out(
        &self,
        op: &'static str,
        symbol: char,
        rhs: &CsMat,
        out: &CsMat,
        want: (usize, usize),
    ) -> Result<(), MatError> {
        if out.shape() == want {
            return Ok(());
        }
        Err(MatError::ShapeMismatch {
            op,
            left: out.name.clone(),
            left_shape: out.shape(),
            right: format!("{}{symbol}{}", self.name, rhs.name),
            right_shape: want,
        })
    }

    /// Unit `i` of self's `axis` must equal unit `i` of rhs's `rhs_axis` where both have
    /// fields. The lengths are equal once the shapes are checked.
    fn check_units(
        &self,
        op: &'static str,
        axis: Axis,
        rhs: &CsMat,
        rhs_axis: Axis,
    ) -> Result<(), MatError> {
        let pairs = self.fields(axis).iter().zip(rhs.fields(rhs_axis));
        match pairs.enumerate().find(|(_, (l, r))| l.unit != r.unit) {
            None => Ok(()),
            Some((index, (l, r))) => Err(MatError::UnitMismatch(Box::new(UnitMismatch {
                op,
                axis,
                index,
                left: self.name.clone(),
                left_field: l.name.clone(),
                left_unit: l.unit.clone(),
                right: rhs.name.clone(),
                right_field: r.name.clone(),
                right_unit: r.unit.clone(),
            }))),
        }
    }

    fn elementwise_result(&self, name: String, m: DMatrix<f64>, rhs: &CsMat) -> CsMat {
        CsMat {
            name,
            m,
            row_fields: either(&self.row_fields, &rhs.row_fields),
            col_fields: either(&self.col_fields, &rhs.col_fields),
        }
    }

    fn singular(&self) -> MatError {
        MatError::Singular {
            mat: self.name.clone(),
        }
    }
}

fn either(first: &[Field], second: &[Field]) -> Vec<Field> {
    if first.is_empty() { second } else { first }.to_vec()
}

fn all_finite(m: &DMatrix<f64>) -> bool {
    m.iter().all(|v| v.is_finite())
}

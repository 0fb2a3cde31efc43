//! What saturation and dead band share: an element-wise map of an input with per-element,
//! tunable bounds.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, Shape};

use crate::mats::{copy_in, copy_out, distinct, matrix_param};
use crate::params::failed;

/// An element-wise map of `input` to `output` with per-element bounds (saturation, dead band).
/// The bounds are the tunable parameter CSMats `"{module}.lower"` and `"{module}.upper"`
/// (columns of one value, or one per element).
pub(super) struct Bounded {
    input: Mat,
    output: Mat,
    lower: Mat,
    upper: Mat,
    lo: DMatrix<f64>,
    hi: DMatrix<f64>,
    value: DMatrix<f64>,
}

impl Bounded {
    /// `lower`/`upper` are named `names` in messages (`width` when the dead band was given one).
    pub(super) fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        (lower, upper): (&[f64], &[f64]),
        names: (&str, &str),
    ) -> Result<Self, ModuleError> {
        distinct(&[input, output])?;
        let n = lower.len().max(upper.len());
        for (name, values) in [(names.0, lower), (names.1, upper)] {
            if values.is_empty() || (values.len() != 1 && values.len() != n) {
                return Err(ModuleError::param(
                    name,
                    format!("has {} values; expected one value or {n}", values.len()),
                ));
            }
            if values.iter().any(|x| x.is_nan()) {
                return Err(ModuleError::param(name, "NaN is not a bound"));
            }
        }
        for i in 0..n {
            let (lo, hi) = (lower[i % lower.len()], upper[i % upper.len()]);
            if lo > hi {
                return Err(ModuleError::param(
                    names.0,
                    format!("{lo} is above `{}` {hi} (element {i})", names.1),
                ));
            }
        }
        let input = b.input(input, Shape::Any);
        if input.is_bound() && n > 1 && n != input.shape().0 * input.shape().1 {
            return Err(ModuleError::param(
                names.0,
                format!(
                    "has {n} values but input `{}` has {} elements",
                    input.name(),
                    input.shape().0 * input.shape().1
                ),
            ));
        }
        let lo = DMatrix::from_column_slice(lower.len(), 1, lower);
        let hi = DMatrix::from_column_slice(upper.len(), 1, upper);
        Ok(Self {
            output: b.output_same_as(output, &input),
            input,
            lower: matrix_param(b, "lower", &lo),
            upper: matrix_param(b, "upper", &hi),
            lo,
            hi,
            value: DMatrix::zeros(0, 0),
        })
    }

    /// Reads the bounds and the input, then maps each element with `map(u, lower, upper)`.
    pub(super) fn apply(&mut self, map: impl Fn(f64, f64, f64) -> f64) -> RoutineResult {
        copy_in(&self.lower, &mut self.lo);
        copy_in(&self.upper, &mut self.hi);
        copy_in(&self.input, &mut self.value);
        let count = self.value.len();
        for (mat, values) in [(&self.lower, &self.lo), (&self.upper, &self.hi)] {
            if values.is_empty() || (values.len() != 1 && values.len() != count) {
                return Err(failed(format!(
                    "bound `{}` has {} values but input `{}` has {count} elements",
                    mat.name(),
                    values.len(),
                    self.input.name()
                )));
            }
        }
        let (lower, upper) = (&self.lo, &self.hi);
        for (i, u) in self.value.iter_mut().enumerate() {
            let (lo, hi) = (lower[i % lower.len()], upper[i % upper.len()]);
            if lo.is_nan() || hi.is_nan() || lo > hi {
                return Err(failed(format!(
                    "`{}` {lo} is not ≤ `{}` {hi} (element {i})",
                    self.lower.name(),
                    self.upper.name()
                )));
            }
            *u = map(*u, lo, hi);
        }
        copy_out(&self.output, &self.value)
    }
}

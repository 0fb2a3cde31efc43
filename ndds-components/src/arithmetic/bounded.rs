//! What saturation and dead band share: bounds checked against each other and the input, and
//! an element-wise map of the input with per-element, tunable bounds.

use nalgebra::DMatrix;

use ndds_runtime::{Mat, ModuleError, RoutineResult};

use crate::mats::{copy_in, copy_out};
use crate::params::failed;

/// Refuses bounds that cannot be applied to `input`: each list has one value or `n` (the
/// longer one's count, which must be `input`'s element count when it exists), no NaN (an
/// infinite bound is no bound), `lower ≤ upper` element by element. `lower`/`upper` are named
/// `names` in messages (`width` when the dead band was given one).
pub(super) fn check(
    input: &Mat,
    (lower, upper): (&[f64], &[f64]),
    names: (&str, &str),
) -> Result<(), ModuleError> {
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
    let elements = input.shape().0 * input.shape().1;
    if input.is_bound() && n > 1 && n != elements {
        return Err(ModuleError::param(
            names.0,
            format!(
                "has {n} values but input `{}` has {elements} elements",
                input.name()
            ),
        ));
    }
    Ok(())
}

/// The CSMats of a bounded map: `input` mapped into `output` with the tunable bounds
/// `lower` and `upper` (columns of one value, or one per element).
pub(super) struct Mats<'a> {
    pub(super) input: &'a Mat,
    pub(super) output: &'a Mat,
    pub(super) lower: &'a Mat,
    pub(super) upper: &'a Mat,
}

/// A bounded map's copies of its CSMats (allocated at the first sample).
#[derive(Default)]
pub(super) struct Buffers {
    lo: DMatrix<f64>,
    hi: DMatrix<f64>,
    value: DMatrix<f64>,
}

impl Buffers {
    /// Reads the bounds and the input, then maps each element with `map(u, lower, upper)`.
    pub(super) fn apply(
        &mut self,
        mats: &Mats<'_>,
        map: impl Fn(f64, f64, f64) -> f64,
    ) -> RoutineResult {
        copy_in(mats.lower, &mut self.lo);
        copy_in(mats.upper, &mut self.hi);
        copy_in(mats.input, &mut self.value);
        let count = self.value.len();
        for (mat, values) in [(mats.lower, &self.lo), (mats.upper, &self.hi)] {
            if values.is_empty() || (values.len() != 1 && values.len() != count) {
                return Err(failed(format!(
                    "bound `{}` has {} values but input `{}` has {count} elements",
                    mat.name(),
                    values.len(),
                    mats.input.name()
                )));
            }
        }
        let (lower, upper) = (&self.lo, &self.hi);
        for (i, u) in self.value.iter_mut().enumerate() {
            let (lo, hi) = (lower[i % lower.len()], upper[i % upper.len()]);
            if lo.is_nan() || hi.is_nan() || lo > hi {
                return Err(failed(format!(
                    "`{}` {lo} is not ≤ `{}` {hi} (element {i})",
                    mats.lower.name(),
                    mats.upper.name()
                )));
            }
            *u = map(*u, lo, hi);
        }
        copy_out(mats.output, &self.value)
    }
}

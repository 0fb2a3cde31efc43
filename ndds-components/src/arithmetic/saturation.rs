//! `saturation`: each element clamped to tunable bounds.

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::bounded::{Buffers, Mats, check};

/// Clamps each element to [lower, upper] (NaN stays NaN).
#[derive(Component)]
#[component(name = "saturation", finish = Self::check_bounds)]
pub struct Saturation {
    /// u, any shape
    #[input]
    input: Mat,
    /// y, the shape of u
    #[output(same_as = input)]
    output: Mat,
    /// lower bound, one value or one per element (CSMat `<module>.lower`, tunable)
    #[param(tunable, column, finite = false)]
    lower: Mat,
    /// upper bound (≥ lower), one value or one per element (`<module>.upper`, tunable)
    #[param(tunable, column, finite = false)]
    upper: Mat,
    buffers: Buffers,
}

impl Saturation {
    /// Clamps `input` into `output` (same shape). `lower` and `upper` have one value, or one
    /// per element; `lower ≤ upper` element by element (infinite bounds are allowed).
    pub fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        lower: &[f64],
        upper: &[f64],
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("input", input)
            .with("output", output)
            .with("lower", lower.to_vec())
            .with("upper", upper.to_vec());
        Self::build(b, &params)
    }

    /// Refuses bounds that are NaN, crossed, or of the wrong count for the input.
    fn check_bounds(&mut self, _: &mut Binder<'_>) -> Result<(), ModuleError> {
        let lower: Vec<f64> = self.lower.read().matrix().iter().copied().collect();
        let upper: Vec<f64> = self.upper.read().matrix().iter().copied().collect();
        check(&self.input, (&lower, &upper), ("lower", "upper"))
    }
}

impl SampleModule for Saturation {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let mats = Mats {
            input: &self.input,
            output: &self.output,
            lower: &self.lower,
            upper: &self.upper,
        };
        self.buffers.apply(&mats, |u, lo, hi| {
            if u < lo {
                lo
            } else if u > hi {
                hi
            } else {
                u
            }
        })
    }
}

/// Registers `saturation`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Saturation>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::arithmetic::testing::once;
    use crate::testing::{TestResult, assert_refuses, refusal, runtime};

    #[test]
    fn saturation_clamps_each_element() -> TestResult {
        let rt = runtime(100.0, &[("u", &[-5.0, 0.5, 5.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("lower", -1.0)
            .with("upper", vec![1.0, 1.0, 2.0]);
        assert_eq!(once(&rt, "saturation", params)?, [-1.0, 0.5, 2.0]);
        // The bounds are tunable; bounds that cross fail the sample, naming them.
        rt.mat("m.lower").write().set(0, 0, -10.0)?;
        let h = rt.habitat("h");
        h.step()?;
        assert_eq!(rt.mat("y").read().matrix().as_slice(), [-5.0, 0.5, 2.0]);
        rt.mat("m.lower").write().set(0, 0, 1.5)?;
        h.step()?;
        assert_eq!(h.stats().module_errors, 1);
        Ok(())
    }

    #[test]
    fn bad_bounds_are_refused_by_name() -> TestResult {
        let rt = runtime(100.0, &[("u", &[0.0, 0.0])])?;
        let bounds = |lower: f64, upper: f64| {
            Params::new()
                .with("input", "u")
                .with("output", "y")
                .with("lower", lower)
                .with("upper", upper)
        };
        let err = refusal(&rt, "saturation", &bounds(2.0, 1.0));
        assert_refuses(&err, "lower", &["above `upper`"]);
        let params = bounds(0.0, 1.0).with("lower", vec![0.0, 0.0, 0.0]);
        let err = refusal(&rt, "saturation", &params);
        assert_refuses(&err, "lower", &["`u` has 2 elements"]);
        let err = refusal(&rt, "saturation", &bounds(0.0, f64::NAN));
        assert_refuses(&err, "upper", &["NaN is not a bound"]);
        Ok(())
    }
}

//! `dead_band`: zero inside tunable bounds, continuous outside.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::bounded::{Buffers, Mats, check};
use crate::mats::matrix_param;

/// 0 inside [lower, upper], u − upper above it and u − lower below it (continuous). Give
/// `width` (the band [−width, width]) or both `lower` and `upper`; the edges are the tunable
/// CSMats `<module>.lower` and `<module>.upper`.
///
/// NaN stays NaN.
#[derive(Component)]
#[component(name = "dead_band", finish = Self::declare_edges)]
pub struct DeadBand {
    /// u, any shape
    #[input]
    input: Mat,
    /// y, the shape of u
    #[output(same_as = input)]
    output: Mat,
    /// half-width (≥ 0) of the band [−width, width]; one value or one per element
    #[param(finite = false)]
    _width: Option<Vec<f64>>,
    /// lower edge of the band, with `upper` instead of `width`
    #[param(default_doc = "−width", finite = false)]
    _lower: Option<Vec<f64>>,
    /// upper edge of the band (≥ lower), with `lower` instead of `width`
    #[param(default_doc = "width", finite = false)]
    _upper: Option<Vec<f64>>,
    /// The edges `[lower, upper]` as given (from `width` or from `lower` and `upper`), checked.
    #[state(init = edges(&input, _width.as_deref(), _lower.as_deref(), _upper.as_deref())?)]
    edges: [DMatrix<f64>; 2],
    /// The tunable `<module>.lower` and `<module>.upper`, declared once the edges are known.
    #[state(init = Mat::placeholder("lower"))]
    lower: Mat,
    #[state(init = Mat::placeholder("upper"))]
    upper: Mat,
    buffers: Buffers,
}

/// The edges from `width`, or from `lower` and `upper` (exactly one of the two ways).
fn edges(
    input: &Mat,
    width: Option<&[f64]>,
    lower: Option<&[f64]>,
    upper: Option<&[f64]>,
) -> Result<[DMatrix<f64>; 2], ModuleError> {
    let column = |values: &[f64]| DMatrix::from_column_slice(values.len(), 1, values);
    match (width, lower, upper) {
        (Some(width), None, None) => {
            if let Some(bad) = width.iter().find(|w| w.is_nan() || **w < 0.0) {
                return Err(ModuleError::param("width", format!("{bad} is not ≥ 0")));
            }
            let lower: Vec<f64> = width.iter().map(|w| -w).collect();
            check(input, (&lower, width), ("width", "width"))?;
            Ok([column(&lower), column(width)])
        }
        (None, Some(lower), Some(upper)) => {
            check(input, (lower, upper), ("lower", "upper"))?;
            Ok([column(lower), column(upper)])
        }
        (Some(_), _, _) => Err(ModuleError::param(
            "width",
            "give `width` or `lower` and `upper`, not both",
        )),
        (None, None, None) => Err(ModuleError::param(
            "width",
            "missing: give `width`, or `lower` and `upper`",
        )),
        (None, Some(_), None) => Err(ModuleError::param(
            "upper",
            "missing: `lower` needs `upper`",
        )),
        (None, None, Some(_)) => Err(ModuleError::param(
            "lower",
            "missing: `upper` needs `lower`",
        )),
    }
}

impl DeadBand {
    /// The dead band `[lower, upper]` (one value, or one per element; `lower ≤ upper`).
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

    /// The symmetric dead band `[−width, width]` (`width ≥ 0`, one value or one per element).
    pub fn symmetric(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        width: &[f64],
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("input", input)
            .with("output", output)
            .with("width", width.to_vec());
        Self::build(b, &params)
    }

    /// The tunable edges, created from the edges given unless they exist.
    fn declare_edges(&mut self, b: &mut Binder<'_>) -> Result<(), ModuleError> {
        let [lower, upper] = &self.edges;
        self.lower = matrix_param(b, "lower", lower);
        self.upper = matrix_param(b, "upper", upper);
        Ok(())
    }
}

impl SampleModule for DeadBand {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let mats = Mats {
            input: &self.input,
            output: &self.output,
            lower: &self.lower,
            upper: &self.upper,
        };
        self.buffers.apply(&mats, |u, lo, hi| {
            if u > hi {
                u - hi
            } else if u < lo {
                u - lo
            } else if u.is_nan() {
                u
            } else {
                0.0
            }
        })
    }
}

/// Registers `dead_band`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<DeadBand>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::arithmetic::testing::once;
    use crate::testing::{TestResult, assert_refuses, refusal, runtime};

    #[test]
    fn dead_band_is_zero_inside_and_continuous_outside() -> TestResult {
        let rt = runtime(100.0, &[("u", &[-3.0, -1.0, -0.5, 0.0, 0.5, 1.0, 3.0])])?;
        let params = Params::new().with("input", "u").with("width", 1.0);
        let out = once(&rt, "dead_band", params)?;
        assert_eq!(out, [-2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]);

        let rt = runtime(100.0, &[("u", &[-3.0, -1.0, 0.0, 2.0, 3.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("lower", -1.0)
            .with("upper", 2.0);
        assert_eq!(once(&rt, "dead_band", params)?, [-2.0, 0.0, 0.0, 0.0, 1.0]);
        Ok(())
    }

    #[test]
    fn a_band_given_twice_half_or_negative_is_refused_by_name() -> TestResult {
        let rt = runtime(100.0, &[("u", &[0.0, 0.0])])?;
        let base = Params::new().with("input", "u").with("output", "y");
        let params = base
            .clone()
            .with("lower", -1.0)
            .with("upper", 1.0)
            .with("width", 1.0);
        assert_refuses(&refusal(&rt, "dead_band", &params), "width", &["not both"]);
        let params = base.clone().with("width", -1.0);
        assert_refuses(&refusal(&rt, "dead_band", &params), "width", &["not ≥ 0"]);
        let params = base.clone().with("lower", -1.0);
        assert_refuses(&refusal(&rt, "dead_band", &params), "upper", &["missing"]);
        let params = base.clone().with("upper", 1.0);
        assert_refuses(&refusal(&rt, "dead_band", &params), "lower", &["missing"]);
        assert_refuses(&refusal(&rt, "dead_band", &base), "width", &["missing"]);
        Ok(())
    }
}

//! `dead_band`: zero inside tunable bounds, continuous outside.

use ndds_runtime::{Binder, ModuleError, Params, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use super::bounded::Bounded;

/// Dead band: `output` is 0 while `lower ≤ input ≤ upper`, `input − upper` above and
/// `input − lower` below, so it is continuous (NaN stays NaN).
pub struct DeadBand(Bounded);

impl DeadBand {
    /// The dead band `[lower, upper]` (one value, or one per element; `lower ≤ upper`).
    pub fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        lower: &[f64],
        upper: &[f64],
    ) -> Result<Self, ModuleError> {
        Bounded::new(b, input, output, (lower, upper), ("lower", "upper")).map(Self)
    }

    /// The symmetric dead band `[−width, width]` (`width ≥ 0`, one value or one per element).
    pub fn symmetric(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        width: &[f64],
    ) -> Result<Self, ModuleError> {
        if let Some(bad) = width.iter().find(|w| w.is_nan() || **w < 0.0) {
            return Err(ModuleError::param("width", format!("{bad} is not ≥ 0")));
        }
        let lower: Vec<f64> = width.iter().map(|w| -w).collect();
        Bounded::new(b, input, output, (&lower, width), ("width", "width")).map(Self)
    }
}

impl SampleModule for DeadBand {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        self.0.apply(|u, lo, hi| {
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

const DEAD_BAND: ComponentSpec = ComponentSpec {
    name: "dead_band",
    summary: "0 inside [lower, upper], u − upper above it and u − lower below it (continuous). \
              Give `width` (the band [−width, width]) or both `lower` and `upper`; the edges \
              are the tunable CSMats `<module>.lower` and `<module>.upper`.",
    params: &[
        P::required("input", K::Input, "u, any shape"),
        P::required("output", K::Output, "y, the shape of u"),
        P::optional(
            "width",
            K::Numbers,
            "none",
            "half-width (≥ 0) of the band [−width, width]; one value or one per element",
        ),
        P::optional(
            "lower",
            K::Numbers,
            "−width",
            "lower edge of the band, with `upper` instead of `width`",
        ),
        P::optional(
            "upper",
            K::Numbers,
            "width",
            "upper edge of the band (≥ lower), with `lower` instead of `width`",
        ),
    ],
};

/// A dead band from `width`, or from `lower` and `upper`.
fn dead_band(b: &mut Binder<'_>, p: &Params) -> Result<DeadBand, ModuleError> {
    let (input, output) = (p.text("input")?, p.text("output")?);
    match (p.has("width"), p.has("lower"), p.has("upper")) {
        (true, false, false) => DeadBand::symmetric(b, input, output, &p.numbers("width")?),
        (false, true, true) => {
            DeadBand::new(b, input, output, &p.numbers("lower")?, &p.numbers("upper")?)
        }
        (true, _, _) => Err(ModuleError::param(
            "width",
            "give `width` or `lower` and `upper`, not both",
        )),
        (false, false, false) => Err(ModuleError::param(
            "width",
            "missing: give `width`, or `lower` and `upper`",
        )),
        (false, true, false) => Err(ModuleError::param(
            "upper",
            "missing: `lower` needs `upper`",
        )),
        (false, false, true) => Err(ModuleError::param(
            "lower",
            "missing: `upper` needs `lower`",
        )),
    }
}

/// Registers `dead_band`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add_with(&DEAD_BAND, dead_band);
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

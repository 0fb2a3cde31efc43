//! `gain`: a tunable scalar gain.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule, Shape};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use crate::mats::{copy_in, copy_out, distinct, scalar_param};

/// `y = k·u`, element by element (`k` is the 1 × 1 parameter `"{module}.k"`).
pub struct Gain {
    input: Mat,
    output: Mat,
    k: Mat,
    value: DMatrix<f64>,
}

impl Gain {
    /// Reads `input`, writes `output` (same shape).
    pub fn new(b: &mut Binder<'_>, input: &str, output: &str, k: f64) -> Result<Self, ModuleError> {
        distinct(&[input, output])?;
        let input_mat = b.input(input, Shape::Any);
        Ok(Self {
            output: b.output_same_as(output, &input_mat),
            input: input_mat,
            k: scalar_param(b, "k", k),
            value: DMatrix::zeros(0, 0),
        })
    }
}

impl SampleModule for Gain {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let k = self.k.read().get(0, 0)?;
        copy_in(&self.input, &mut self.value);
        self.value.scale_mut(k);
        copy_out(&self.output, &self.value)
    }
}

const GAIN: ComponentSpec = ComponentSpec {
    name: "gain",
    summary: "y = k·u, element by element.",
    params: &[
        P::required("input", K::Input, "u, any shape"),
        P::required("output", K::Output, "y, the shape of u"),
        P::optional(
            "k",
            K::Number,
            "1",
            "the gain (a 1 × 1 CSMat `<module>.k`, tunable)",
        ),
    ],
};

/// Registers `gain`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add(&GAIN, |b, p| {
        Gain::new(
            b,
            p.text("input")?,
            p.text("output")?,
            p.number_or("k", 1.0)?,
        )
    });
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::arithmetic::testing::once;
    use crate::testing::{TestResult, refusal, runtime};

    #[test]
    fn gain_scales_each_element_by_its_tunable_k() -> TestResult {
        let rt = runtime(100.0, &[("u", &[1.0, -2.0])])?;
        let params = Params::new().with("input", "u").with("k", 3.0);
        assert_eq!(once(&rt, "gain", params)?, [3.0, -6.0]);
        rt.mat("m.k").write().set(0, 0, 0.5)?;
        rt.habitat("h").step()?;
        assert_eq!(rt.mat("y").read().matrix().as_slice(), [0.5, -1.0]);
        let params = Params::new().with("input", "u").with("output", "u");
        let err = refusal(&runtime(100.0, &[])?, "gain", &params).to_string();
        assert!(err.contains("`u`") && err.contains("twice"), "{err}");
        Ok(())
    }
}

//! `gain`: a tunable scalar gain.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::mats::{copy_in, copy_out};

/// y = k·u, element by element.
#[derive(Component)]
#[component(name = "gain")]
pub struct Gain {
    /// u, any shape
    #[input]
    input: Mat,
    /// y, the shape of u
    #[output(same_as = input)]
    output: Mat,
    /// the gain (a 1 × 1 CSMat `<module>.k`, tunable)
    #[param(tunable, default = 1.0)]
    k: Mat,
    value: DMatrix<f64>,
}

impl Gain {
    /// Reads `input`, writes `output` (same shape); `k` is the tunable parameter
    /// `"{module}.k"`.
    pub fn new(b: &mut Binder<'_>, input: &str, output: &str, k: f64) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("input", input)
            .with("output", output)
            .with("k", k);
        Self::build(b, &params)
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

/// Registers `gain`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Gain>();
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

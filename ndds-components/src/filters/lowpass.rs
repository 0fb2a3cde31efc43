//! `lowpass`: a first-order low-pass filter.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::mats::{copy_in, copy_out};

/// First-order low-pass y += a·(u − y), a = dt/(tau + dt); starts from its input when
/// enabled.
///
/// `tau` in seconds is the 1 × 1 parameter `"{module}.tau"` (a value tuned below 0 acts as 0).
/// Enabling it starts from the current input (no step).
#[derive(Component)]
#[component(name = "lowpass")]
pub struct LowPass {
    /// u, any shape
    #[input]
    input: Mat,
    /// y, the shape of u
    #[output(same_as = input)]
    output: Mat,
    /// time constant, a CSMat `<module>.tau`
    #[param(tunable, unit = "s", min = 0)]
    tau: Mat,
    state: DMatrix<f64>,
    value: DMatrix<f64>,
    primed: bool,
}

impl LowPass {
    /// Filters `input` into `output` (same shape).
    pub fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        tau: f64,
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("input", input)
            .with("output", output)
            .with("tau", tau);
        Self::build(b, &params)
    }

    fn prime(&mut self) {
        copy_in(&self.input, &mut self.state);
        self.primed = true;
    }
}

impl SampleModule for LowPass {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        if !self.primed {
            self.prime();
        }
        let tau = self.tau.read().get(0, 0)?.max(0.0);
        let a = ctx.dt() / (tau + ctx.dt());
        copy_in(&self.input, &mut self.value);
        if self.value.shape() != self.state.shape() {
            self.prime();
        }
        self.state.zip_apply(&self.value, |s, u| *s += a * (u - *s));
        copy_out(&self.output, &self.state)
    }

    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        self.prime();
        Ok(())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.primed = false;
        Ok(())
    }
}

/// Registers `lowpass`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<LowPass>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::testing::{TestResult, runtime};

    #[test]
    fn lowpass_starts_from_its_input_and_converges_at_its_rate() -> TestResult {
        // a = dt/(tau + dt) = 0.01/0.1: the distance to the input shrinks by 0.9 a sample.
        let rt = runtime(100.0, &[("u", &[1.0])])?;
        let lowpass = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("tau", 0.09);
        rt.install_component("h", "lp", "lowpass", &lowpass)?;
        let h = rt.habitat("h");
        h.start()?;
        for _ in 0..5 {
            h.step()?;
            assert_eq!(rt.mat("y").value(0, 0), 1.0, "enabled without a step");
        }
        rt.mat("u").write().set(0, 0, 2.0)?;
        for k in 1..20 {
            h.step()?;
            let (y, expected) = (rt.mat("y").value(0, 0), 2.0 - 0.9f64.powi(k));
            assert!(
                (y - expected).abs() < 1e-12,
                "y = {y} after {k}, expected {expected}"
            );
        }
        assert_eq!(h.stats().module_errors, 0);
        Ok(())
    }
}

//! `pd`: PD control on the measurement.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::mats::{copy_in, copy_out, shape_error};

/// PD on the measurement: u = kp·(r − y) − kd·ẏ (the derivative of the measurement, so
/// reference steps do not kick).
///
/// Element by element; `kp` and `kd` are the 1 × 1 parameters `"{module}.kp"` and
/// `"{module}.kd"`. Enabling it takes the current measurement as the previous one, so it
/// starts without a derivative jump.
#[derive(Component)]
#[component(name = "pd")]
pub struct Pd {
    /// y (n × 1)
    #[input]
    measured: Mat,
    /// r (n × 1)
    #[input(same_as = measured)]
    reference: Mat,
    /// u (n × 1)
    #[output(same_as = measured)]
    output: Mat,
    /// proportional gain
    #[param(tunable)]
    kp: Mat,
    /// derivative gain
    #[param(tunable, unit = "s")]
    kd: Mat,
    y: DMatrix<f64>,
    r: DMatrix<f64>,
    u: DMatrix<f64>,
    previous: DMatrix<f64>,
    primed: bool,
}

impl Pd {
    /// Reads `measured` and `reference` (n × 1 each), writes `output` (n × 1).
    pub fn new(
        b: &mut Binder<'_>,
        measured: &str,
        reference: &str,
        output: &str,
        kp: f64,
        kd: f64,
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("measured", measured)
            .with("reference", reference)
            .with("output", output)
            .with("kp", kp)
            .with("kd", kd);
        Self::build(b, &params)
    }
}
impl SampleModule for Pd {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let kp = self.kp.read().get(0, 0)?;
        let kd = self.kd.read().get(0, 0)?;
        copy_in(&self.measured, &mut self.y);
        copy_in(&self.reference, &mut self.r);
        if self.r.shape() != self.y.shape() {
            return Err(shape_error(
                "reference",
                self.reference.name(),
                self.r.shape(),
                self.y.shape(),
            ));
        }
        if !self.primed || self.previous.shape() != self.y.shape() {
            copy_in(&self.measured, &mut self.previous);
            self.primed = true;
        }
        if self.u.shape() != self.y.shape() {
            self.u = self.y.clone();
        }
        let dt = ctx.dt();
        for (i, out) in self.u.iter_mut().enumerate() {
            let (y, r, prev) = (self.y[i], self.r[i], self.previous[i]);
            *out = kp * (r - y) - kd * (y - prev) / dt;
        }
        copy_out(&self.output, &self.u)
    }

    fn state_update(&mut self, _: &SampleContext) -> RoutineResult {
        if self.previous.shape() == self.y.shape() {
            self.previous.copy_from(&self.y);
        }
        Ok(())
    }

    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        self.primed = false;
        Ok(())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.primed = false;
        Ok(())
    }
}

/// Registers `pd`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Pd>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::testing::{TestResult, runtime, trace};

    #[test]
    fn pd_known_answers_on_a_ramp_measurement() -> TestResult {
        // y = 3·t, r = 5: u = 2·(5 − y) − 0.5·3, but no derivative in the first sample.
        let dt = 0.01;
        let rt = runtime(1.0 / dt, &[("r", &[5.0])])?;
        let ramp = Params::new().with("output", "y").with("slope", 3.0);
        rt.install_component("h", "ramp", "ramp", &ramp)?;
        let pd = Params::new()
            .with("measured", "y")
            .with("reference", "r")
            .with("output", "u")
            .with("kp", 2.0)
            .with("kd", 0.5);
        rt.install_component("h", "pd", "pd", &pd)?;
        let u = &trace(&rt, &["u"], 5)?[0];
        assert_eq!(u[0], 10.0, "enabled without a derivative jump");
        for (k, u) in u.iter().enumerate().skip(1) {
            let expected = 2.0 * (5.0 - 3.0 * dt * k as f64) - 0.5 * 3.0;
            assert!(
                (u - expected).abs() < 1e-9,
                "u[{k}] = {u}, expected {expected}"
            );
        }
        Ok(())
    }
}

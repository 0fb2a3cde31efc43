//! `pd`: PD control on the measurement.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule, Shape};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use crate::mats::{copy_in, copy_out, distinct, scalar_param, shape_error, shape_of};

/// PD control on the measurement: `u = kp·(r − y) − kd·dy/dt`, element by element (taking
/// the derivative of the measurement, not of the error, avoids a kick on reference steps).
/// `kp` and `kd` are the 1 × 1 parameters `"{module}.kp"` and `"{module}.kd"`. Enabling it
/// takes the current measurement as the previous one, so it starts without a derivative jump.
pub struct Pd {
    measured: Mat,
    reference: Mat,
    output: Mat,
    kp: Mat,
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
        distinct(&[measured, reference, output])?;
        let measured_mat = b.input(measured, Shape::Any);
        let shape = shape_of(&measured_mat, Shape::Any);
        Ok(Self {
            reference: b.input(reference, shape),
            output: b.output_same_as(output, &measured_mat),
            measured: measured_mat,
            kp: scalar_param(b, "kp", kp),
            kd: scalar_param(b, "kd", kd),
            y: DMatrix::zeros(0, 0),
            r: DMatrix::zeros(0, 0),
            u: DMatrix::zeros(0, 0),
            previous: DMatrix::zeros(0, 0),
            primed: false,
        })
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

const PD: ComponentSpec = ComponentSpec {
    name: "pd",
    summary: "PD on the measurement: u = kp·(r − y) − kd·ẏ (the derivative of the \
              measurement, so reference steps do not kick).",
    params: &[
        P::required("measured", K::Input, "y (n × 1)"),
        P::required("reference", K::Input, "r (n × 1)"),
        P::required("output", K::Output, "u (n × 1)"),
        P::required("kp", K::Number, "proportional gain"),
        P::required("kd", K::Number, "derivative gain (s)"),
    ],
};

/// Registers `pd`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add_with(&PD, |b, p| {
        Pd::new(
            b,
            p.text("measured")?,
            p.text("reference")?,
            p.text("output")?,
            p.number("kp")?,
            p.number("kd")?,
        )
    });
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

//! A steady-state Kalman estimator, the first half of a hand-assembled LQG controller.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule};

use crate::mats::{copy_in, copy_out, distinct, gemm, matrix_param, shape_error};
use crate::params::failed;

/// A steady-state Kalman estimator for `x⁺ = A·x + B·u`, `y = C·x`:
/// `x̂ = x̂⁻ + L·(y − C·x̂⁻)` in `execute` (written to `estimate`), then
/// `x̂⁻ = A·x̂ + B·u` in `state_update` — the command `u` is read only there, which is what lets
/// the estimator sit in a loop with the controller that computes `u` from `x̂`.
/// Parameters `"{module}.A"`, `.B`, `.C`, `.L`. Enabling it initialises `x̂⁻` with the
/// minimum-norm state that explains the current measurement, so it takes over bumplessly.
pub struct Estimator {
    measured: Mat,
    command: Mat,
    estimate: Mat,
    a: Mat,
    b: Mat,
    c: Mat,
    l: Mat,
    predicted: DMatrix<f64>,
    innovation: DMatrix<f64>,
    corrected: DMatrix<f64>,
    y: DMatrix<f64>,
    u: DMatrix<f64>,
}

impl Estimator {
    /// `a` n × n, `b` n × m, `c` p × n, `l` n × p.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        b: &mut Binder<'_>,
        measured: &str,
        command: &str,
        estimate: &str,
        a: &DMatrix<f64>,
        bm: &DMatrix<f64>,
        c: &DMatrix<f64>,
        l: &DMatrix<f64>,
    ) -> Result<Self, ModuleError> {
        distinct(&[measured, command, estimate])?;
        let (n, m, p) = (a.nrows(), bm.ncols(), c.nrows());
        if a.ncols() != n || bm.nrows() != n || c.ncols() != n || l.shape() != (n, p) {
            return Err(failed("estimator model: A n×n, B n×m, C p×n, L n×p"));
        }
        Ok(Self {
            measured: b.input(measured, (p, 1)),
            command: b.state_input(command, (m, 1)),
            estimate: b.output(estimate, (n, 1)),
            a: matrix_param(b, "A", a),
            b: matrix_param(b, "B", bm),
            c: matrix_param(b, "C", c),
            l: matrix_param(b, "L", l),
            predicted: DMatrix::zeros(n, 1),
            innovation: DMatrix::zeros(p, 1),
            corrected: DMatrix::zeros(n, 1),
            y: DMatrix::zeros(p, 1),
            u: DMatrix::zeros(m, 1),
        })
    }
}

impl SampleModule for Estimator {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        copy_in(&self.measured, &mut self.y);
        if self.y.shape() != self.innovation.shape() {
            return Err(shape_error(
                "measurement",
                self.measured.name(),
                self.y.shape(),
                self.innovation.shape(),
            ));
        }
        self.innovation.copy_from(&self.y);
        gemm(
            &mut self.innovation,
            -1.0,
            self.c.read().matrix(),
            &self.predicted,
            1.0,
        )?;
        self.corrected.copy_from(&self.predicted);
        gemm(
            &mut self.corrected,
            1.0,
            self.l.read().matrix(),
            &self.innovation,
            1.0,
        )?;
        copy_out(&self.estimate, &self.corrected)
    }

    fn state_update(&mut self, _: &SampleContext) -> RoutineResult {
        copy_in(&self.command, &mut self.u);
        gemm(
            &mut self.predicted,
            1.0,
            self.a.read().matrix(),
            &self.corrected,
            0.0,
        )?;
        gemm(
            &mut self.predicted,
            1.0,
            self.b.read().matrix(),
            &self.u,
            1.0,
        )
    }

    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        copy_in(&self.measured, &mut self.y);
        let pinv = self
            .c
            .read()
            .matrix()
            .clone()
            .pseudo_inverse(1e-12)
            .map_err(|e| failed(format!("C has no pseudo-inverse: {e}")))?;
        if pinv.shape() != (self.predicted.nrows(), self.y.nrows()) || self.y.ncols() != 1 {
            return Err(failed(format!(
                "estimator: C is {}x{} and the measurement {}x{}; expected {}x{} and {}x1",
                pinv.ncols(),
                pinv.nrows(),
                self.y.nrows(),
                self.y.ncols(),
                self.innovation.nrows(),
                self.predicted.nrows(),
                self.innovation.nrows()
            )));
        }
        gemm(&mut self.predicted, 1.0, &pinv, &self.y, 0.0)?;
        self.corrected.copy_from(&self.predicted);
        Ok(())
    }

    fn reset(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.enable(ctx)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use super::Estimator;
    use crate::testing::{TestResult, runtime};

    #[test]
    fn corrects_by_the_innovation_and_predicts_with_the_command() -> TestResult {
        // x⁺ = x + u, y = x, L = 0.5; enabled at y = 2, then y = 4 with u = 1 throughout.
        let rt = runtime(100.0, &[("y", &[2.0]), ("u", &[1.0])])?;
        let one = |x: f64| DMatrix::from_element(1, 1, x);
        rt.install("h", "kalman", |b| {
            Estimator::new(b, "y", "u", "x", &one(1.0), &one(1.0), &one(1.0), &one(0.5))
        })?;
        let h = rt.habitat("h");
        h.start()?;
        let mut estimates = Vec::new();
        for k in 0..3 {
            if k == 1 {
                rt.mat("y").write().set(0, 0, 4.0)?;
            }
            h.step()?;
            estimates.push(rt.mat("x").value(0, 0));
        }
        assert_eq!(estimates, [2.0, 3.5, 4.25]);
        assert_eq!(h.stats().module_errors, 0);
        Ok(())
    }
}

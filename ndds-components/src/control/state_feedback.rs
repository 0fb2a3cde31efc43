//! State feedback with reference feedforward, the second half of a hand-assembled LQG
//! controller.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule};

use crate::mats::{copy_in, copy_out, distinct, gemm, matrix_param};
use crate::params::failed;

/// State feedback with reference feedforward: `u = N·r − K·x̂`. Parameters `"{module}.K"`
/// (m × n) and `"{module}.N"` (m × p).
pub struct StateFeedback {
    estimate: Mat,
    reference: Mat,
    output: Mat,
    k: Mat,
    n: Mat,
    x: DMatrix<f64>,
    r: DMatrix<f64>,
    work: DMatrix<f64>,
}

impl StateFeedback {
    /// Reads `estimate` (n × 1) and `reference` (p × 1), writes `output` (m × 1).
    pub fn new(
        b: &mut Binder<'_>,
        estimate: &str,
        reference: &str,
        output: &str,
        k: &DMatrix<f64>,
        n: &DMatrix<f64>,
    ) -> Result<Self, ModuleError> {
        distinct(&[estimate, reference, output])?;
        let (m, states, p) = (k.nrows(), k.ncols(), n.ncols());
        if n.nrows() != m {
            return Err(failed("state feedback: K m×n and N m×p"));
        }
        Ok(Self {
            estimate: b.input(estimate, (states, 1)),
            reference: b.input(reference, (p, 1)),
            output: b.output(output, (m, 1)),
            k: matrix_param(b, "K", k),
            n: matrix_param(b, "N", n),
            x: DMatrix::zeros(states, 1),
            r: DMatrix::zeros(p, 1),
            work: DMatrix::zeros(m, 1),
        })
    }
}

impl SampleModule for StateFeedback {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        copy_in(&self.estimate, &mut self.x);
        copy_in(&self.reference, &mut self.r);
        gemm(&mut self.work, 1.0, self.n.read().matrix(), &self.r, 0.0)?;
        gemm(&mut self.work, -1.0, self.k.read().matrix(), &self.x, 1.0)?;
        copy_out(&self.output, &self.work)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use super::StateFeedback;
    use crate::testing::{TestResult, runtime, trace};

    #[test]
    fn commands_n_r_minus_k_x() -> TestResult {
        // K = [2, 1], N = [3]: u = 3·0.5 − (2·1 + 1·(−1)) = 0.5.
        let rt = runtime(100.0, &[("x", &[1.0, -1.0]), ("r", &[0.5])])?;
        let k = DMatrix::from_row_slice(1, 2, &[2.0, 1.0]);
        let n = DMatrix::from_element(1, 1, 3.0);
        rt.install("h", "lqr", |b| StateFeedback::new(b, "x", "r", "u", &k, &n))?;
        assert_eq!(trace(&rt, &["u"], 2)?[0], [0.5, 0.5]);
        rt.mat("lqr.K").write().set(0, 1, 0.0)?;
        rt.habitat("h").step()?;
        assert_eq!(rt.mat("u").value(0, 0), -0.5, "K is tunable");
        Ok(())
    }
}

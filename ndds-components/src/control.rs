//! Controllers: PD, and the two halves of an LQG controller (a steady-state Kalman estimator
//! and state feedback), with the design helpers that compute their gains.

use nalgebra::DMatrix;

use super::{copy_in, copy_out, distinct, matrix_param, scalar_param, shape_error};
use ndds_runtime::Mat;
use ndds_runtime::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule};

fn failed(text: &str) -> ModuleError {
    ModuleError::Failed(text.to_owned())
}

/// `out = alpha·a·b + beta·out`, with the shapes checked first (nalgebra would panic).
pub(crate) fn gemm(
    out: &mut DMatrix<f64>,
    alpha: f64,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
) -> Result<(), ModuleError> {
    if a.ncols() != b.nrows() || out.nrows() != a.nrows() || out.ncols() != b.ncols() {
        return Err(ModuleError::Failed(format!(
            "matrix product of {}x{} and {}x{} into {}x{}",
            a.nrows(),
            a.ncols(),
            b.nrows(),
            b.ncols(),
            out.nrows(),
            out.ncols()
        )));
    }
    out.gemm(alpha, a, b, beta);
    Ok(())
}

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
        let measured_mat = b.input(measured, super::Shape::Any);
        let shape = super::shape_of(&measured_mat, super::Shape::Any);
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
                &self.reference.read(),
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
                &self.measured.read(),
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
            .map_err(|e| ModuleError::Failed(format!("C has no pseudo-inverse: {e}")))?;
        if pinv.shape() != (self.predicted.nrows(), self.y.nrows()) || self.y.ncols() != 1 {
            return Err(ModuleError::Failed(format!(
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

/// Zero-order-hold discretisation of `ẋ = A·x + B·u` at period `dt`: `(Ad, Bd)` from the
/// matrix exponential of `[[A, B], [0, 0]]·dt`.
pub fn discretize(a: &DMatrix<f64>, b: &DMatrix<f64>, dt: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, m) = (a.nrows(), b.ncols());
    let mut aug = DMatrix::zeros(n + m, n + m);
    aug.view_mut((0, 0), (n, n)).copy_from(&(a * dt));
    aug.view_mut((0, n), (n, m)).copy_from(&(b * dt));
    let e = aug.exp();
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, m)).into_owned(),
    )
}

/// Iterates a discrete Riccati equation to its fixed point (at most 100 000 steps).
fn riccati(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let mut p = q.clone();
    for _ in 0..100_000 {
        let s = r + b.transpose() * &p * b;
        let gain = s.try_inverse()? * b.transpose() * &p * a;
        let next = q + a.transpose() * &p * a - a.transpose() * &p * b * &gain;
        let change = (&next - &p).abs().max();
        p = next;
        if !change.is_finite() {
            return None; // diverged: no stabilising solution
        }
        if change <= 1e-12 * (1.0 + p.abs().max()) {
            return Some(p);
        }
    }
    None
}

/// The discrete LQR gain `K` (u = −K·x) for `x⁺ = A·x + B·u` with costs `Q`, `R`.
pub fn dlqr(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let p = riccati(a, b, q, r)?;
    Some((r + b.transpose() * &p * b).try_inverse()? * b.transpose() * &p * a)
}

/// The steady-state Kalman filter gain `L` (x̂ = x̂⁻ + L·(y − C·x̂⁻)) for process noise `Qn` and
/// measurement noise `Rn`.
pub fn kalman_gain(
    a: &DMatrix<f64>,
    c: &DMatrix<f64>,
    qn: &DMatrix<f64>,
    rn: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let p = riccati(&a.transpose(), &c.transpose(), qn, rn)?;
    Some(&p * c.transpose() * (c * &p * c.transpose() + rn).try_inverse()?)
}

/// The feedforward `N` that makes `y = C·x` settle at `r` under `u = N·r − K·x`.
pub fn reference_gain(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
    k: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let n = a.nrows();
    let closed = DMatrix::identity(n, n) - a + b * k;
    let dc = c * closed.try_inverse()? * b;
    dc.try_inverse()
}

/// Everything an LQG controller for a continuous plant needs, discretised at one period.
#[derive(Clone, Debug, PartialEq)]
pub struct LqgDesign {
    /// Discrete state matrix.
    pub ad: DMatrix<f64>,
    /// Discrete input matrix.
    pub bd: DMatrix<f64>,
    /// Output matrix.
    pub c: DMatrix<f64>,
    /// State-feedback gain (`u = N·r − K·x̂`).
    pub k: DMatrix<f64>,
    /// Reference feedforward.
    pub n: DMatrix<f64>,
    /// Kalman gain.
    pub l: DMatrix<f64>,
}

/// Weights of an LQG design: state and input costs, process and measurement noise.
#[derive(Clone, Debug, PartialEq)]
pub struct LqgWeights {
    /// State cost (n × n).
    pub q: DMatrix<f64>,
    /// Input cost (m × m).
    pub r: DMatrix<f64>,
    /// Process noise covariance (n × n).
    pub process_noise: DMatrix<f64>,
    /// Measurement noise covariance (p × p).
    pub measurement_noise: DMatrix<f64>,
}

/// Designs an LQG controller for `ẋ = A·x + B·u`, `y = C·x` sampled every `dt` seconds, or
/// `None` if the plant is not stabilisable / detectable with these weights.
pub fn design_lqg(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
    dt: f64,
    weights: &LqgWeights,
) -> Option<LqgDesign> {
    let (ad, bd) = discretize(a, b, dt);
    let k = dlqr(&ad, &bd, &weights.q, &weights.r)?;
    let l = kalman_gain(&ad, c, &weights.process_noise, &weights.measurement_noise)?;
    let n = reference_gain(&ad, &bd, c, &k)?;
    Some(LqgDesign {
        ad,
        bd,
        c: c.clone(),
        k,
        n,
        l,
    })
}

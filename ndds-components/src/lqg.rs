//! An LQG controller in one module: a steady-state Kalman estimator and LQR state feedback
//! with reference feedforward, designed by the module itself at its habitat's rate.
//!
//! The model is continuous, `ẋ = A·x + B·u`, `y = C·x`, either given explicitly or obtained by
//! linearising a library plant about an operating point (see [`LqgModel`]). All of the
//! controller's arithmetic is in deviations from that operating point, where the plant is at
//! rest with output `y0` under command `u0`:
//!
//! ```text
//! δy = y − y0,  δr = r − y0                      (measurement, reference)
//! x̂  = x̂⁻ + L·(δy − C·x̂⁻)                        (execute: correct)
//! u  = clamp(u0 + N·δr − K·x̂, ±limit)            (execute: command)
//! x̂⁻ = Ad·x̂ + Bd·(u − u0)                        (state_update: predict)
//! ```
//!
//! `(Ad, Bd)` is the zero-order-hold discretisation at the habitat's period and `K`, `L`, `N`
//! come from [`design_lqg`] (discrete LQR on `q`, `r`; steady-state Kalman gain on
//! `process_noise`, `measurement_noise`; `N` makes `y` settle at `r`). An explicit model has
//! `y0 = 0`, `u0 = 0`.

use nalgebra::linalg::{Schur, SymmetricEigen};
use nalgebra::{DMatrix, DVector};

use super::arm::{ArmModel, joint_pair};
use super::control::gemm;
use super::{LqgDesign, LqgWeights, Physical, copy_out, design_lqg, distinct, shape_error};
use ndds_runtime::Mat;
use ndds_runtime::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{
    ComponentSpec, ParamError, ParamKind as K, ParamSpec as P, ParamValue, Params, Registry,
};

/// The period (s) at which [`Lqg::new`] test-designs the controller, to refuse a model or
/// weights that cannot work before any habitat runs it (the real design is at the habitat's
/// period, in `startup` and `timing_changed`).
pub const LQG_NOMINAL_DT: f64 = 0.01;

fn failed(text: impl Into<String>) -> ModuleError {
    ModuleError::Failed(text.into())
}

/// What an LQG controller of a `mass_spring_damper` measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MassOutput {
    /// The position `p` (m): `C = [1, 0]`.
    Position,
    /// The lever angle `p / length` (rad): `C = [1/length, 0]`.
    Angle,
}

/// What an LQG controller of a `two_link_arm` measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArmOutput {
    /// The joint angles (rad): `C = [I, 0]`, `y0 = at`.
    Angles,
    /// The endpoint (m): `C = [J(at), 0]` (the Jacobian), `y0 = FK(at)`.
    Endpoint,
}

/// The model an [`Lqg`] is designed on.
#[derive(Clone, Debug, PartialEq)]
pub enum LqgModel {
    /// `ẋ = a·x + b·u`, `y = c·x` (a n × n, b n × m, c p × n), operating point 0.
    Explicit {
        /// A (n × n).
        a: DMatrix<f64>,
        /// B (n × m).
        b: DMatrix<f64>,
        /// C (p × n).
        c: DMatrix<f64>,
    },
    /// A [`MassSpringDamper`](super::MassSpringDamper) (`x = [p, ṗ]`, `u` = force), exactly
    /// linear, operating point 0.
    MassSpringDamper {
        /// Its constants.
        physical: Physical,
        /// What is measured.
        output: MassOutput,
    },
    /// A [`TwoLinkArm`](super::TwoLinkArm) linearised about rest at `at`
    /// (`δx = [q − at, q̇]`, `u0 = g(at)`, the gravity torque: 0 in a horizontal plane).
    TwoLinkArm {
        /// Its constants.
        model: ArmModel,
        /// The operating point (rad); for `Endpoint`, not singular (`q2 ≠ 0, π`).
        at: [f64; 2],
        /// What is measured.
        output: ArmOutput,
    },
}

/// A model linearised: `(A, B, C)` and the operating point `(y0, u0)`.
struct Linear {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DMatrix<f64>,
    y0: DMatrix<f64>,
    u0: DMatrix<f64>,
}

impl Linear {
    /// `(n, m, p)`: states, commands, measurements.
    fn dims(&self) -> (usize, usize, usize) {
        (self.a.nrows(), self.b.ncols(), self.c.nrows())
    }
}

fn plant_error(e: ParamError) -> ModuleError {
    failed(format!("parameter `plant.{}`: {}", e.name, e.problem))
}

fn all_finite(m: &DMatrix<f64>) -> bool {
    m.iter().all(|x| x.is_finite())
}

impl LqgModel {
    /// The model of an `lqg` component's parameters: `a`, `b` and `c`, or `plant` (a table
    /// with `type = "mass_spring_damper"` or `"two_link_arm"`; see [`LQG`]).
    pub fn from_params(p: &Params) -> Result<Self, ModuleError> {
        let given: Vec<&str> = ["a", "b", "c"].into_iter().filter(|k| p.has(k)).collect();
        match (p.has("plant"), given.len()) {
            (true, 0) => Self::from_plant(p.table("plant")?),
            (false, 3) => Ok(LqgModel::Explicit {
                a: p.matrix("a")?,
                b: p.matrix("b")?,
                c: p.matrix("c")?,
            }),
            (true, _) => Err(failed(format!(
                "parameter `plant`: give either `plant` or `a`, `b`, `c`, not both (also \
                 given: {})",
                given.join(", ")
            ))),
            (false, 0) => Err(failed(
                "the model is missing: give `plant` (a table naming a library plant) or the \
                 matrices `a`, `b` and `c`",
            )),
            (false, _) => Err(failed(format!(
                "parameters `a`, `b`, `c`: all three are needed, only {} given",
                given.join(", ")
            ))),
        }
    }

    fn from_plant(t: &Params) -> Result<Self, ModuleError> {
        let kind = t.text("type").map_err(plant_error)?;
        let known: &[&str] = match kind {
            "mass_spring_damper" => &["type", "mass", "stiffness", "damping", "length", "output"],
            "two_link_arm" => &[
                "type", "l1", "l2", "m1", "m2", "damping", "gravity", "at", "output",
            ],
            other => {
                return Err(failed(format!(
                    "parameter `plant.type`: unknown plant `{other}` (known: \
                     mass_spring_damper, two_link_arm)"
                )));
            }
        };
        if let Some(extra) = t.0.keys().find(|k| !known.contains(&k.as_str())) {
            return Err(failed(format!(
                "parameter `plant.{extra}`: not a parameter of a `{kind}` plant (known: {})",
                known.join(", ")
            )));
        }
        if kind == "mass_spring_damper" {
            Self::mass_spring_damper(t)
        } else {
            Self::two_link_arm(t)
        }
    }

    fn mass_spring_damper(t: &Params) -> Result<Self, ModuleError> {
        let output = match t.text_or("output", "position").map_err(plant_error)? {
            "position" => MassOutput::Position,
            "angle" => MassOutput::Angle,
            other => {
                return Err(failed(format!(
                    "parameter `plant.output`: expected \"position\" or \"angle\", got \
                     \"{other}\""
                )));
            }
        };
        let physical = Physical {
            mass: t.number_or("mass", 1.0).map_err(plant_error)?,
            stiffness: t.number_or("stiffness", 4.0).map_err(plant_error)?,
            damping: t.number_or("damping", 0.4).map_err(plant_error)?,
            length: t.number_or("length", 0.5).map_err(plant_error)?,
        };
        Ok(LqgModel::MassSpringDamper { physical, output })
    }

    fn two_link_arm(t: &Params) -> Result<Self, ModuleError> {
        let output = match t.text_or("output", "angles").map_err(plant_error)? {
            "angles" => ArmOutput::Angles,
            "endpoint" => ArmOutput::Endpoint,
            other => {
                return Err(failed(format!(
                    "parameter `plant.output`: expected \"angles\" or \"endpoint\", got \
                     \"{other}\""
                )));
            }
        };
        if !t.has("at") {
            return Err(failed(
                "parameter `plant.at`: missing (the operating point [q1, q2] in rad)",
            ));
        }
        Ok(LqgModel::TwoLinkArm {
            model: ArmModel::from_params(t).map_err(plant_error)?,
            at: joint_pair(t, "at", [0.0; 2]).map_err(plant_error)?,
            output,
        })
    }

    /// `(n, m, p)`: the numbers of states, commands and measurements, once the model checks.
    pub fn dimensions(&self) -> Result<(usize, usize, usize), ModuleError> {
        Ok(self.linear()?.dims())
    }

    /// Checks the model and linearises it.
    fn linear(&self) -> Result<Linear, ModuleError> {
        match self {
            LqgModel::Explicit { a, b, c } => explicit(a, b, c),
            LqgModel::MassSpringDamper { physical, output } => {
                let ph = physical;
                let ok = ph.mass.is_finite() && ph.mass > 0.0 && ph.length.is_finite();
                if !(ok && ph.length > 0.0 && ph.stiffness.is_finite() && ph.damping.is_finite()) {
                    return Err(failed(format!(
                        "parameter `plant`: mass and length must be positive, stiffness and \
                         damping finite; got {ph:?}"
                    )));
                }
                let (a, b) = ph.model();
                let scale = match output {
                    MassOutput::Position => 1.0,
                    MassOutput::Angle => 1.0 / ph.length,
                };
                Ok(Linear {
                    a,
                    b,
                    c: DMatrix::from_row_slice(1, 2, &[scale, 0.0]),
                    y0: DMatrix::zeros(1, 1),
                    u0: DMatrix::zeros(1, 1),
                })
            }
            LqgModel::TwoLinkArm { model, at, output } => arm_linear(model, *at, *output),
        }
    }
}

/// States (and commands, measurements) an `lqg` takes at most.
pub const MAX_STATES: usize = 16;

fn explicit(a: &DMatrix<f64>, b: &DMatrix<f64>, c: &DMatrix<f64>) -> Result<Linear, ModuleError> {
    let n = a.nrows();
    let dims = |name: &str, m: &DMatrix<f64>, expected: String| {
        failed(format!(
            "parameter `{name}`: expected {expected}, got {} × {}",
            m.nrows(),
            m.ncols()
        ))
    };
    if n == 0 || a.ncols() != n {
        return Err(dims("a", a, "a square matrix (n × n, n ≥ 1)".into()));
    }
    if n > MAX_STATES || b.ncols() > MAX_STATES || c.nrows() > MAX_STATES {
        return Err(failed(format!(
            "parameter `a`: at most {MAX_STATES} states, commands and measurements \
             (the design iterates a Riccati equation at load time)"
        )));
    }
    if b.nrows() != n || b.ncols() == 0 {
        return Err(dims("b", b, format!("{n} rows (n × m, `a` is {n} × {n})")));
    }
    if c.ncols() != n || c.nrows() == 0 {
        return Err(dims(
            "c",
            c,
            format!("{n} columns (p × n, `a` is {n} × {n})"),
        ));
    }
    for (name, m) in [("a", a), ("b", b), ("c", c)] {
        if !all_finite(m) {
            return Err(failed(format!("parameter `{name}`: not all finite")));
        }
    }
    Ok(Linear {
        a: a.clone(),
        b: b.clone(),
        c: c.clone(),
        y0: DMatrix::zeros(c.nrows(), 1),
        u0: DMatrix::zeros(b.ncols(), 1),
    })
}

fn arm_linear(model: &ArmModel, at: [f64; 2], output: ArmOutput) -> Result<Linear, ModuleError> {
    model.check().map_err(plant_error)?;
    if !(at[0].is_finite() && at[1].is_finite()) {
        return Err(failed(format!(
            "parameter `plant.at`: expected finite angles (rad), got {at:?}"
        )));
    }
    let (a, b) = model.linearize(at);
    let mut c = DMatrix::zeros(2, 4);
    let y0 = match output {
        ArmOutput::Angles => {
            c[(0, 0)] = 1.0;
            c[(1, 1)] = 1.0;
            at
        }
        ArmOutput::Endpoint => {
            let j = model.jacobian(at);
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            if det.abs() < 1e-6 * model.l1 * model.l2 {
                return Err(failed(format!(
                    "parameter `plant.at`: the arm is singular at {at:?} (q2 = 0 or π): the \
                     endpoint does not determine the joint angles there"
                )));
            }
            for (i, row) in j.iter().enumerate() {
                c[(i, 0)] = row[0];
                c[(i, 1)] = row[1];
            }
            model.forward_kinematics(at)
        }
    };
    Ok(Linear {
        a,
        b,
        c,
        y0: DMatrix::from_column_slice(2, 1, &y0),
        u0: DMatrix::from_column_slice(2, 1, &model.gravity_torque(at)),
    })
}

/// A weight or covariance parameter as a `dim × dim` matrix: a matrix of that shape as it
/// is, a list of `dim` numbers (a row or a column) as its diagonal, one number times the
/// identity.
pub fn weight_matrix(p: &Params, name: &str, dim: usize) -> Result<DMatrix<f64>, ModuleError> {
    let m = match p.0.get(name) {
        Some(ParamValue::Numbers(xs)) => DMatrix::from_column_slice(xs.len(), 1, xs),
        _ => p.matrix(name)?,
    };
    if m.shape() == (dim, dim) {
        Ok(m)
    } else if m.len() == 1 {
        Ok(DMatrix::identity(dim, dim) * m[0])
    } else if m.len() == dim && (m.nrows() == 1 || m.ncols() == 1) {
        Ok(DMatrix::from_diagonal(&DVector::from_iterator(
            dim,
            m.iter().copied(),
        )))
    } else {
        Err(failed(format!(
            "parameter `{name}`: expected a {dim} × {dim} matrix or its diagonal ({dim} \
             numbers), got {} × {}",
            m.nrows(),
            m.ncols()
        )))
    }
}

/// Checks that `w` is `dim × dim`, finite, symmetric, and positive semi-definite (or definite).
fn check_weight(name: &str, w: &DMatrix<f64>, dim: usize, definite: bool) -> RoutineResult {
    let bad = |why: String| Err(failed(format!("parameter `{name}`: {why}")));
    if w.shape() != (dim, dim) {
        return bad(format!(
            "expected {dim} × {dim}, got {} × {}",
            w.nrows(),
            w.ncols()
        ));
    }
    if !all_finite(w) {
        return bad("not all finite".into());
    }
    let scale = w.abs().max();
    if (w - w.transpose()).abs().max() > 1e-9 * (1.0 + scale) {
        return bad("not symmetric".into());
    }
    let lowest = SymmetricEigen::try_new(w.clone(), 1e-14, 10_000)
        .map(|e| e.eigenvalues.min())
        .unwrap_or(f64::NAN);
    let tolerance = 1e-12 * scale;
    let ok = if definite {
        lowest > tolerance
    } else {
        lowest >= -tolerance
    };
    if ok {
        Ok(())
    } else {
        let what = if definite {
            "definite"
        } else {
            "semi-definite"
        };
        bad(format!(
            "expected a positive {what} matrix, its lowest eigenvalue is {lowest:e}"
        ))
    }
}

/// The largest eigenvalue modulus of `m` (NaN if the eigenvalues cannot be computed).
fn spectral_radius(m: &DMatrix<f64>) -> f64 {
    Schur::try_new(m.clone(), 1e-14, 10_000)
        .map(|s| {
            s.complex_eigenvalues()
                .iter()
                .map(|z| z.norm())
                .fold(0.0, f64::max)
        })
        .unwrap_or(f64::NAN)
}

/// Designs at `dt` and checks that both the state feedback and the estimator are stable.
fn design(linear: &Linear, weights: &LqgWeights, dt: f64) -> Result<LqgDesign, ModuleError> {
    let d = design_lqg(&linear.a, &linear.b, &linear.c, dt, weights).ok_or_else(|| {
        failed(format!(
            "lqg: no design at dt = {dt} s: the Riccati equations have no solution, or the \
             steady-state gain is singular (is the model controllable from its input and \
             observable from its output, and are `r` and `measurement_noise` positive?)"
        ))
    })?;
    let control = spectral_radius(&(&d.ad - &d.bd * &d.k));
    if control.is_nan() || control >= 1.0 {
        return Err(failed(format!(
            "lqg: the state feedback designed at dt = {dt} s does not stabilise the model \
             (closed-loop spectral radius {control}): is every unstable mode controllable and \
             weighted by `q`?"
        )));
    }
    let estimator = spectral_radius(&(&d.ad - &d.ad * &d.l * &d.c));
    if estimator.is_nan() || estimator >= 1.0 {
        return Err(failed(format!(
            "lqg: the estimator designed at dt = {dt} s is not stable (spectral radius \
             {estimator}): is every unstable mode observable and excited by `process_noise`?"
        )));
    }
    Ok(d)
}

/// Copies `mat` into `buffer` minus `offset` (same shapes, finite values), without allocating.
fn read_deviation(mat: &Mat, offset: &DMatrix<f64>, buffer: &mut DMatrix<f64>) -> RoutineResult {
    let value = mat.read();
    if value.shape() != buffer.shape() {
        return Err(shape_error("input", &value, buffer.shape()));
    }
    if !all_finite(value.matrix()) {
        return Err(failed(format!(
            "input `{}` holds a non-finite value",
            value.name()
        )));
    }
    buffer.copy_from(value.matrix());
    *buffer -= offset;
    Ok(())
}

/// An LQG controller with its own steady-state Kalman estimator (see the module docs for the
/// equations). Reads `measured` and `reference` (p × 1) in `execute`, writes the command
/// `output` (m × 1) and, if asked for, `estimate` (n × 1, the state's deviation from the
/// operating point). The gains are designed at the habitat's period in `startup` and again in
/// `timing_changed`. Enabling (and resetting) it starts the estimate from the minimum-norm
/// state that explains the current measurement, `x̂⁻ = C⁺·δy` (at rest), so it can take over
/// from another controller without a bump.
pub struct Lqg {
    measured: Mat,
    reference: Mat,
    output: Mat,
    estimate: Option<Mat>,
    linear: Linear,
    weights: LqgWeights,
    limit: Option<f64>,
    /// `None` until `startup` (or after a failed redesign).
    design: Option<LqgDesign>,
    /// C⁺, for the bumpless start.
    c_pinv: DMatrix<f64>,
    y: DMatrix<f64>,
    r: DMatrix<f64>,
    innovation: DMatrix<f64>,
    predicted: DMatrix<f64>,
    corrected: DMatrix<f64>,
    du: DMatrix<f64>,
    u: DMatrix<f64>,
}

impl Lqg {
    /// Reads `measured` and `reference` (p × 1), writes `output` (m × 1) and `estimate`
    /// (n × 1) if given. Checks the model and weights and test-designs the controller at
    /// [`LQG_NOMINAL_DT`], failing with the reason if that is impossible. `limit`, if given,
    /// clamps each command element to `[−limit, limit]`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        b: &mut Binder<'_>,
        measured: &str,
        reference: &str,
        output: &str,
        estimate: Option<&str>,
        model: &LqgModel,
        weights: LqgWeights,
        limit: Option<f64>,
    ) -> Result<Self, ModuleError> {
        let mut names = vec![measured, reference, output];
        names.extend(estimate);
        distinct(&names)?;
        let linear = model.linear()?;
        let (n, m, p) = linear.dims();
        check_weight("q", &weights.q, n, false)?;
        check_weight("r", &weights.r, m, true)?;
        check_weight("process_noise", &weights.process_noise, n, false)?;
        check_weight("measurement_noise", &weights.measurement_noise, p, true)?;
        if let Some(limit) = limit
            && (limit.is_nan() || limit <= 0.0)
        {
            return Err(failed(format!(
                "parameter `limit`: expected a positive number (command units), got {limit}"
            )));
        }
        design(&linear, &weights, LQG_NOMINAL_DT)?;
        let c_pinv = linear
            .c
            .clone()
            .pseudo_inverse(1e-12)
            .map_err(|e| failed(format!("lqg: C has no pseudo-inverse: {e}")))?;
        let measured = b.input(measured, (p, 1));
        let reference = b.input(reference, (p, 1));
        let output = b.output(output, (m, 1));
        Ok(Self {
            measured,
            reference,
            output,
            estimate: estimate.map(|name| b.output(name, (n, 1))),
            linear,
            weights,
            limit,
            design: None,
            c_pinv,
            y: DMatrix::zeros(p, 1),
            r: DMatrix::zeros(p, 1),
            innovation: DMatrix::zeros(p, 1),
            predicted: DMatrix::zeros(n, 1),
            corrected: DMatrix::zeros(n, 1),
            du: DMatrix::zeros(m, 1),
            u: DMatrix::zeros(m, 1),
        })
    }

    /// The current design (`None` before `startup`).
    pub fn design(&self) -> Option<&LqgDesign> {
        self.design.as_ref()
    }

    fn redesign(&mut self, dt: f64) -> RoutineResult {
        self.design = None;
        self.design = Some(design(&self.linear, &self.weights, dt)?);
        Ok(())
    }

    /// `x̂⁻ = x̂ = C⁺·(y − y0)`.
    fn initialise(&mut self) -> RoutineResult {
        read_deviation(&self.measured, &self.linear.y0, &mut self.y)?;
        gemm(&mut self.predicted, 1.0, &self.c_pinv, &self.y, 0.0)?;
        self.corrected.copy_from(&self.predicted);
        self.du.fill(0.0);
        Ok(())
    }
}

impl SampleModule for Lqg {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let Some(d) = self.design.as_ref() else {
            return Err(failed(
                "lqg: no design for this rate (see the startup error)",
            ));
        };
        read_deviation(&self.measured, &self.linear.y0, &mut self.y)?;
        read_deviation(&self.reference, &self.linear.y0, &mut self.r)?;
        self.innovation.copy_from(&self.y);
        gemm(&mut self.innovation, -1.0, &d.c, &self.predicted, 1.0)?;
        self.corrected.copy_from(&self.predicted);
        gemm(&mut self.corrected, 1.0, &d.l, &self.innovation, 1.0)?;
        gemm(&mut self.du, 1.0, &d.n, &self.r, 0.0)?;
        gemm(&mut self.du, -1.0, &d.k, &self.corrected, 1.0)?;
        for i in 0..self.u.nrows() {
            let u0 = self.linear.u0[i];
            let mut u = u0 + self.du[i];
            if let Some(limit) = self.limit {
                u = u.clamp(-limit, limit);
            }
            self.u[i] = u;
            self.du[i] = u - u0;
        }
        copy_out(&self.output, &self.u)?;
        if let Some(estimate) = &self.estimate {
            copy_out(estimate, &self.corrected)?;
        }
        Ok(())
    }

    fn state_update(&mut self, _: &SampleContext) -> RoutineResult {
        let Some(d) = self.design.as_ref() else {
            return Ok(());
        };
        gemm(&mut self.predicted, 1.0, &d.ad, &self.corrected, 0.0)?;
        gemm(&mut self.predicted, 1.0, &d.bd, &self.du, 1.0)
    }

    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        self.initialise()
    }

    fn startup(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.redesign(ctx.dt())
    }

    fn timing_changed(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.redesign(ctx.dt())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.initialise()
    }
}

/// `lqg`.
pub const LQG: ComponentSpec = ComponentSpec {
    name: "lqg",
    summary: "LQG controller: steady-state Kalman estimator and LQR state feedback with \
              reference feedforward, u = u0 + N·(r − y0) − K·x̂, designed at the habitat's rate \
              on an explicit model (a, b, c) or a linearised library plant (plant).",
    params: &[
        P::required("measured", K::Input, "y (p × 1), in the plant's units"),
        P::required(
            "reference",
            K::Input,
            "r (p × 1): the desired y, in the same units",
        ),
        P::required("output", K::Output, "u (m × 1), the command"),
        P::optional(
            "estimate",
            K::Output,
            "none",
            "x̂ (n × 1): the estimated state's deviation from the operating point",
        ),
        P::optional(
            "plant",
            K::Table,
            "none",
            "a library plant to linearise instead of a, b, c: { type = \"mass_spring_damper\", \
             mass, stiffness, damping, length, output = \"position\" | \"angle\" } (defaults \
             as the component, output position) or { type = \"two_link_arm\", l1, l2, m1, m2, \
             damping, gravity, at = [q1, q2] (required, rad), output = \"angles\" | \
             \"endpoint\" } (defaults as the component, output angles)",
        ),
        P::optional("a", K::Matrix, "none", "continuous A (n × n), with b and c"),
        P::optional("b", K::Matrix, "none", "continuous B (n × m), with a and c"),
        P::optional("c", K::Matrix, "none", "C (p × n), with a and b"),
        P::required(
            "q",
            K::Matrix,
            "state cost (n × n, or its diagonal as a list, or one number × I)",
        ),
        P::required(
            "r",
            K::Matrix,
            "command cost (m × m positive definite, or its diagonal, or a number)",
        ),
        P::required(
            "process_noise",
            K::Matrix,
            "process noise covariance (n × n, or its diagonal, or a number)",
        ),
        P::required(
            "measurement_noise",
            K::Matrix,
            "measurement noise covariance (p × p positive definite, or its diagonal, or a \
             number)",
        ),
        P::optional(
            "limit",
            K::Number,
            "none",
            "clamp each command element to [−limit, limit] (command units)",
        ),
    ],
};

/// Registers `lqg`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add(&LQG, |b, p| {
        let model = LqgModel::from_params(p)?;
        let (n, m, outputs) = model.dimensions()?;
        let weights = LqgWeights {
            q: weight_matrix(p, "q", n)?,
            r: weight_matrix(p, "r", m)?,
            process_noise: weight_matrix(p, "process_noise", n)?,
            measurement_noise: weight_matrix(p, "measurement_noise", outputs)?,
        };
        let optional = |name: &str| p.has(name).then(|| p.text(name)).transpose();
        let limit = p.has("limit").then(|| p.number("limit")).transpose()?;
        Lqg::new(
            b,
            p.text("measured")?,
            p.text("reference")?,
            p.text("output")?,
            optional("estimate")?,
            &model,
            weights,
            limit,
        )
    });
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::time::Duration;

    use super::*;
    use crate::dlqr;
    use ndds_runtime::{Clock, CsMat, HabitatOptions, Runtime};

    /// The positive root of the scalar discrete Riccati equation
    /// `P = q + a²P − (abP)²/(r + b²P)`, i.e. `b²P² + ((1 − a²)r − qb²)P − qr = 0`.
    fn scalar_riccati(a: f64, b: f64, q: f64, r: f64) -> f64 {
        let linear = (1.0 - a * a) * r - q * b * b;
        (-linear + (linear * linear + 4.0 * b * b * q * r).sqrt()) / (2.0 * b * b)
    }

    fn scalar_gain(a: f64, b: f64, q: f64, r: f64) -> f64 {
        let p = scalar_riccati(a, b, q, r);
        a * b * p / (r + b * b * p)
    }

    fn one(x: f64) -> DMatrix<f64> {
        DMatrix::from_element(1, 1, x)
    }

    #[test]
    fn dlqr_matches_the_scalar_closed_form() {
        let golden = (1.0 + 5f64.sqrt()) / 2.0;
        assert!((scalar_riccati(1.0, 1.0, 1.0, 1.0) - golden).abs() < 1e-12);
        for (a, b, q, r) in [
            (1.0, 1.0, 1.0, 1.0),
            (1.2, 0.5, 2.0, 0.3),
            (0.9, 2.0, 0.1, 5.0),
        ] {
            let k = dlqr(&one(a), &one(b), &one(q), &one(r)).expect("a design")[0];
            let expected = scalar_gain(a, b, q, r);
            assert!((k - expected).abs() < 1e-9, "{k} vs {expected}");
        }
        assert!((scalar_gain(1.0, 1.0, 1.0, 1.0) - 0.618_034).abs() < 1e-6);
    }

    #[test]
    fn the_component_designs_the_scalar_closed_form() {
        // ẋ = 100·u sampled at 10 ms: x⁺ = x + u exactly (a = 1, b = 1).
        let dt = 0.01;
        let mut mats: BTreeMap<String, Mat> = BTreeMap::new();
        let mut lookup = |name: &str| {
            mats.entry(name.to_owned())
                .or_insert_with(|| Mat::placeholder(name))
                .clone()
        };
        let mut binder = Binder::detached("lqg", &mut lookup);
        let model = LqgModel::Explicit {
            a: one(0.0),
            b: one(1.0 / dt),
            c: one(1.0),
        };
        let weights = LqgWeights {
            q: one(1.0),
            r: one(1.0),
            process_noise: one(1.0),
            measurement_noise: one(1.0),
        };
        let mut lqg = Lqg::new(&mut binder, "y", "r", "u", None, &model, weights, None).unwrap();
        assert!(lqg.design().is_none());
        let ctx = SampleContext {
            period: Duration::from_secs_f64(dt),
            sample: 0,
            time: Duration::ZERO,
        };
        lqg.startup(&ctx).unwrap();
        let design = lqg.design().expect("designed at startup");
        let expected = scalar_gain(1.0, 1.0, 1.0, 1.0);
        assert!((design.k[0] - expected).abs() < 1e-9, "{}", design.k);
        // The Kalman problem is the same Riccati equation (a = c = 1, Qn = Rn = 1):
        // L = P/(P + 1) with P the predicted covariance.
        assert!((design.l[0] - expected).abs() < 1e-9, "{}", design.l);
        // N makes y = r in steady state: (1 − (1 − K))·x = N·r ⇒ N = K.
        assert!((design.n[0] - expected).abs() < 1e-9, "{}", design.n);
    }

    fn habitat() -> Runtime {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(200.0).clock(Clock::Manual))
            .unwrap();
        rt
    }

    /// Steps `seconds` at 200 Hz; returns when the error last entered `< tol` and stayed.
    fn settle(rt: &Runtime, seconds: f64, tol: f64, error: impl Fn() -> f64) -> Option<f64> {
        let habitat = rt.habitat("h");
        habitat.start().unwrap();
        let mut settled = None;
        for k in 0..(seconds * 200.0).round() as u64 {
            habitat.step().unwrap();
            match (error() < tol, settled) {
                (true, None) => settled = Some(k as f64 / 200.0),
                (false, _) => settled = None,
                _ => {}
            }
        }
        habitat.stop();
        assert_eq!(habitat.stats_total().module_errors, 0);
        settled
    }

    #[test]
    fn tracks_a_mass_spring_damper_position() {
        let rt = habitat();
        rt.create_mat(CsMat::from_row_slice("reference", 1, 1, &[0.1]).unwrap())
            .unwrap();
        let plant = Params::new()
            .with("force", "force")
            .with("position", "position")
            .with("angle", "angle");
        rt.install_component("h", "plant", "mass_spring_damper", &plant)
            .unwrap();
        let lqg = Params::new()
            .with("measured", "position")
            .with("reference", "reference")
            .with("output", "force")
            .with("estimate", "estimate")
            .with(
                "plant",
                Params::new()
                    .with("type", "mass_spring_damper")
                    .with("mass", 1.0)
                    .with("stiffness", 4.0)
                    .with("damping", 0.4)
                    .with("output", "position"),
            )
            .with("q", vec![4000.0, 10.0])
            .with("r", 0.01)
            .with("process_noise", vec![1e-6, 1e-4])
            .with("measurement_noise", 1e-6);
        rt.install_component("h", "lqg", "lqg", &lqg).unwrap();
        let position = rt.mat("position");
        let settled = settle(&rt, 5.0, 1e-3, || (position.value(0, 0) - 0.1).abs())
            .expect("within 1 mm of 0.1 m after 5 s");
        let error = (position.value(0, 0) - 0.1).abs();
        eprintln!("lqg on the mass: |p − r| < 1e-3 m from {settled:.3} s, final {error:.2e} m");
        assert!(settled < 5.0);
        assert!((rt.mat("estimate").value(0, 0) - 0.1).abs() < 1e-3);
    }

    fn arm_lqg(output: &str, at: [f64; 2], measured: &str) -> Params {
        Params::new()
            .with("measured", measured)
            .with("reference", "reference")
            .with("output", "torque")
            .with(
                "plant",
                Params::new()
                    .with("type", "two_link_arm")
                    .with("at", at.to_vec())
                    .with("output", output),
            )
            .with("q", vec![400.0, 400.0, 1.0, 1.0])
            .with("r", vec![0.01, 0.01])
            .with("process_noise", vec![1e-6, 1e-6, 1e-4, 1e-4])
            .with("measurement_noise", 1e-6)
            .with("limit", 50.0)
    }

    #[test]
    fn brings_the_arm_endpoint_to_its_operating_point() {
        let rt = habitat();
        let at = [0.5, 1.0];
        let goal = ArmModel::default().forward_kinematics(at);
        rt.create_mat(CsMat::from_row_slice("reference", 2, 1, &goal).unwrap())
            .unwrap();
        let arm = Params::new()
            .with("torque", "torque")
            .with("angles", "angles")
            .with("endpoint", "endpoint")
            .with("q0", vec![0.55, 0.92]);
        rt.install_component("h", "arm", "two_link_arm", &arm)
            .unwrap();
        rt.install_component("h", "lqg", "lqg", &arm_lqg("endpoint", at, "endpoint"))
            .unwrap();
        let endpoint = rt.mat("endpoint");
        let distance = || (endpoint.value(0, 0) - goal[0]).hypot(endpoint.value(1, 0) - goal[1]);
        let start = distance();
        let settled = settle(&rt, 5.0, 1e-3, distance).expect("within 1 mm after 5 s");
        eprintln!(
            "lqg on the arm endpoint: from {start:.3} m to < 1e-3 m at {settled:.3} s, final \
             {:.2e} m",
            distance()
        );
    }

    #[test]
    fn holds_the_arm_angles_under_gravity() {
        let rt = habitat();
        let at = [0.5, 1.0];
        rt.create_mat(CsMat::from_row_slice("reference", 2, 1, &at).unwrap())
            .unwrap();
        let arm = Params::new()
            .with("torque", "torque")
            .with("angles", "angles")
            .with("endpoint", "endpoint")
            .with("gravity", 9.81)
            .with("q0", vec![0.45, 1.05]);
        rt.install_component("h", "arm", "two_link_arm", &arm)
            .unwrap();
        let mut lqg = arm_lqg("angles", at, "angles");
        if let Some(ParamValue::Table(plant)) = lqg.0.get_mut("plant") {
            plant.0.insert("gravity".into(), ParamValue::Number(9.81));
        }
        rt.install_component("h", "lqg", "lqg", &lqg).unwrap();
        let angles = rt.mat("angles");
        let error = || (angles.value(0, 0) - at[0]).hypot(angles.value(1, 0) - at[1]);
        let settled = settle(&rt, 5.0, 1e-3, error).expect("within 1e-3 rad after 5 s");
        eprintln!("lqg on the arm angles under gravity: < 1e-3 rad from {settled:.3} s");
    }

    #[test]
    fn starts_from_the_state_that_explains_the_measurement() {
        let rt = habitat();
        let at = [0.5, 1.0];
        rt.create_mat(CsMat::from_row_slice("reference", 2, 1, &at).unwrap())
            .unwrap();
        let arm = Params::new()
            .with("torque", "torque")
            .with("angles", "angles")
            .with("endpoint", "endpoint")
            .with("q0", vec![0.45, 1.05]);
        rt.install_component("h", "arm", "two_link_arm", &arm)
            .unwrap();
        let lqg = arm_lqg("angles", at, "angles").with("estimate", "estimate");
        rt.install_component("h", "lqg", "lqg", &lqg).unwrap();
        let habitat = rt.habitat("h");
        habitat.start().unwrap();
        habitat.step().unwrap();
        let estimate = rt.mat("estimate").snapshot();
        let expected = [-0.05, 0.05, 0.0, 0.0];
        for (i, want) in expected.iter().enumerate() {
            let got = estimate.get(i, 0).unwrap();
            assert!((got - want).abs() < 1e-9, "x̂[{i}] = {got}, expected {want}");
        }
        habitat.stop();
    }

    fn install_error(params: &Params) -> String {
        let rt = habitat();
        rt.install_component("h", "lqg", "lqg", params)
            .expect_err("refused")
            .to_string()
    }

    #[test]
    fn bad_models_are_refused_by_name() {
        let base = Params::new()
            .with("measured", "y")
            .with("reference", "r")
            .with("output", "u")
            .with("q", 1.0)
            .with("r", 1.0)
            .with("process_noise", 1.0)
            .with("measurement_noise", 1.0);
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let explicit = base
            .clone()
            .with("a", a.clone())
            .with("b", b.clone())
            .with("c", c.clone());
        let cases = [
            (
                base.clone()
                    .with("plant", Params::new().with("type", "pendulum")),
                "`plant.type`",
            ),
            (
                base.clone().with(
                    "plant",
                    Params::new()
                        .with("type", "mass_spring_damper")
                        .with("stifness", 3.0),
                ),
                "`plant.stifness`",
            ),
            (
                base.clone()
                    .with("plant", Params::new().with("type", "two_link_arm")),
                "`plant.at`",
            ),
            (
                base.clone().with(
                    "plant",
                    Params::new()
                        .with("type", "two_link_arm")
                        .with("at", vec![0.3, 0.0])
                        .with("output", "endpoint"),
                ),
                "singular",
            ),
            (
                explicit.clone().with("b", DMatrix::from_element(3, 1, 1.0)),
                "`b`",
            ),
            (
                explicit.clone().with("c", DMatrix::from_element(1, 3, 1.0)),
                "`c`",
            ),
            (
                explicit.clone().with("a", DMatrix::from_element(2, 3, 1.0)),
                "`a`",
            ),
            (base.clone().with("a", a.clone()), "all three"),
            (base.clone(), "`plant`"),
            (
                explicit
                    .clone()
                    .with("plant", Params::new().with("type", "mass_spring_damper")),
                "not both",
            ),
            (explicit.clone().with("q", vec![1.0, 2.0, 3.0]), "`q`"),
            (explicit.clone().with("r", -1.0), "`r`"),
            (explicit.clone().with("limit", 0.0), "`limit`"),
            (explicit.clone().with("estimate", "y"), "`y`"),
        ];
        for (params, needle) in cases {
            let err = install_error(&params);
            assert!(err.contains(needle), "{needle}: {err}");
        }
        // The explicit model itself is fine.
        habitat()
            .install_component("h", "lqg", "lqg", &explicit)
            .unwrap();
    }

    #[test]
    fn an_uncontrollable_unstable_model_is_refused() {
        let base = Params::new()
            .with("measured", "y")
            .with("reference", "r")
            .with("output", "u")
            .with("q", 1.0)
            .with("r", 1.0)
            .with("process_noise", 1.0)
            .with("measurement_noise", 1.0)
            .with("a", DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 1.0]))
            .with("b", DMatrix::from_row_slice(2, 1, &[1.0, 0.0]))
            .with("c", DMatrix::from_row_slice(1, 2, &[1.0, 1.0]));
        let err = install_error(&base);
        assert!(err.contains("lqg: "), "{err}");
    }
}

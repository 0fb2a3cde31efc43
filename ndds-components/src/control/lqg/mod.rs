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

mod model;
mod weights;

pub use model::{ArmOutput, LqgModel, MassOutput};

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::design::spectral_radius;
use crate::mats::{copy_out, gemm, shape_error};
use crate::params::failed;
use crate::{LqgDesign, LqgWeights, design_lqg};
use model::Linear;
use weights::{check_weight, weight_matrix};

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
        return Err(shape_error(
            "input",
            value.name(),
            value.shape(),
            buffer.shape(),
        ));
    }
    if !value.matrix().iter().all(|x| x.is_finite()) {
        return Err(failed(format!(
            "input `{}` holds a non-finite value",
            value.name()
        )));
    }
    buffer.copy_from(value.matrix());
    *buffer -= offset;
    Ok(())
}

/// LQG controller: steady-state Kalman estimator and LQR state feedback with reference
/// feedforward, u = u0 + N·(r − y0) − K·x̂, designed at the habitat's rate on an explicit model
/// (a, b, c) or a linearised library plant (plant).
///
/// See the module docs for the equations. Reads `measured` and `reference` (p × 1) in
/// `execute`, writes the command `output` (m × 1) and, if asked for, `estimate` (n × 1, the
/// state's deviation from the operating point). The gains are designed at the habitat's
/// period in `startup` and again in `timing_changed`. Enabling (and resetting) it starts the
/// estimate from the minimum-norm state that explains the current measurement, `x̂⁻ = C⁺·δy`
/// (at rest), so it can take over from another controller without a bump.
#[derive(Component)]
#[component(name = "lqg")]
pub struct Lqg {
    #[state(init = LqgModel::from_parts(
        _plant.as_ref(),
        [_a.as_ref(), _b.as_ref(), _c.as_ref()],
    )?
    .linear()?)]
    linear: Linear,
    #[state(init = weights(&linear, [&_q, &_r, &_process_noise, &_measurement_noise])?)]
    weights: LqgWeights,
    /// C⁺, for the bumpless start (the design tested first).
    #[state(init = prepare(&linear, &weights)?)]
    c_pinv: DMatrix<f64>,
    /// y (p × 1), in the plant's units
    #[input(shape = (linear.c.nrows(), 1))]
    measured: Mat,
    /// r (p × 1): the desired y, in the same units
    #[input(shape = (linear.c.nrows(), 1))]
    reference: Mat,
    /// u (m × 1), the command
    #[output(shape = (linear.b.ncols(), 1))]
    output: Mat,
    /// x̂ (n × 1): the estimated state's deviation from the operating point
    #[output(shape = (linear.a.nrows(), 1))]
    estimate: Option<Mat>,
    /// a library plant to linearise instead of a, b, c: { type = "mass_spring_damper", mass,
    /// stiffness, damping, length, output = "position" | "angle" } (defaults as the component,
    /// output position) or { type = "two_link_arm", l1, l2, m1, m2, damping, gravity, at =
    /// [q1, q2] (required, rad), output = "angles" | "endpoint" } (defaults as the component,
    /// output angles)
    #[param]
    _plant: Option<Params>,
    /// continuous A (n × n), with b and c
    #[param]
    _a: Option<DMatrix<f64>>,
    /// continuous B (n × m), with a and c
    #[param]
    _b: Option<DMatrix<f64>>,
    /// C (p × n), with a and b
    #[param]
    _c: Option<DMatrix<f64>>,
    /// state cost (n × n, or its diagonal as a list, or one number × I)
    #[param]
    _q: DMatrix<f64>,
    /// command cost (m × m positive definite, or its diagonal, or a number)
    #[param]
    _r: DMatrix<f64>,
    /// process noise covariance (n × n, or its diagonal, or a number)
    #[param]
    _process_noise: DMatrix<f64>,
    /// measurement noise covariance (p × p positive definite, or its diagonal, or a number)
    #[param]
    _measurement_noise: DMatrix<f64>,
    /// clamp each command element to [−limit, limit] (command units; `inf`: no clamp)
    #[param(above = 0, finite = false)]
    limit: Option<f64>,
    /// `None` until `startup` (or after a failed redesign).
    design: Option<LqgDesign>,
    #[state(init = DMatrix::zeros(linear.c.nrows(), 1))]
    y: DMatrix<f64>,
    #[state(init = DMatrix::zeros(linear.c.nrows(), 1))]
    r: DMatrix<f64>,
    #[state(init = DMatrix::zeros(linear.c.nrows(), 1))]
    innovation: DMatrix<f64>,
    #[state(init = DMatrix::zeros(linear.a.nrows(), 1))]
    predicted: DMatrix<f64>,
    #[state(init = DMatrix::zeros(linear.a.nrows(), 1))]
    corrected: DMatrix<f64>,
    #[state(init = DMatrix::zeros(linear.b.ncols(), 1))]
    du: DMatrix<f64>,
    #[state(init = DMatrix::zeros(linear.b.ncols(), 1))]
    u: DMatrix<f64>,
}

/// The weight parameters `[q, r, process_noise, measurement_noise]` as matrices of the
/// model's dimensions, checked.
fn weights(linear: &Linear, given: [&DMatrix<f64>; 4]) -> Result<LqgWeights, ModuleError> {
    let (n, m, p) = linear.dims();
    let [q, r, process_noise, measurement_noise] = given;
    let weights = LqgWeights {
        q: weight_matrix("q", q, n)?,
        r: weight_matrix("r", r, m)?,
        process_noise: weight_matrix("process_noise", process_noise, n)?,
        measurement_noise: weight_matrix("measurement_noise", measurement_noise, p)?,
    };
    check_weights(linear, &weights)?;
    Ok(weights)
}

/// Refuses weights of the wrong shape, asymmetric or not (semi-)definite.
fn check_weights(linear: &Linear, weights: &LqgWeights) -> RoutineResult {
    let (n, m, p) = linear.dims();
    check_weight("q", &weights.q, n, false)?;
    check_weight("r", &weights.r, m, true)?;
    check_weight("process_noise", &weights.process_noise, n, false)?;
    check_weight("measurement_noise", &weights.measurement_noise, p, true)
}

/// Test-designs at [`Lqg::NOMINAL_DT`], failing with the reason if that is impossible;
/// returns C⁺.
fn prepare(linear: &Linear, weights: &LqgWeights) -> Result<DMatrix<f64>, ModuleError> {
    design(linear, weights, Lqg::NOMINAL_DT)?;
    linear
        .c
        .clone()
        .pseudo_inverse(1e-12)
        .map_err(|e| failed(format!("lqg: C has no pseudo-inverse: {e}")))
}

impl Lqg {
    /// The period (s) at which [`Lqg::new`] test-designs the controller, to refuse a model or
    /// weights that cannot work before any habitat runs it (the real design is at the
    /// habitat's period, in `startup` and `timing_changed`).
    pub const NOMINAL_DT: f64 = 0.01;

    /// Reads `measured` and `reference` (p × 1), writes `output` (m × 1) and `estimate`
    /// (n × 1) if given. Checks the model and weights and test-designs the controller at
    /// [`NOMINAL_DT`](Self::NOMINAL_DT), failing with the reason if that is impossible. `limit`, if given,
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
        let LqgWeights {
            q,
            r,
            process_noise,
            measurement_noise,
        } = weights;
        let mut params = model
            .params()
            .with("measured", measured)
            .with("reference", reference)
            .with("output", output)
            .with("q", q)
            .with("r", r)
            .with("process_noise", process_noise)
            .with("measurement_noise", measurement_noise);
        if let Some(estimate) = estimate {
            params = params.with("estimate", estimate);
        }
        if let Some(limit) = limit {
            params = params.with("limit", limit);
        }
        Self::build(b, &params)
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

/// Registers `lqg`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Lqg>();
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::time::Duration;

    use super::*;
    use crate::ArmModel;
    use crate::testing::{assert_refuses, one, refusal, scalar_gain};
    use ndds_runtime::{Clock, CsMat, HabitatOptions, ParamValue, Params, Runtime};

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
        let table = |type_name: &str| Params::new().with("type", type_name);
        let cases = [
            (
                base.clone().with("plant", table("pendulum")),
                "plant.type",
                "unknown plant",
            ),
            (
                base.clone()
                    .with("plant", table("mass_spring_damper").with("stifness", 3.0)),
                "plant.stifness",
                "not a parameter",
            ),
            (
                base.clone().with(
                    "plant",
                    table("mass_spring_damper").with("stiffness", "stiff"),
                ),
                "plant.stiffness",
                "number",
            ),
            (
                base.clone().with("plant", table("two_link_arm")),
                "plant.at",
                "missing",
            ),
            (
                base.clone().with(
                    "plant",
                    table("two_link_arm")
                        .with("at", vec![0.3, 0.0])
                        .with("output", "endpoint"),
                ),
                "plant.at",
                "singular",
            ),
            (
                base.clone().with(
                    "plant",
                    table("two_link_arm")
                        .with("l2", -1.0)
                        .with("at", vec![0.5, 1.0]),
                ),
                "plant.l2",
                "positive",
            ),
            (
                explicit.clone().with("b", DMatrix::from_element(3, 1, 1.0)),
                "b",
                "2 rows",
            ),
            (
                explicit.clone().with("c", DMatrix::from_element(1, 3, 1.0)),
                "c",
                "2 columns",
            ),
            (
                explicit.clone().with("a", DMatrix::from_element(2, 3, 1.0)),
                "a",
                "square",
            ),
            (
                explicit
                    .clone()
                    .with("a", DMatrix::from_element(2, 2, f64::NAN)),
                "a",
                "finite",
            ),
            (base.clone().with("a", a.clone()), "b", "all three"),
            (base.clone(), "plant", "missing"),
            (
                explicit.clone().with("plant", table("mass_spring_damper")),
                "plant",
                "not both",
            ),
            (
                explicit.clone().with("q", vec![1.0, 2.0, 3.0]),
                "q",
                "diagonal",
            ),
            (explicit.clone().with("r", -1.0), "r", "positive definite"),
            (explicit.clone().with("limit", 0.0), "limit", "positive"),
            (explicit.clone().with("limit", f64::NAN), "limit", "NaN"),
        ];
        for (params, name, says) in cases {
            assert_refuses(&refusal(&habitat(), "lqg", &params), name, &[says]);
        }
        let err = install_error(&explicit.clone().with("estimate", "y"));
        assert!(err.contains("`y`") && err.contains("twice"), "{err}");
        // The explicit model itself is fine, and so is an infinite limit (no clamp).
        habitat()
            .install_component("h", "lqg", "lqg", &explicit)
            .unwrap();
        habitat()
            .install_component("h", "lqg", "lqg", &explicit.with("limit", f64::INFINITY))
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

//! `pid`: PID control on the measurement, with output limits and anti-windup.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::mats::{copy_in, copy_out, shape_error};
use crate::params::failed;

/// Gains, derivative filter and output limits of a [`Pid`]. `Default` is all gains 0, no
/// filter and no limits; set what you need:
/// `PidTuning { kp: 2.0, ki: 1.0, ..PidTuning::default() }`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PidTuning {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain (1/s).
    pub ki: f64,
    /// Derivative gain (s).
    pub kd: f64,
    /// Time constant of the derivative's first-order filter (s, 0 = none).
    pub tau: f64,
    /// Lowest output (may be −∞).
    pub lower: f64,
    /// Highest output (may be +∞).
    pub upper: f64,
}

impl Default for PidTuning {
    fn default() -> Self {
        Self {
            kp: 0.0,
            ki: 0.0,
            kd: 0.0,
            tau: 0.0,
            lower: f64::NEG_INFINITY,
            upper: f64::INFINITY,
        }
    }
}

/// PID on the measurement: u = clamp(kp·e + ki·∫e + kd·d(−y)/dt, lower, upper), e = r − y,
/// element by element; the derivative optionally filtered (tau); anti-windup by conditional
/// integration (the integrator does not move further into the limit the output is held at).
///
/// Precisely, for each element (n × 1): `u = clamp(kp·e + I + kd·D, lower, upper)`,
/// `I = Σ ki·e·dt`, `D = (tau·D⁻ − (y − y⁻)) / (tau + dt)` (the derivative of −y through a
/// first-order filter with time constant `tau`; for `tau = 0`, `−(y − y⁻)/dt`).
///
/// The derivative acts on the measurement, so reference steps do not kick. Anti-windup is
/// conditional integration: while the unclamped output is above `upper` the integrator does
/// not grow, and while it is below `lower` it does not shrink; it only moves in the direction
/// that brings the output back inside the limits. `kp`, `ki`, `kd`, `tau`, `lower`, `upper`
/// are the 1 × 1 parameters `"{module}.kp"`, `.ki`, … (tunable while sampling; `I` holds
/// `ki·∫e`, so changing `ki` does not bump the output). Enabling or resetting it clears the
/// integrator and the filter and takes the current measurement as the previous one.
#[derive(Component)]
#[component(name = "pid", finish = Self::check_limits)]
pub struct Pid {
    /// y (n × 1)
    #[input]
    measured: Mat,
    /// r (n × 1)
    #[input(same_as = measured)]
    reference: Mat,
    /// u (n × 1)
    #[output(same_as = measured)]
    output: Mat,
    /// proportional gain (a CSMat `<module>.kp`, tunable)
    #[param(tunable)]
    kp: Mat,
    /// integral gain (`<module>.ki`, tunable)
    #[param(tunable, default = 0.0, unit = "1/s")]
    ki: Mat,
    /// derivative gain (`<module>.kd`, tunable)
    #[param(tunable, default = 0.0, unit = "s")]
    kd: Mat,
    /// lowest output (`<module>.lower`, tunable)
    #[param(tunable, default = f64::NEG_INFINITY, default_doc = "none", finite = false)]
    lower: Mat,
    /// highest output, ≥ lower (`<module>.upper`, tunable)
    #[param(tunable, default = f64::INFINITY, default_doc = "none", finite = false)]
    upper: Mat,
    /// derivative filter time constant (0 = unfiltered; `<module>.tau`, tunable)
    #[param(tunable, default = 0.0, unit = "s", min = 0)]
    tau: Mat,
    y: DMatrix<f64>,
    r: DMatrix<f64>,
    u: DMatrix<f64>,
    /// State: the integral term, the filtered derivative, the last measurement.
    integral: DMatrix<f64>,
    derivative: DMatrix<f64>,
    previous: DMatrix<f64>,
    /// This sample's integrator increment and derivative, committed by `state_update`.
    increment: DMatrix<f64>,
    next_derivative: DMatrix<f64>,
    primed: bool,
    computed: bool,
}

impl Pid {
    /// Reads `measured` and `reference` (n × 1 each), writes `output` (n × 1).
    pub fn new(
        b: &mut Binder<'_>,
        measured: &str,
        reference: &str,
        output: &str,
        tuning: PidTuning,
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("measured", measured)
            .with("reference", reference)
            .with("output", output)
            .with("kp", tuning.kp)
            .with("ki", tuning.ki)
            .with("kd", tuning.kd)
            .with("tau", tuning.tau)
            .with("lower", tuning.lower)
            .with("upper", tuning.upper);
        Self::build(b, &params)
    }

    /// Refuses limits that are NaN or crossed (infinite limits are no limits).
    fn check_limits(&mut self, _: &mut Binder<'_>) -> Result<(), ModuleError> {
        let lower = self.lower.read().get(0, 0)?;
        let upper = self.upper.read().get(0, 0)?;
        if lower.is_nan() || upper.is_nan() || lower > upper {
            return Err(ModuleError::param(
                "lower",
                format!("{lower} must be ≤ `upper` {upper}"),
            ));
        }
        Ok(())
    }

    /// Fresh state shaped like the measurement (allocates only when the shape changes).
    fn prime(&mut self) {
        let (rows, cols) = self.y.shape();
        for buffer in [
            &mut self.u,
            &mut self.integral,
            &mut self.derivative,
            &mut self.increment,
            &mut self.next_derivative,
        ] {
            if buffer.shape() != (rows, cols) {
                *buffer = DMatrix::zeros(rows, cols);
            }
            buffer.fill(0.0);
        }
        if self.previous.shape() != (rows, cols) {
            self.previous = self.y.clone();
        }
        self.previous.copy_from(&self.y);
        self.primed = true;
    }
}

impl SampleModule for Pid {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.computed = false;
        let kp = self.kp.read().get(0, 0)?;
        let ki = self.ki.read().get(0, 0)?;
        let kd = self.kd.read().get(0, 0)?;
        let tau = self.tau.read().get(0, 0)?;
        // One statement each: a guard lives to the end of its statement (one lock at a time).
        let lower = self.lower.read().get(0, 0)?;
        let upper = self.upper.read().get(0, 0)?;
        if tau.is_nan() || tau < 0.0 {
            return Err(failed(format!(
                "`{}` is {tau}, expected ≥ 0",
                self.tau.name()
            )));
        }
        if lower.is_nan() || upper.is_nan() || lower > upper {
            return Err(failed(format!(
                "`{}` {lower} is not ≤ `{}` {upper}",
                self.lower.name(),
                self.upper.name()
            )));
        }
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
        if !self.primed || self.integral.shape() != self.y.shape() {
            self.prime();
        }
        let dt = ctx.dt();
        for i in 0..self.y.len() {
            let (y, e) = (self.y[i], self.r[i] - self.y[i]);
            let d = (tau * self.derivative[i] - (y - self.previous[i])) / (tau + dt);
            let unclamped = kp * e + self.integral[i] + kd * d;
            let step = ki * e * dt;
            let winding_up = (unclamped > upper && step > 0.0) || (unclamped < lower && step < 0.0);
            self.increment[i] = if winding_up { 0.0 } else { step };
            self.next_derivative[i] = d;
            self.u[i] = if unclamped > upper {
                upper
            } else if unclamped < lower {
                lower
            } else {
                unclamped
            };
        }
        self.computed = true;
        copy_out(&self.output, &self.u)
    }

    fn state_update(&mut self, _: &SampleContext) -> RoutineResult {
        if self.computed {
            self.integral += &self.increment;
            self.derivative.copy_from(&self.next_derivative);
            self.previous.copy_from(&self.y);
            self.computed = false;
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

/// Registers `pid`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Pid>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::{Params, Runtime};

    use crate::testing::{TestResult, assert_refuses, refusal, runtime, trace};

    const DT: f64 = 0.01;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    /// `plant`: y⁺ = 0.9·y + 0.1·u (DC gain 1); `pid` from `r` and `y` to `u`.
    fn pid_loop(rt: &Runtime, pid: Params) -> TestResult {
        let plant = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("a", 0.9)
            .with("b", 0.1)
            .with("c", 1.0);
        rt.install_component("h", "plant", "state_space", &plant)?;
        let pid = pid
            .with("measured", "y")
            .with("reference", "r")
            .with("output", "u");
        rt.install_component("h", "pid", "pid", &pid)?;
        Ok(())
    }

    #[test]
    fn pid_known_answers() -> TestResult {
        // e = 0.8: u0 = kp·e, then the integral adds ki·e·dt each sample.
        let rt = runtime(1.0 / DT, &[("y", &[0.2]), ("r", &[1.0])])?;
        let params = Params::new()
            .with("measured", "y")
            .with("reference", "r")
            .with("output", "u")
            .with("kp", 2.0)
            .with("ki", 10.0);
        rt.install_component("h", "pid", "pid", &params)?;
        let u = &trace(&rt, &["u"], 3)?[0];
        assert!(
            close(u[0], 1.6) && close(u[1], 1.68) && close(u[2], 1.76),
            "{u:?}"
        );
        // The limits are tunable; crossed limits fail the sample, naming them.
        rt.mat("pid.upper").write().set(0, 0, 1.0)?;
        let h = rt.habitat("h");
        h.step()?;
        assert_eq!(rt.mat("u").value(0, 0), 1.0);
        rt.mat("pid.lower").write().set(0, 0, 2.0)?;
        h.step()?;
        assert_eq!(h.stats().module_errors, 1);

        // The derivative of the measurement y = 3·t, first unfiltered, then through tau.
        for tau in [0.0, 0.02] {
            let rt = runtime(1.0 / DT, &[("r", &[5.0])])?;
            let ramp = Params::new().with("output", "y").with("slope", 3.0);
            rt.install_component("h", "ramp", "ramp", &ramp)?;
            let params = Params::new()
                .with("measured", "y")
                .with("reference", "r")
                .with("output", "u")
                .with("kp", 0.0)
                .with("kd", 0.5)
                .with("tau", tau);
            rt.install_component("h", "pid", "pid", &params)?;
            let u = &trace(&rt, &["u"], 4)?[0];
            let mut d = 0.0;
            assert_eq!(u[0], 0.0, "enabled without a derivative jump");
            for (k, u) in u.iter().enumerate().skip(1) {
                d = (tau * d - 3.0 * DT) / (tau + DT);
                assert!(
                    close(*u, 0.5 * d),
                    "tau {tau}, u[{k}] = {u}, expected {}",
                    0.5 * d
                );
            }
        }
        Ok(())
    }

    #[test]
    fn pid_reaches_the_reference_without_steady_state_error() -> TestResult {
        let rt = runtime(1.0 / DT, &[("r", &[1.0])])?;
        pid_loop(&rt, Params::new().with("kp", 2.0).with("ki", 5.0))?;
        let [y] = &trace(&rt, &["y"], 1000)?[..] else {
            unreachable!()
        };
        assert!((y[999] - 1.0).abs() < 1e-6, "y = {}", y[999]);
        Ok(())
    }

    /// Samples after index `from` until `trace` stays within `tolerance` of `target`.
    fn settling(trace: &[f64], from: usize, target: f64, tolerance: f64) -> usize {
        let last_out = trace
            .iter()
            .rposition(|y| (y - target).abs() > tolerance)
            .unwrap_or(0);
        last_out.saturating_sub(from)
    }

    #[test]
    fn pid_does_not_wind_up_while_saturated() -> TestResult {
        // The reference 2 is out of reach for u ≤ 1.2 (y → 1.2) for 5 s, then drops to 1.
        let (kp, ki, upper, switch) = (2.0, 5.0, 1.2, 500);
        let rt = runtime(1.0 / DT, &[])?;
        let reference = Params::new()
            .with("output", "r")
            .with("initial", 2.0)
            .with("final", 1.0)
            .with("at", switch as f64 * DT);
        rt.install_component("h", "ref", "step", &reference)?;
        let limits = Params::new()
            .with("kp", kp)
            .with("ki", ki)
            .with("lower", -upper)
            .with("upper", upper);
        pid_loop(&rt, limits)?;
        let out = trace(&rt, &["y", "u"], 1500)?;
        let (y, u) = (&out[0], &out[1]);
        assert!(
            u.iter().all(|u| u.abs() <= upper),
            "output outside its limits"
        );
        assert!(
            (y[switch - 1] - upper).abs() < 1e-3,
            "y = {}",
            y[switch - 1]
        );
        // The integrator held near 0, so the loop settles like a fresh PI step (about 2 s).
        let settle = settling(y, switch, 1.0, 0.01);
        assert!(
            settle < 300,
            "took {settle} samples to settle after the saturation"
        );
        assert!((y[1499] - 1.0).abs() < 1e-6);

        // The same loop integrating all the time winds up to I ≈ 10 and is still more than 1 %
        // off 10 s later.
        let (mut plant, mut integral, mut windup) = (0.0, 0.0, Vec::new());
        for k in 0..1500 {
            let r = if k < switch { 2.0 } else { 1.0 };
            let e = r - plant;
            let u = (kp * e + integral).clamp(-upper, upper);
            integral += ki * e * DT;
            plant = 0.9 * plant + 0.1 * u;
            windup.push(plant);
        }
        let windup_settle = settling(&windup, switch, 1.0, 0.01);
        assert!(windup_settle > 3 * settle, "{windup_settle} vs {settle}");
        Ok(())
    }

    #[test]
    fn bad_gains_and_limits_are_refused_by_name() -> TestResult {
        let rt = runtime(1.0 / DT, &[("u", &[0.0])])?;
        let pid = Params::new()
            .with("measured", "u")
            .with("reference", "r")
            .with("output", "y")
            .with("kp", 1.0);
        let err = refusal(
            &rt,
            "pid",
            &pid.clone().with("lower", 1.0).with("upper", -1.0),
        );
        assert_refuses(&err, "lower", &["`upper`"]);
        let err = refusal(&rt, "pid", &pid.clone().with("tau", -0.1));
        assert_refuses(&err, "tau", &["negative"]);
        let err = refusal(&rt, "pid", &pid.with("ki", f64::NAN));
        assert_refuses(&err, "ki", &["finite"]);
        Ok(())
    }
}

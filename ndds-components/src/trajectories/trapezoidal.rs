//! `trapezoidal`: a trapezoidal velocity profile per joint.

use ndds_runtime::{Binder, Component, Mat, ModuleError, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::{Motion, PointToPoint};

/// Per joint, the timing of a trapezoidal profile over a unit distance.
#[derive(Clone, Copy, Debug)]
struct Timing {
    /// Acceleration time, peak speed, total time (all in fractions of the distance).
    ramp: f64,
    peak: f64,
    total: f64,
    accel: f64,
}

impl Timing {
    /// Distance `d ≥ 0` with speed cap `v` and acceleration cap `a`, scaled to `s ∈ [0, 1]`.
    fn new(d: f64, v: f64, a: f64) -> Self {
        if d == 0.0 {
            return Self {
                ramp: 0.0,
                peak: 0.0,
                total: 0.0,
                accel: 0.0,
            };
        }
        let (ramp, peak, total) = if d >= v * v / a {
            (v / a, v, d / v + v / a)
        } else {
            let ramp = (d / a).sqrt();
            (ramp, a * ramp, 2.0 * ramp)
        };
        Self {
            ramp,
            peak: peak / d,
            total,
            accel: a / d,
        }
    }

    /// `(s, ds/dt)` at `τ > 0`.
    fn at(&self, tau: f64) -> (f64, f64) {
        let (ramp, a) = (self.ramp, self.accel);
        if tau >= self.total {
            (1.0, 0.0)
        } else if tau < ramp {
            (a * tau * tau / 2.0, a * tau)
        } else if tau < self.total - ramp {
            (a * ramp * ramp / 2.0 + self.peak * (tau - ramp), self.peak)
        } else {
            let left = self.total - tau;
            (1.0 - a * left * left / 2.0, a * left)
        }
    }
}

/// Trapezoidal velocity profile per joint from start to goal: accelerate at
/// max_acceleration to max_velocity, cruise, stop at the goal (triangular when the distance
/// is short); joints are not synchronised.
///
/// A move over a distance `d` takes `d/v + v/a` seconds; when `d < v²/a` the profile is
/// triangular (peak speed `√(a·d)`, time `2·√(d/a)`).
#[derive(Component)]
#[component(name = "trapezoidal")]
pub struct Trapezoidal {
    #[state(init = Motion::new(&_start, &_goal, _at)?)]
    motion: Motion,
    /// position (n × 1)
    #[output(shape = (motion.len(), 1))]
    position: Mat,
    /// velocity (n × 1), written only when given
    #[output(shape = (motion.len(), 1))]
    velocity: Option<Mat>,
    /// start position, one value per joint
    #[param]
    _start: Vec<f64>,
    /// goal position, one value per joint
    #[param]
    _goal: Vec<f64>,
    /// when the move begins, after the module is enabled
    #[param(default = 0.0, unit = "s")]
    _at: f64,
    /// speed limit, one value or one per joint
    #[param(above = 0)]
    _max_velocity: Vec<f64>,
    /// acceleration limit, one value or one per joint
    #[param(above = 0)]
    _max_acceleration: Vec<f64>,
    #[state(init = timing(&motion, &_max_velocity, &_max_acceleration)?)]
    timing: Vec<Timing>,
}

/// Each joint's timing, from limits with one value or one per joint (all positive).
fn timing(
    motion: &Motion,
    max_velocity: &[f64],
    max_acceleration: &[f64],
) -> Result<Vec<Timing>, ModuleError> {
    let n = motion.len();
    let limits = [
        ("max_velocity", max_velocity),
        ("max_acceleration", max_acceleration),
    ];
    for (name, values) in limits {
        if values.len() != 1 && values.len() != n {
            return Err(ModuleError::param(
                name,
                format!("has {} values; expected one or {n}", values.len()),
            ));
        }
    }
    Ok((0..n)
        .map(|i| {
            let v = max_velocity[i % max_velocity.len()];
            let a = max_acceleration[i % max_acceleration.len()];
            Timing::new(motion.distance[i].abs(), v, a)
        })
        .collect())
}

impl Trapezoidal {
    /// Moves along `path`; `max_velocity` and `max_acceleration` (> 0) have one value for all
    /// joints or one per joint. `velocity`, when given, is written too.
    pub fn new(
        b: &mut Binder<'_>,
        position: &str,
        velocity: Option<&str>,
        path: &PointToPoint<'_>,
        max_velocity: &[f64],
        max_acceleration: &[f64],
    ) -> Result<Self, ModuleError> {
        let params = path
            .params(position, velocity)
            .with("max_velocity", max_velocity.to_vec())
            .with("max_acceleration", max_acceleration.to_vec());
        Self::build(b, &params)
    }
}

impl SampleModule for Trapezoidal {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let timing = &self.timing;
        let outputs = (&self.position, self.velocity.as_ref());
        self.motion.write(ctx, outputs, |i, tau| timing[i].at(tau))
    }

    fn enable(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.motion.restart(ctx)
    }

    fn reset(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.motion.restart(ctx)
    }
}

/// Registers `trapezoidal`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Trapezoidal>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::testing::{TestResult, assert_refuses};
    use crate::trajectories::testing::{refused, run};

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn trapezoidal_cruises_at_max_velocity_and_arrives_on_time() -> TestResult {
        // Joint 0: 2 m at 1 m/s, 2 m/s² → trapezoid, T = d/v + v/a = 2.5 s.
        // Joint 1: 0.1 m < v²/a → triangle, T = 2·√(d/a) ≈ 0.447 s, peak √(a·d) ≈ 0.447 m/s.
        let params = Params::new()
            .with("start", vec![0.0, 0.5])
            .with("goal", vec![2.0, 0.4])
            .with("at", 0.25)
            .with("max_velocity", 1.0)
            .with("max_acceleration", 2.0);
        let [p, v] = run("trapezoidal", params, 300)?;
        // Sample k is at t = k/100 s, τ = t − 0.25 s into the move.
        assert_eq!((p[0][25], v[0][25]), (0.0, 0.0));
        assert!(close(p[0][125], 0.75), "p(τ = 1 s) = {}", p[0][125]);
        let peak = v[0].iter().copied().fold(0.0, f64::max);
        assert!(close(peak, 1.0), "peak velocity {peak}");
        assert!(p[0][274] < 2.0 && v[0][274] > 0.0);
        assert_eq!((p[0][275], v[0][275]), (2.0, 0.0));
        assert_eq!(p[0][299], 2.0);

        let peak = v[1].iter().copied().fold(0.0, f64::min);
        assert!(
            peak < 0.0 && -peak <= 0.2f64.sqrt() + 1e-12,
            "peak velocity {peak}"
        );
        assert!(-peak > 0.2f64.sqrt() - 0.02, "peak velocity {peak}");
        assert!(p[1][69] > 0.4 && v[1][69] < 0.0, "τ = 0.44 s: still moving");
        assert_eq!((p[1][70], v[1][70]), (0.4, 0.0));
        Ok(())
    }

    #[test]
    fn bad_limits_are_refused_by_name() {
        let limits = |v: f64| {
            Params::new()
                .with("start", vec![0.0, 0.0])
                .with("goal", vec![1.0, 1.0])
                .with("max_velocity", v)
                .with("max_acceleration", 1.0)
        };
        let err = refused("trapezoidal", limits(0.0));
        assert_refuses(&err, "max_velocity", &["positive"]);
        let err = refused(
            "trapezoidal",
            limits(1.0).with("max_acceleration", vec![1.0; 3]),
        );
        assert_refuses(&err, "max_acceleration", &["expected one or 2"]);
    }
}

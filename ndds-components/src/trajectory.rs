//! Point-to-point trajectories: from `start` to `goal`, beginning `at` seconds after the module
//! was enabled (when sampling starts, or when a configuration switch makes its group active:
//! a state machine sequences moves by switching configurations), written as a position (and
//! optionally a velocity) each sample. `reset` starts the move over.
//!
//! | type          | module          | writes                   | profile                        |
//! |---------------|-----------------|--------------------------|--------------------------------|
//! | `trapezoidal` | [`Trapezoidal`] | `position`, `velocity`?  | velocity and acceleration cap  |
//! | `quintic`     | [`Quintic`]     | `position`, `velocity`?  | minimum jerk in `duration`     |
//!
//! Each element (joint) moves on its own profile: a trapezoidal joint with a shorter distance
//! arrives earlier; they are not synchronised. Before `at` the position is `start`, after the
//! move `goal`, with zero velocity.

use nalgebra::DMatrix;

use super::sources::param_checks::{columns, finite, problem};
use super::{copy_out, distinct};
use ndds_runtime::Mat;
use ndds_runtime::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Params, Registry};

/// Where a trajectory starts and ends, and when it starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointToPoint<'a> {
    /// Start position, one value per joint.
    pub start: &'a [f64],
    /// Goal position, as many values as `start`.
    pub goal: &'a [f64],
    /// When the move begins (s after the module is enabled).
    pub at: f64,
}

/// The outputs and values shared by both profiles.
struct Motion {
    position: Mat,
    velocity: Option<Mat>,
    start: DMatrix<f64>,
    distance: DMatrix<f64>,
    at: f64,
    /// Sample time (s) when the module was enabled: the move's time zero.
    origin: f64,
    p: DMatrix<f64>,
    v: DMatrix<f64>,
}

impl Motion {
    fn new(
        b: &mut Binder<'_>,
        position: &str,
        velocity: Option<&str>,
        path: &PointToPoint<'_>,
    ) -> Result<Self, ModuleError> {
        if path.start.len() != path.goal.len() {
            return Err(problem(
                "goal",
                format!(
                    "has {} values but `start` has {}; give one per joint",
                    path.goal.len(),
                    path.start.len()
                ),
            ));
        }
        let [start, goal] = columns([("start", path.start), ("goal", path.goal)])?;
        if let Some(velocity) = velocity {
            distinct(&[position, velocity])?;
        }
        let n = start.nrows();
        Ok(Self {
            position: b.output(position, (n, 1)),
            velocity: velocity.map(|v| b.output(v, (n, 1))),
            distance: &goal - &start,
            start,
            at: finite("at", path.at)?,
            origin: 0.0,
            p: DMatrix::zeros(n, 1),
            v: DMatrix::zeros(n, 1),
        })
    }

    fn len(&self) -> usize {
        self.start.nrows()
    }

    /// The move starts over from now.
    fn restart(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.origin = ctx.time.as_secs_f64();
        Ok(())
    }

    /// Writes `start + s·distance` and `ds/dt·distance`, with `profile(i, τ) = (s, ds/dt)`
    /// for joint `i` at `τ = t − at`.
    fn write(
        &mut self,
        ctx: &SampleContext,
        profile: impl Fn(usize, f64) -> (f64, f64),
    ) -> RoutineResult {
        let tau = ctx.time.as_secs_f64() - self.origin - self.at;
        for i in 0..self.len() {
            let (s, ds) = if tau <= 0.0 {
                (0.0, 0.0)
            } else {
                profile(i, tau)
            };
            self.p[i] = self.start[i] + s * self.distance[i];
            self.v[i] = ds * self.distance[i];
        }
        copy_out(&self.position, &self.p)?;
        match &self.velocity {
            Some(velocity) => copy_out(velocity, &self.v),
            None => Ok(()),
        }
    }
}

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

/// A trapezoidal velocity profile per joint: accelerate at `max_acceleration` to
/// `max_velocity`, cruise, decelerate to stop at the goal, taking `d/v + v/a` seconds for a
/// distance `d`; when `d < v²/a` the profile is triangular (peak speed `√(a·d)`, time
/// `2·√(d/a)`).
pub struct Trapezoidal {
    motion: Motion,
    timing: Vec<Timing>,
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
        let motion = Motion::new(b, position, velocity, path)?;
        let n = motion.len();
        let limits = [
            ("max_velocity", max_velocity),
            ("max_acceleration", max_acceleration),
        ];
        for (name, values) in limits {
            if values.len() != 1 && values.len() != n {
                return Err(problem(
                    name,
                    format!("has {} values; expected one or {n}", values.len()),
                ));
            }
            if let Some(bad) = values.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
                return Err(problem(name, format!("{bad} is not a positive number")));
            }
        }
        let timing = (0..n)
            .map(|i| {
                let v = max_velocity[i % max_velocity.len()];
                let a = max_acceleration[i % max_acceleration.len()];
                Timing::new(motion.distance[i].abs(), v, a)
            })
            .collect();
        Ok(Self { motion, timing })
    }
}

impl SampleModule for Trapezoidal {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let timing = &self.timing;
        self.motion.write(ctx, |i, tau| timing[i].at(tau))
    }

    fn enable(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.motion.restart(ctx)
    }

    fn reset(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.motion.restart(ctx)
    }
}

/// A minimum-jerk (quintic) move per joint, lasting `duration` seconds:
/// `p = start + (goal − start)·(10σ³ − 15σ⁴ + 6σ⁵)`, `σ = (t − at)/duration`, with zero
/// velocity and acceleration at both ends; the peak velocity, at mid-move, is
/// `1.875·(goal − start)/duration`.
pub struct Quintic {
    motion: Motion,
    duration: f64,
}

impl Quintic {
    /// Moves along `path` in `duration` (> 0) seconds. `velocity`, when given, is written too.
    pub fn new(
        b: &mut Binder<'_>,
        position: &str,
        velocity: Option<&str>,
        path: &PointToPoint<'_>,
        duration: f64,
    ) -> Result<Self, ModuleError> {
        if !(duration.is_finite() && duration > 0.0) {
            return Err(problem(
                "duration",
                format!("{duration} is not a positive number"),
            ));
        }
        Ok(Self {
            motion: Motion::new(b, position, velocity, path)?,
            duration,
        })
    }
}

impl SampleModule for Quintic {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let duration = self.duration;
        self.motion.write(ctx, |_, tau| {
            let x = (tau / duration).min(1.0);
            let s = x * x * x * (10.0 - 15.0 * x + 6.0 * x * x);
            let ds = 30.0 * x * x * (1.0 - x) * (1.0 - x) / duration;
            (s, ds)
        })
    }

    fn enable(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.motion.restart(ctx)
    }

    fn reset(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.motion.restart(ctx)
    }
}

const START_DOC: &str = "start position, one value per joint";
const GOAL_DOC: &str = "goal position, one value per joint";
const AT_DOC: &str = "when the move begins (s after the module is enabled)";
const POSITION_DOC: &str = "position (n × 1)";
const VELOCITY_DOC: &str = "velocity (n × 1), written only when given";

/// `trapezoidal`.
pub const TRAPEZOIDAL: ComponentSpec = ComponentSpec {
    name: "trapezoidal",
    summary: "Trapezoidal velocity profile per joint from start to goal: accelerate at \
              max_acceleration to max_velocity, cruise, stop at the goal (triangular when the \
              distance is short); joints are not synchronised.",
    params: &[
        P::required("position", K::Output, POSITION_DOC),
        P::optional("velocity", K::Output, "none", VELOCITY_DOC),
        P::required("start", K::Numbers, START_DOC),
        P::required("goal", K::Numbers, GOAL_DOC),
        P::optional("at", K::Number, "0", AT_DOC),
        P::required(
            "max_velocity",
            K::Numbers,
            "speed limit (> 0), one value or one per joint",
        ),
        P::required(
            "max_acceleration",
            K::Numbers,
            "acceleration limit (> 0), one value or one per joint",
        ),
    ],
};

/// `quintic`.
pub const QUINTIC: ComponentSpec = ComponentSpec {
    name: "quintic",
    summary: "Minimum-jerk quintic move from start to goal in `duration` seconds, zero \
              velocity and acceleration at both ends.",
    params: &[
        P::required("position", K::Output, POSITION_DOC),
        P::optional("velocity", K::Output, "none", VELOCITY_DOC),
        P::required("start", K::Numbers, START_DOC),
        P::required("goal", K::Numbers, GOAL_DOC),
        P::optional("at", K::Number, "0", AT_DOC),
        P::required("duration", K::Number, "length of the move (s, > 0)"),
    ],
};

/// The optional `velocity` output's name.
fn velocity(p: &Params) -> Result<Option<&str>, ModuleError> {
    if p.has("velocity") {
        Ok(Some(p.text("velocity")?))
    } else {
        Ok(None)
    }
}

/// `start`, `goal` and `at`, shared by both profiles.
fn path_params(p: &Params) -> Result<(Vec<f64>, Vec<f64>, f64), ModuleError> {
    Ok((
        p.numbers("start")?,
        p.numbers("goal")?,
        p.number_or("at", 0.0)?,
    ))
}

/// Registers this file's component types.
pub(crate) fn register(registry: &mut Registry) {
    registry.add(&TRAPEZOIDAL, |b, p| {
        let (start, goal, at) = path_params(p)?;
        let path = PointToPoint {
            start: &start,
            goal: &goal,
            at,
        };
        Trapezoidal::new(
            b,
            p.text("position")?,
            velocity(p)?,
            &path,
            &p.numbers("max_velocity")?,
            &p.numbers("max_acceleration")?,
        )
    });
    registry.add(&QUINTIC, |b, p| {
        let (start, goal, at) = path_params(p)?;
        let path = PointToPoint {
            start: &start,
            goal: &goal,
            at,
        };
        Quintic::new(
            b,
            p.text("position")?,
            velocity(p)?,
            &path,
            p.number("duration")?,
        )
    });
}

#[cfg(test)]
mod tests {
    use ndds_runtime::{Clock, HabitatOptions, Params, Runtime};

    type TestResult = Result<(), Box<dyn std::error::Error>>;
    type Outcome<T> = Result<T, Box<dyn std::error::Error>>;

    /// Runs `m` of `type_name` (writing `p` and `v`) at 100 Hz for `samples` samples;
    /// returns `[p, v]` after each, per joint: `out[joint][sample]`.
    fn run(type_name: &str, params: Params, samples: usize) -> Outcome<[Vec<Vec<f64>>; 2]> {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        let params = params.with("position", "p").with("velocity", "v");
        rt.install_component("h", "m", type_name, &params)?;
        let h = rt.habitat("h");
        h.start()?;
        let joints = rt.mat("p").shape().0;
        let mut out = [vec![Vec::new(); joints], vec![Vec::new(); joints]];
        for _ in 0..samples {
            h.step()?;
            for (trace, name) in out.iter_mut().zip(["p", "v"]) {
                for (joint, values) in trace.iter_mut().enumerate() {
                    values.push(rt.mat(name).value(joint, 0));
                }
            }
        }
        assert_eq!(h.stats().module_errors, 0);
        Ok(out)
    }

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

    /// A move in a group switched in later starts when it is enabled, not at time zero.
    #[test]
    fn a_move_starts_when_its_group_is_switched_in() -> TestResult {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        rt.group("motion", "Hold", &["hold"])?;
        rt.group("motion", "Move", &["move"])?;
        rt.configuration("Hold", &[("motion", "Hold")])?;
        rt.configuration("Move", &[("motion", "Move")])?;
        let path = |start: f64, goal: f64| {
            Params::new()
                .with("start", vec![start])
                .with("goal", vec![goal])
                .with("duration", 1.0)
                .with("position", "p")
        };
        rt.install_component("h", "hold", "quintic", &path(0.0, 0.0))?;
        rt.install_component("h", "move", "quintic", &path(0.0, 2.0))?;
        rt.switch("Hold")?;
        let h = rt.habitat("h");
        h.start()?;
        for _ in 0..300 {
            h.step()?;
        }
        rt.switch("Move")?;
        h.step()?;
        let first = rt.mat("p").value(0, 0);
        assert!(first < 0.01, "the move jumped ahead: {first}");
        for _ in 0..49 {
            h.step()?;
        }
        // Half way through its 1 s move, 3.5 s after sampling began.
        let mid = rt.mat("p").value(0, 0);
        assert!((mid - 1.0).abs() < 0.05, "mid-move position {mid}");
        for _ in 0..60 {
            h.step()?;
        }
        assert_eq!(rt.mat("p").value(0, 0), 2.0);
        Ok(())
    }

    #[test]
    fn quintic_is_symmetric_with_its_peak_velocity_at_mid_move() -> TestResult {
        let params = Params::new()
            .with("start", vec![1.0, 0.0])
            .with("goal", vec![3.0, -1.0])
            .with("duration", 2.0);
        let [p, v] = run("quintic", params, 250)?;
        assert_eq!((p[0][0], v[0][0]), (1.0, 0.0));
        assert!(close(p[0][100], 2.0) && close(p[1][100], -0.5));
        assert!(close(v[0][100], 1.875 * 2.0 / 2.0), "peak {}", v[0][100]);
        assert!(v[0].iter().all(|x| *x <= v[0][100] + 1e-12));
        assert!(close(p[0][50] + p[0][150], 4.0), "symmetric about mid-move");
        assert!(
            v[0][1] > 0.0 && v[0][1] < 1e-3,
            "starts gently: {}",
            v[0][1]
        );
        assert_eq!((p[0][200], v[0][200]), (3.0, 0.0));
        assert_eq!((p[1][249], v[1][249]), (-1.0, 0.0));
        Ok(())
    }

    #[test]
    fn velocity_is_optional() -> TestResult {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        let params = Params::new()
            .with("position", "p")
            .with("start", 0.0)
            .with("goal", 1.0)
            .with("duration", 1.0);
        rt.install_component("h", "m", "quintic", &params)?;
        assert_eq!(rt.mat("p").shape(), (1, 1));
        assert!(rt.verify().is_ok(), "{}", rt.verify());
        rt.habitat("h").start()?;
        rt.habitat("h").step()?;
        assert_eq!(rt.habitat("h").stats().module_errors, 0);
        Ok(())
    }

    #[test]
    fn bad_parameters_fail_the_install_naming_them() {
        let error = |type_name: &str, params: Params| {
            let rt = Runtime::new("t");
            crate::register(&rt);
            let params = params.with("position", "p");
            match rt.install_component("h", "m", type_name, &params) {
                Ok(()) => panic!("{type_name} with bad parameters was installed"),
                Err(err) => err.to_string(),
            }
        };
        let path = || {
            Params::new()
                .with("start", vec![0.0, 0.0])
                .with("goal", vec![1.0, 1.0])
        };
        let limits = |v: f64| path().with("max_velocity", v).with("max_acceleration", 1.0);
        let err = error("trapezoidal", limits(0.0));
        assert!(
            err.contains("`max_velocity`") && err.contains("positive"),
            "{err}"
        );
        let err = error(
            "trapezoidal",
            limits(1.0).with("max_acceleration", vec![1.0; 3]),
        );
        assert!(err.contains("`max_acceleration`"), "{err}");
        let err = error("quintic", path().with("duration", -1.0));
        assert!(
            err.contains("`duration`") && err.contains("positive"),
            "{err}"
        );
        let err = error("quintic", path().with("goal", 1.0).with("duration", 1.0));
        assert!(
            err.contains("`goal`") && err.contains("`start` has 2"),
            "{err}"
        );
        let err = error(
            "quintic",
            path().with("duration", 1.0).with("velocity", "p"),
        );
        assert!(err.contains("`p`") && err.contains("twice"), "{err}");
    }
}

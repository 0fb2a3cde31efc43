//! `quintic`: a minimum-jerk move per joint.

use ndds_runtime::{Binder, Component, Mat, ModuleError, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::{Motion, PointToPoint};

/// Minimum-jerk quintic move from start to goal in `duration` seconds, zero velocity and
/// acceleration at both ends.
///
/// Per joint, `p = start + (goal − start)·(10σ³ − 15σ⁴ + 6σ⁵)`, `σ = (t − at)/duration`; the
/// peak velocity, at mid-move, is `1.875·(goal − start)/duration`.
#[derive(Component)]
#[component(name = "quintic")]
pub struct Quintic {
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
    /// length of the move
    #[param(unit = "s", above = 0)]
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
        let params = path.params(position, velocity).with("duration", duration);
        Self::build(b, &params)
    }
}

impl SampleModule for Quintic {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let duration = self.duration;
        let outputs = (&self.position, self.velocity.as_ref());
        self.motion.write(ctx, outputs, |_, tau| {
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

/// Registers `quintic`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Quintic>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::testing::{TestResult, assert_refuses, runtime};
    use crate::trajectories::testing::{refused, run};

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    /// A move in a group switched in later starts when it is enabled, not at time zero.
    #[test]
    fn a_move_starts_when_its_group_is_switched_in() -> TestResult {
        let rt = runtime(100.0, &[])?;
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
        let rt = runtime(100.0, &[])?;
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
    fn bad_durations_and_paths_are_refused_by_name() {
        let path = || {
            Params::new()
                .with("start", vec![0.0, 0.0])
                .with("goal", vec![1.0, 1.0])
        };
        let err = refused("quintic", path().with("duration", -1.0));
        assert_refuses(&err, "duration", &["positive"]);
        let err = refused("quintic", path().with("goal", 1.0).with("duration", 1.0));
        assert_refuses(&err, "goal", &["`start` has 2"]);
        let err = refused("quintic", path().with("at", f64::NAN).with("duration", 1.0));
        assert_refuses(&err, "at", &["finite"]);
        let err = refused(
            "quintic",
            path().with("duration", 1.0).with("velocity", "p"),
        )
        .to_string();
        assert!(err.contains("`p`") && err.contains("twice"), "{err}");
    }
}

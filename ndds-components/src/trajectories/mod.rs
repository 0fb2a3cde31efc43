//! Point-to-point trajectories: from `start` to `goal`, beginning `at` seconds after the module
//! was enabled (when sampling starts, or when a configuration switch makes its group active:
//! a state machine sequences moves by switching configurations), written as a position (and
//! optionally a velocity) each sample. `reset` starts the move over.
//!
//! | type          | module                              | writes                   | profile                        |
//! |---------------|-------------------------------------|--------------------------|--------------------------------|
//! | `trapezoidal` | [`Trapezoidal`](crate::Trapezoidal) | `position`, `velocity`?  | velocity and acceleration cap  |
//! | `quintic`     | [`Quintic`](crate::Quintic)         | `position`, `velocity`?  | minimum jerk in `duration`     |
//!
//! Each element (joint) moves on its own profile: a trapezoidal joint with a shorter distance
//! arrives earlier; they are not synchronised. Before `at` the position is `start`, after the
//! move `goal`, with zero velocity. This file holds what both profiles share: the move
//! (`Motion`, a state field each profile initialises before its outputs, whose shape it
//! gives) and the Rust constructors' `PointToPoint`.

pub(crate) mod quintic;
pub(crate) mod trapezoidal;

use nalgebra::DMatrix;

use ndds_runtime::{Mat, ModuleError, Params, Registry, RoutineResult, SampleContext};

use crate::mats::copy_out;
use crate::params::columns;

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

impl PointToPoint<'_> {
    /// The parameters `start`, `goal` and `at` of a trajectory component, with `position` and
    /// (when given) `velocity`.
    pub(super) fn params(&self, position: &str, velocity: Option<&str>) -> Params {
        let params = Params::new()
            .with("position", position)
            .with("start", self.start.to_vec())
            .with("goal", self.goal.to_vec())
            .with("at", self.at);
        match velocity {
            Some(velocity) => params.with("velocity", velocity),
            None => params,
        }
    }
}

/// The values both profiles share: where each joint starts, how far it goes, when.
pub(super) struct Motion {
    start: DMatrix<f64>,
    pub(super) distance: DMatrix<f64>,
    at: f64,
    /// Sample time (s) when the module was enabled: the move's time zero.
    origin: f64,
    p: DMatrix<f64>,
    v: DMatrix<f64>,
}

impl Motion {
    /// From `start` to `goal` (one value per joint each, as many), `at` seconds after enabling.
    pub(super) fn new(start: &[f64], goal: &[f64], at: f64) -> Result<Self, ModuleError> {
        if start.len() != goal.len() {
            return Err(ModuleError::param(
                "goal",
                format!(
                    "has {} values but `start` has {}; give one per joint",
                    goal.len(),
                    start.len()
                ),
            ));
        }
        let [start, goal] = columns([("start", start), ("goal", goal)])?;
        let n = start.nrows();
        Ok(Self {
            distance: &goal - &start,
            start,
            at,
            origin: 0.0,
            p: DMatrix::zeros(n, 1),
            v: DMatrix::zeros(n, 1),
        })
    }

    pub(super) fn len(&self) -> usize {
        self.start.nrows()
    }

    /// The move starts over from now.
    pub(super) fn restart(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.origin = ctx.time.as_secs_f64();
        Ok(())
    }

    /// Writes `start + s·distance` to `position` and `ds/dt·distance` to `velocity` (if
    /// given), with `profile(i, τ) = (s, ds/dt)` for joint `i` at `τ = t − at`.
    pub(super) fn write(
        &mut self,
        ctx: &SampleContext,
        (position, velocity): (&Mat, Option<&Mat>),
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
        copy_out(position, &self.p)?;
        match velocity {
            Some(velocity) => copy_out(velocity, &self.v),
            None => Ok(()),
        }
    }
}

/// Registers the trajectories.
pub(crate) fn register(registry: &mut Registry) {
    trapezoidal::register(registry);
    quintic::register(registry);
}

#[cfg(test)]
pub(crate) mod testing {
    use ndds_runtime::{ModuleError, Params};

    use crate::testing::{Outcome, refusal, runtime};

    /// Runs `m` of `type_name` (writing `p` and `v`) at 100 Hz for `samples` samples;
    /// returns `[p, v]` after each, per joint: `out[joint][sample]`.
    pub(crate) fn run(
        type_name: &str,
        params: Params,
        samples: usize,
    ) -> Outcome<[Vec<Vec<f64>>; 2]> {
        let rt = runtime(100.0, &[])?;
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

    /// Why a trajectory `type_name` writing `p` refuses `params`.
    pub(crate) fn refused(type_name: &str, params: Params) -> ModuleError {
        let rt = runtime(100.0, &[]).expect("a runtime");
        refusal(&rt, type_name, &params.with("position", "p"))
    }
}

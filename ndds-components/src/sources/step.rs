//! `step`: one value before a time, another from then on.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::{TIME_TOLERANCE, seconds, source_columns};
use crate::mats::copy_out;

/// output = initial while t < at, final from the first sample with t ≥ at on.
#[derive(Component)]
#[component(name = "step")]
pub struct Step {
    /// `[initial, final]` as columns of one length.
    #[state(init = source_columns(_rows, [("initial", &_initial), ("final", &_final)])?)]
    values: [DMatrix<f64>; 2],
    /// y (n × 1)
    #[output(shape = values[0].shape())]
    output: Mat,
    /// the value from `at` on
    #[param]
    _final: Vec<f64>,
    /// the value before `at`
    #[param(default = vec![0.0], default_doc = "0")]
    _initial: Vec<f64>,
    /// when it steps, since sampling began
    #[param(default = 0.0, unit = "s")]
    at: f64,
    /// output rows n (every list then has one value or n)
    #[param(default_doc = "the length of the longest list", min = 1, max = 65536)]
    _rows: Option<usize>,
}

impl Step {
    /// Steps `output` from `initial` to `final_value` at `at` seconds.
    pub fn new(
        b: &mut Binder<'_>,
        output: &str,
        initial: &[f64],
        final_value: &[f64],
        at: f64,
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("output", output)
            .with("initial", initial.to_vec())
            .with("final", final_value.to_vec())
            .with("at", at);
        Self::build(b, &params)
    }
}

impl SampleModule for Step {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let [initial, final_value] = &self.values;
        if seconds(ctx) + TIME_TOLERANCE >= self.at {
            copy_out(&self.output, final_value)
        } else {
            copy_out(&self.output, initial)
        }
    }
}

/// Registers `step`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Step>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::sources::testing::{refused, run, with};
    use crate::testing::{TestResult, assert_refuses, runtime};

    #[test]
    fn step_switches_exactly_at_its_time() -> TestResult {
        let params = Params::new()
            .with("initial", 1.0)
            .with("final", vec![2.0, 3.0])
            .with("at", 0.5);
        let out = run(&with("step", params)?, 52)?;
        // Sample k runs at t = k·10 ms: sample 50 is the first at t ≥ 0.5 s.
        assert_eq!(out[0], [1.0, 1.0]);
        assert_eq!(out[49], [1.0, 1.0]);
        assert_eq!(out[50], [2.0, 3.0]);
        assert_eq!(out[51], [2.0, 3.0]);
        // A period that does not divide `at` in nanoseconds still switches on time.
        let rt = runtime(3.0, &[])?;
        let params = Params::new().with("final", 1.0).with("at", 1.0);
        rt.install_component("h", "m", "step", &params.with("output", "y"))?;
        rt.habitat("h").start()?;
        assert_eq!(run(&rt, 4)?, [[0.0], [0.0], [0.0], [1.0]]);
        Ok(())
    }

    #[test]
    fn lists_of_different_lengths_are_refused_by_name() {
        let params = Params::new()
            .with("initial", vec![0.0, 0.0])
            .with("final", vec![1.0, 1.0, 1.0]);
        assert_refuses(&refused("step", params), "initial", &["`final` has 3"]);
    }
}

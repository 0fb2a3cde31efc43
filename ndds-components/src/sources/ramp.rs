//! `ramp`: a value rising at a constant rate from a time on.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::{seconds, source_columns};
use crate::mats::copy_out;

/// output = start + slope·max(t − at, 0).
#[derive(Component)]
#[component(name = "ramp")]
pub struct Ramp {
    /// `[start, slope]` as columns of one length.
    #[state(init = source_columns(_rows, [("start", &_start), ("slope", &_slope)])?)]
    values: [DMatrix<f64>; 2],
    /// y (n × 1)
    #[output(shape = values[0].shape())]
    output: Mat,
    /// rate of change (per s)
    #[param]
    _slope: Vec<f64>,
    /// the value until `at`
    #[param(default = vec![0.0], default_doc = "0")]
    _start: Vec<f64>,
    /// when it starts rising
    #[param(default = 0.0, unit = "s")]
    at: f64,
    /// output rows n (every list then has one value or n)
    #[param(default_doc = "the length of the longest list", min = 1, max = 65536)]
    _rows: Option<usize>,
    #[state(init = values[0].clone())]
    buffer: DMatrix<f64>,
}

impl Ramp {
    /// Ramps `output` from `start` at `slope` per second from `at` seconds on.
    pub fn new(
        b: &mut Binder<'_>,
        output: &str,
        start: &[f64],
        slope: &[f64],
        at: f64,
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("output", output)
            .with("start", start.to_vec())
            .with("slope", slope.to_vec())
            .with("at", at);
        Self::build(b, &params)
    }
}

impl SampleModule for Ramp {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let elapsed = (seconds(ctx) - self.at).max(0.0);
        let [start, slope] = &self.values;
        for (i, out) in self.buffer.iter_mut().enumerate() {
            *out = start[i] + slope[i] * elapsed;
        }
        copy_out(&self.output, &self.buffer)
    }
}

/// Registers `ramp`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Ramp>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::sources::testing::{refused, run, with};
    use crate::testing::{TestResult, assert_refuses};

    #[test]
    fn ramp_rises_at_its_slope_after_its_start() -> TestResult {
        let params = Params::new()
            .with("start", 1.0)
            .with("slope", vec![2.0, -1.0])
            .with("at", 0.1);
        let out = run(&with("ramp", params)?, 31)?;
        assert_eq!(out[5], [1.0, 1.0]);
        assert_eq!(out[10], [1.0, 1.0]);
        // t = 0.3 s: 0.2 s after the start.
        assert!((out[30][0] - 1.4).abs() < 1e-12, "{:?}", out[30]);
        assert!((out[30][1] - 0.8).abs() < 1e-12, "{:?}", out[30]);
        Ok(())
    }

    #[test]
    fn a_slope_that_is_not_finite_is_refused_by_name() {
        let params = Params::new().with("slope", f64::NAN);
        assert_refuses(&refused("ramp", params), "slope", &["finite"]);
    }
}

//! `ramp`: a value rising at a constant rate from a time on.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use super::{ROWS_DEFAULT, ROWS_DOC, list, rows, seconds};
use crate::mats::copy_out;
use crate::params::{columns, finite};

/// A ramp: `output = start + slope·max(t − at, 0)` (`slope` per second).
pub struct Ramp {
    output: Mat,
    start: DMatrix<f64>,
    slope: DMatrix<f64>,
    at: f64,
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
        let [start, slope] = columns([("start", start), ("slope", slope)])?;
        finite("at", at)?;
        Ok(Self {
            output: b.output(output, start.shape()),
            buffer: start.clone(),
            start,
            slope,
            at,
        })
    }
}

impl SampleModule for Ramp {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let elapsed = (seconds(ctx) - self.at).max(0.0);
        for (i, out) in self.buffer.iter_mut().enumerate() {
            *out = self.start[i] + self.slope[i] * elapsed;
        }
        copy_out(&self.output, &self.buffer)
    }
}

const RAMP: ComponentSpec = ComponentSpec {
    name: "ramp",
    summary: "output = start + slope·max(t − at, 0).",
    params: &[
        P::required("output", K::Output, "y (n × 1)"),
        P::required("slope", K::Numbers, "rate of change (per s)"),
        P::optional("start", K::Numbers, "0", "the value until `at`"),
        P::optional("at", K::Number, "0", "when it starts rising (s)"),
        P::optional("rows", K::Number, ROWS_DEFAULT, ROWS_DOC),
    ],
};

/// Registers `ramp`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add_with(&RAMP, |b, p| {
        let n = rows(p)?;
        Ramp::new(
            b,
            p.text("output")?,
            &list(p, "start", Some(0.0), n)?,
            &list(p, "slope", None, n)?,
            p.number_or("at", 0.0)?,
        )
    });
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

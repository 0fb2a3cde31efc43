//! `step`: one value before a time, another from then on.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use super::{ROWS_DEFAULT, ROWS_DOC, TIME_TOLERANCE, list, rows, seconds};
use crate::mats::copy_out;
use crate::params::{columns, finite};

/// A step: `output = initial` while `t < at`, `final` from the first sample with `t ≥ at` on.
pub struct Step {
    output: Mat,
    initial: DMatrix<f64>,
    final_value: DMatrix<f64>,
    at: f64,
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
        let [initial, final_value] = columns([("initial", initial), ("final", final_value)])?;
        finite("at", at)?;
        Ok(Self {
            output: b.output(output, initial.shape()),
            initial,
            final_value,
            at,
        })
    }
}

impl SampleModule for Step {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        if seconds(ctx) + TIME_TOLERANCE >= self.at {
            copy_out(&self.output, &self.final_value)
        } else {
            copy_out(&self.output, &self.initial)
        }
    }
}

const STEP: ComponentSpec = ComponentSpec {
    name: "step",
    summary: "output = initial while t < at, final from the first sample with t ≥ at on.",
    params: &[
        P::required("output", K::Output, "y (n × 1)"),
        P::required("final", K::Numbers, "the value from `at` on"),
        P::optional("initial", K::Numbers, "0", "the value before `at`"),
        P::optional(
            "at",
            K::Number,
            "0",
            "when it steps (s since sampling began)",
        ),
        P::optional("rows", K::Number, ROWS_DEFAULT, ROWS_DOC),
    ],
};

/// Registers `step`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add_with(&STEP, |b, p| {
        let n = rows(p)?;
        Step::new(
            b,
            p.text("output")?,
            &list(p, "initial", Some(0.0), n)?,
            &list(p, "final", None, n)?,
            p.number_or("at", 0.0)?,
        )
    });
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

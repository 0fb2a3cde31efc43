//! `constant`: a tunable constant column.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use super::{ROWS_DEFAULT, ROWS_DOC, list, rows};
use crate::mats::{copy_in, copy_out, matrix_param};
use crate::params::columns;

/// `output = value`: a tunable constant. `value` is the `n × 1` parameter CSMat
/// `"{module}.value"`; the application may change it while sampling runs.
pub struct Constant {
    output: Mat,
    value: Mat,
    buffer: DMatrix<f64>,
}

impl Constant {
    /// Writes `value` (a column) to `output`.
    pub fn new(b: &mut Binder<'_>, output: &str, value: &[f64]) -> Result<Self, ModuleError> {
        let [value] = columns([("value", value)])?;
        Ok(Self {
            output: b.output(output, value.shape()),
            value: matrix_param(b, "value", &value),
            buffer: value,
        })
    }
}

impl SampleModule for Constant {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        copy_in(&self.value, &mut self.buffer);
        copy_out(&self.output, &self.buffer)
    }
}

const CONSTANT: ComponentSpec = ComponentSpec {
    name: "constant",
    summary: "output = value, a tunable n × 1 CSMat `<module>.value`.",
    params: &[
        P::required("output", K::Output, "y (n × 1)"),
        P::required("value", K::Numbers, "the value, one per row or one for all"),
        P::optional("rows", K::Number, ROWS_DEFAULT, ROWS_DOC),
    ],
};

/// Registers `constant`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add_with(&CONSTANT, |b, p| {
        let n = rows(p)?;
        Constant::new(b, p.text("output")?, &list(p, "value", None, n)?)
    });
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::sources::testing::{refused, run, with};
    use crate::testing::{TestResult, assert_refuses};

    #[test]
    fn constant_writes_its_tunable_value() -> TestResult {
        let rt = with("constant", Params::new().with("value", vec![1.0, 2.0, 3.0]))?;
        assert_eq!(run(&rt, 1)?, [[1.0, 2.0, 3.0]]);
        rt.mat("m.value").write().set(1, 0, -5.0)?;
        assert_eq!(run(&rt, 1)?, [[1.0, -5.0, 3.0]]);
        let rt = with(
            "constant",
            Params::new().with("value", 4.0).with("rows", 2.0),
        )?;
        assert_eq!(run(&rt, 1)?, [[4.0, 4.0]]);
        Ok(())
    }

    #[test]
    fn bad_rows_are_refused_by_name() {
        let params = Params::new().with("value", 1.0).with("rows", 0.0);
        assert_refuses(&refused("constant", params), "rows", &["whole number"]);
        let params = Params::new()
            .with("value", vec![1.0, 2.0])
            .with("rows", 3.0);
        assert_refuses(
            &refused("constant", params),
            "value",
            &["expected one value or 3"],
        );
    }
}

//! `constant`: a tunable constant column.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::source_columns;
use crate::mats::{copy_in, copy_out, matrix_param};

/// output = value, a tunable n × 1 CSMat `<module>.value`.
///
/// The application may change `value` while sampling runs.
#[derive(Component)]
#[component(name = "constant", finish = Self::declare_value)]
pub struct Constant {
    /// The value as a column (its rows give the output's).
    #[state(init = { let [value] = source_columns(_rows, [("value", &_value)])?; value })]
    buffer: DMatrix<f64>,
    /// y (n × 1)
    #[output(shape = buffer.shape())]
    output: Mat,
    /// the value, one per row or one for all
    #[param]
    _value: Vec<f64>,
    /// output rows n (every list then has one value or n)
    #[param(default_doc = "the length of the longest list", min = 1, max = 65536)]
    _rows: Option<usize>,
    /// The parameter CSMat `<module>.value`, declared once `buffer` is known.
    #[state(init = Mat::placeholder("value"))]
    value: Mat,
}

impl Constant {
    /// Writes `value` (a column) to `output`.
    pub fn new(b: &mut Binder<'_>, output: &str, value: &[f64]) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("output", output)
            .with("value", value.to_vec());
        Self::build(b, &params)
    }

    /// The tunable `<module>.value`, created from the column unless it exists.
    fn declare_value(&mut self, b: &mut Binder<'_>) -> Result<(), ModuleError> {
        self.value = matrix_param(b, "value", &self.buffer);
        Ok(())
    }
}

impl SampleModule for Constant {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        copy_in(&self.value, &mut self.buffer);
        copy_out(&self.output, &self.buffer)
    }
}

/// Registers `constant`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Constant>();
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

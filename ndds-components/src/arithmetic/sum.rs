//! `sum`: a weighted sum of inputs of one shape.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::mismatch;
use crate::mats::{copy_in, copy_out};

/// A weighted sum: `output = Σ signs[i]·inputs[i]`, element by element, all inputs of one
/// shape (signs `[1, -1]` make an error signal `inputs[0] − inputs[1]`).
#[derive(Component)]
#[component(
    name = "sum",
    summary = "output = Σ signs[i]·inputs[i], element by element; all inputs of one shape."
)]
pub struct Sum {
    /// the terms (at least one), all of one shape
    #[inputs(same_shape)]
    inputs: Vec<Mat>,
    /// the sum, the shape of the inputs
    #[output(same_as = inputs)]
    output: Mat,
    /// one weight per input, e.g. [1, -1] for an error signal
    #[param(default_doc = "all 1")]
    _signs: Option<Vec<f64>>,
    /// The weights, one per input.
    #[state(init = weights(_signs.as_deref(), inputs.len())?)]
    signs: Vec<f64>,
    total: DMatrix<f64>,
    term: DMatrix<f64>,
}

/// `signs`, which must have one value per input; all 1 when absent.
fn weights(signs: Option<&[f64]>, inputs: usize) -> Result<Vec<f64>, ModuleError> {
    match signs {
        None => Ok(vec![1.0; inputs]),
        Some(signs) if signs.len() == inputs => Ok(signs.to_vec()),
        Some(signs) => Err(ModuleError::param(
            "signs",
            format!(
                "has {} values for {inputs} inputs; give one per input",
                signs.len()
            ),
        )),
    }
}

impl Sum {
    /// Sums `inputs` weighted by `signs` (one per input) into `output` (their shape).
    pub fn new(
        b: &mut Binder<'_>,
        inputs: &[&str],
        signs: &[f64],
        output: &str,
    ) -> Result<Self, ModuleError> {
        let names: Vec<String> = inputs.iter().map(|n| (*n).to_owned()).collect();
        let params = Params::new()
            .with("inputs", names)
            .with("signs", signs.to_vec())
            .with("output", output);
        Self::build(b, &params)
    }
}

impl SampleModule for Sum {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        copy_in(&self.inputs[0], &mut self.total);
        self.total.scale_mut(self.signs[0]);
        for (input, &sign) in self.inputs.iter().zip(&self.signs).skip(1) {
            copy_in(input, &mut self.term);
            if self.term.shape() != self.total.shape() {
                let first = &self.inputs[0];
                return Err(mismatch(
                    input,
                    self.term.shape(),
                    first,
                    self.total.shape(),
                ));
            }
            self.total.zip_apply(&self.term, |t, x| *t += sign * x);
        }
        copy_out(&self.output, &self.total)
    }
}

/// Registers `sum`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Sum>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::arithmetic::testing::{names, once};
    use crate::testing::{TestResult, assert_refuses, refusal, runtime};

    #[test]
    fn sum_weights_its_inputs_by_their_signs() -> TestResult {
        let mats: &[(&str, &[f64])] =
            &[("a", &[1.0, 2.0]), ("b", &[3.0, 5.0]), ("c", &[10.0, 10.0])];
        let params = Params::new()
            .with("inputs", names(&["a", "b", "c"]))
            .with("signs", vec![1.0, -1.0, 0.5]);
        assert_eq!(once(&runtime(100.0, mats)?, "sum", params)?, [3.0, 2.0]);
        let params = Params::new().with("inputs", names(&["a", "b", "c"]));
        assert_eq!(once(&runtime(100.0, mats)?, "sum", params)?, [14.0, 17.0]);
        Ok(())
    }

    #[test]
    fn bad_signs_and_inputs_are_refused_by_name() -> TestResult {
        let rt = runtime(100.0, &[("u", &[0.0, 0.0]), ("v", &[0.0, 0.0, 0.0])])?;
        let refused = |params: Params| refusal(&rt, "sum", &params.with("output", "y"));
        let params = Params::new()
            .with("inputs", names(&["u", "u"]))
            .with("signs", 1.0);
        assert_refuses(&refused(params), "signs", &["2 inputs"]);
        let params = Params::new()
            .with("inputs", names(&["u", "u"]))
            .with("signs", vec![1.0, f64::INFINITY]);
        assert_refuses(&refused(params), "signs", &["inf is not a finite number"]);
        let params = Params::new().with("inputs", names(&["u", "v"]));
        assert_refuses(&refused(params), "inputs", &["one shape"]);
        let params = Params::new().with("inputs", Vec::<String>::new());
        assert_refuses(&refused(params), "inputs", &["at least one"]);
        let params = Params::new().with("inputs", names(&["u", "y"]));
        let err = refused(params).to_string();
        assert!(err.contains("`y`") && err.contains("twice"), "{err}");
        Ok(())
    }
}

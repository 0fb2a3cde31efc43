//! `transfer_function`: a discrete SISO transfer function applied to each element.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::mats::{copy_in, copy_out, shape_error};
use crate::params::failed;

/// Coefficients of `num` or `den` at most.
const MAX_COEFFICIENTS: usize = 256;
/// State values of one transfer function at most (128 MiB).
const MAX_STATE: usize = 1 << 24;

/// Discrete H(z) = (b0 + b1·z⁻¹ + … + bm·z⁻ᵐ)/(a0 + a1·z⁻¹ + … + an·z⁻ⁿ), applied to each
/// element on its own (direct form II transposed); with b0 = 0 the input is a state input
/// (usable in loops).
///
/// The coefficients are normalised by `a0`. With `b0 = 0` (a delay) the input is read only in
/// `state_update`, so the block can sit in a loop. The state (one per element, sized at the
/// first sample) is zero when sampling begins and after `reset`.
#[derive(Component)]
#[component(name = "transfer_function")]
pub struct TransferFunction {
    #[state(init = Coefficients::new(&_num, &_den)?)]
    coefficients: Coefficients,
    /// u, any shape
    #[input(state = !coefficients.feedthrough())]
    input: Mat,
    /// y, the shape of u
    #[output(same_as = input)]
    output: Mat,
    /// numerator [b0, b1, …] in powers of z⁻¹
    #[param]
    _num: Vec<f64>,
    /// denominator [a0, a1, …] in powers of z⁻¹ (a0 ≠ 0)
    #[param]
    _den: Vec<f64>,
    /// `state[(i, j)]`: delay `i` of element `j`.
    #[state(init = DMatrix::zeros(coefficients.order(), 0))]
    state: DMatrix<f64>,
    /// The input, then (feedthrough) the output.
    value: DMatrix<f64>,
    /// Without feedthrough: this sample's output, used by `state_update`.
    y: DMatrix<f64>,
}

/// Numerator and denominator, normalised by `a0`, both `order + 1` long (`den[0] = 1`).
struct Coefficients {
    num: Vec<f64>,
    den: Vec<f64>,
}

impl Coefficients {
    /// `num` and `den` checked (at least one coefficient each, at most
    /// [`MAX_COEFFICIENTS`], `a0 ≠ 0`), normalised and padded to one length.
    fn new(num: &[f64], den: &[f64]) -> Result<Self, ModuleError> {
        if num.is_empty() {
            return Err(ModuleError::param(
                "num",
                "expected at least one coefficient",
            ));
        }
        for (name, c) in [("num", num), ("den", den)] {
            if c.len() > MAX_COEFFICIENTS {
                return Err(ModuleError::param(
                    name,
                    format!("has {} coefficients; at most {MAX_COEFFICIENTS}", c.len()),
                ));
            }
        }
        let a0 = match den.first() {
            Some(&a0) if a0 != 0.0 => a0,
            _ => {
                return Err(ModuleError::param(
                    "den",
                    "the leading coefficient a0 must not be 0",
                ));
            }
        };
        let len = num.len().max(den.len());
        let padded = |c: &[f64]| -> Vec<f64> {
            (0..len).map(|i| c.get(i).map_or(0.0, |x| x / a0)).collect()
        };
        Ok(Self {
            num: padded(num),
            den: padded(den),
        })
    }

    fn order(&self) -> usize {
        self.num.len() - 1
    }

    /// Whether `b0 ≠ 0` (the input is read in `execute`).
    fn feedthrough(&self) -> bool {
        self.num[0] != 0.0
    }
}

impl TransferFunction {
    /// Filters `input` through `num(z⁻¹) / den(z⁻¹)` into `output` (same shape). `den[0]`
    /// must not be 0.
    pub fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        num: &[f64],
        den: &[f64],
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("input", input)
            .with("output", output)
            .with("num", num.to_vec())
            .with("den", den.to_vec());
        Self::build(b, &params)
    }

    fn order(&self) -> usize {
        self.coefficients.order()
    }

    fn feedthrough(&self) -> bool {
        self.coefficients.feedthrough()
    }

    /// Zero state for `elements` elements (allocates only when the count changes; refuses
    /// more than [`MAX_STATE`] values).
    fn size_state(&mut self, elements: usize) -> RoutineResult {
        if self.state.ncols() != elements {
            if self.order().saturating_mul(elements) > MAX_STATE {
                return Err(failed(format!(
                    "transfer function of order {} on {elements} elements: more than \
                     {MAX_STATE} state values",
                    self.order()
                )));
            }
            self.state = DMatrix::zeros(self.order(), elements);
        }
        Ok(())
    }

    /// Advances element `j` by one sample with input `u` and output `y`.
    fn advance(&mut self, j: usize, u: f64, y: f64) {
        let order = self.order();
        for i in 0..order {
            let next = if i + 1 < order {
                self.state[(i + 1, j)]
            } else {
                0.0
            };
            let Coefficients { num, den } = &self.coefficients;
            self.state[(i, j)] = num[i + 1] * u - den[i + 1] * y + next;
        }
    }

    fn first_state(&self, j: usize) -> f64 {
        if self.order() > 0 {
            self.state[(0, j)]
        } else {
            0.0
        }
    }
}

impl SampleModule for TransferFunction {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        if self.feedthrough() {
            copy_in(&self.input, &mut self.value);
            self.size_state(self.value.len())?;
            for j in 0..self.value.len() {
                let u = self.value[j];
                let y = self.coefficients.num[0] * u + self.first_state(j);
                self.advance(j, u, y);
                self.value[j] = y;
            }
            return copy_out(&self.output, &self.value);
        }
        let shape = self.input.shape();
        if self.y.shape() != shape {
            self.y = DMatrix::zeros(shape.0, shape.1);
        }
        self.size_state(self.y.len())?;
        for j in 0..self.y.len() {
            self.y[j] = self.first_state(j);
        }
        copy_out(&self.output, &self.y)
    }

    fn state_update(&mut self, _: &SampleContext) -> RoutineResult {
        if self.feedthrough() {
            return Ok(());
        }
        copy_in(&self.input, &mut self.value);
        if self.value.shape() != self.y.shape() {
            return Err(shape_error(
                "input",
                self.input.name(),
                self.value.shape(),
                self.y.shape(),
            ));
        }
        for j in 0..self.value.len() {
            self.advance(j, self.value[j], self.y[j]);
        }
        Ok(())
    }

    fn startup(&mut self, _: &SampleContext) -> RoutineResult {
        self.state.fill(0.0);
        Ok(())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.state.fill(0.0);
        Ok(())
    }
}

/// Registers `transfer_function`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<TransferFunction>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::testing::{TestResult, assert_refuses, refusal, runtime, trace};

    const DT: f64 = 0.01;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn transfer_function_step_response() -> TestResult {
        // H = 0.5 / (1 − 0.5 z⁻¹): the step response is 1 − 0.5^(k+1). (Given as 2 / (4 − 2 z⁻¹)
        // to check the normalisation.)
        let rt = runtime(1.0 / DT, &[("u", &[1.0, 2.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("num", vec![2.0])
            .with("den", vec![4.0, -2.0]);
        rt.install_component("h", "tf", "transfer_function", &params)?;
        let [y] = &trace(&rt, &["y"], 20)?[..] else {
            unreachable!()
        };
        for (k, y) in y.iter().enumerate() {
            assert!(close(*y, 1.0 - 0.5f64.powi(k as i32 + 1)), "y[{k}] = {y}");
        }
        assert!(close(
            rt.mat("y").value(1, 0),
            2.0 * (1.0 - 0.5f64.powi(20))
        ));
        Ok(())
    }

    #[test]
    fn transfer_function_matches_the_lowpass() -> TestResult {
        let (tau, a) = (0.09, DT / (0.09 + DT));
        let rt = runtime(1.0 / DT, &[])?;
        let sine = Params::new()
            .with("output", "u")
            .with("amplitude", 1.0)
            .with("frequency", 3.0);
        rt.install_component("h", "wave", "sine", &sine)?;
        let tf = Params::new()
            .with("input", "u")
            .with("output", "y_tf")
            .with("num", vec![a])
            .with("den", vec![1.0, a - 1.0]);
        rt.install_component("h", "tf", "transfer_function", &tf)?;
        let lowpass = Params::new()
            .with("input", "u")
            .with("output", "y_lp")
            .with("tau", tau);
        rt.install_component("h", "lp", "lowpass", &lowpass)?;
        let out = trace(&rt, &["y_tf", "y_lp"], 200)?;
        for (k, (tf, lp)) in out[0].iter().zip(&out[1]).enumerate() {
            assert!(close(*tf, *lp), "sample {k}: {tf} vs {lp}");
        }
        assert!(out[0].iter().any(|y| y.abs() > 0.1));
        Ok(())
    }

    #[test]
    fn a_pure_delay_closes_a_loop() -> TestResult {
        // y = z⁻¹·(1 + y): without feedthrough the loop is legal, and y counts samples.
        let rt = runtime(1.0 / DT, &[("one", &[1.0])])?;
        let sum = Params::new()
            .with("inputs", vec!["one".to_owned(), "y".to_owned()])
            .with("output", "s");
        rt.install_component("h", "add", "sum", &sum)?;
        let delay = Params::new()
            .with("input", "s")
            .with("output", "y")
            .with("num", vec![0.0, 1.0])
            .with("den", vec![1.0]);
        rt.install_component("h", "delay", "transfer_function", &delay)?;
        let [y] = &trace(&rt, &["y"], 5)?[..] else {
            unreachable!()
        };
        assert_eq!(y, &[0.0, 1.0, 2.0, 3.0, 4.0]);
        Ok(())
    }

    #[test]
    fn bad_coefficients_are_refused_by_name() -> TestResult {
        let rt = runtime(1.0 / DT, &[("u", &[0.0])])?;
        let tf = |num: Vec<f64>, den: Vec<f64>| {
            Params::new()
                .with("input", "u")
                .with("output", "y")
                .with("num", num)
                .with("den", den)
        };
        let err = refusal(&rt, "transfer_function", &tf(vec![1.0], vec![0.0, 1.0]));
        assert_refuses(&err, "den", &["a0"]);
        let err = refusal(&rt, "transfer_function", &tf(vec![], vec![1.0]));
        assert_refuses(&err, "num", &["at least one"]);
        let err = refusal(&rt, "transfer_function", &tf(vec![f64::NAN], vec![1.0]));
        assert_refuses(&err, "num", &["finite"]);
        Ok(())
    }
}

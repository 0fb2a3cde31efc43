//! `state_space`: a discrete linear system `x⁺ = A·x + B·u`, `y = C·x + D·u`.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::mats::{copy_in, copy_out, shape_error};
use crate::params::all_finite;

/// The matrices of a discrete linear system `x⁺ = A·x + B·u`, `y = C·x + D·u`.
#[derive(Clone, Debug, PartialEq)]
pub struct StateSpaceModel {
    /// State matrix (n × n).
    pub a: DMatrix<f64>,
    /// Input matrix (n × m).
    pub b: DMatrix<f64>,
    /// Output matrix (p × n).
    pub c: DMatrix<f64>,
    /// Feedthrough matrix (p × m); all zeros for a system without direct feedthrough.
    pub d: DMatrix<f64>,
}

impl StateSpaceModel {
    /// A system without direct feedthrough (`D = 0`, p × m).
    pub fn strictly_proper(a: DMatrix<f64>, b: DMatrix<f64>, c: DMatrix<f64>) -> Self {
        let d = DMatrix::zeros(c.nrows(), b.ncols());
        Self { a, b, c, d }
    }

    /// The model of the matrices given (`d` zeros when absent), its dimensions checked.
    fn checked(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        c: &DMatrix<f64>,
        d: Option<&DMatrix<f64>>,
    ) -> Result<Self, ModuleError> {
        let model = match d {
            Some(d) => Self {
                a: a.clone(),
                b: b.clone(),
                c: c.clone(),
                d: d.clone(),
            },
            None => Self::strictly_proper(a.clone(), b.clone(), c.clone()),
        };
        model.dimensions()?;
        Ok(model)
    }

    /// `(n, m, p)`, or an error naming the first matrix that does not fit.
    fn dimensions(&self) -> Result<(usize, usize, usize), ModuleError> {
        let (n, m, p) = (self.a.nrows(), self.b.ncols(), self.c.nrows());
        let checks = [
            ("a", &self.a, (n, n), "n × n"),
            ("b", &self.b, (n, m), "n × m (n rows, like a)"),
            ("c", &self.c, (p, n), "p × n (n columns, like a)"),
            ("d", &self.d, (p, m), "p × m (rows of c, columns of b)"),
        ];
        for (name, matrix, expected, rule) in checks {
            if matrix.shape() != expected || matrix.is_empty() {
                return Err(ModuleError::param(
                    name,
                    format!(
                        "is {}x{}, expected {}x{}: {rule}",
                        matrix.nrows(),
                        matrix.ncols(),
                        expected.0,
                        expected.1
                    ),
                ));
            }
            all_finite(name, matrix.as_slice())?;
        }
        Ok((n, m, p))
    }
}

/// Discrete x⁺ = A·x + B·u, y = C·x + D·u; with D = 0 the input is a state input (usable in
/// loops, e.g. as a simulated plant).
///
/// `u` = `input` (m × 1), `y` = `output` (p × 1). With `D = 0` the input is read only in
/// `state_update` (no direct feedthrough: a plant in a loop); otherwise in `execute`. The
/// state starts at `x0` when sampling begins and after `reset`.
#[derive(Component)]
#[component(name = "state_space")]
pub struct StateSpace {
    /// The model, its dimensions checked (`D` zeros when not given).
    #[state(init = StateSpaceModel::checked(&_a, &_b, &_c, _d.as_ref())?)]
    model: StateSpaceModel,
    #[state(init = model.d.iter().any(|x| *x != 0.0))]
    feedthrough: bool,
    /// u (m × 1)
    #[input(state = !feedthrough, shape = (model.b.ncols(), 1))]
    input: Mat,
    /// y (p × 1)
    #[output(shape = (model.c.nrows(), 1))]
    output: Mat,
    /// A (n × n)
    #[param]
    _a: DMatrix<f64>,
    /// B (n × m)
    #[param]
    _b: DMatrix<f64>,
    /// C (p × n)
    #[param]
    _c: DMatrix<f64>,
    /// D (p × m)
    #[param(default_doc = "zeros")]
    _d: Option<DMatrix<f64>>,
    /// initial state (n values)
    #[param(default_doc = "zeros")]
    _x0: Option<Vec<f64>>,
    #[state(init = initial_state(&model, _x0.as_deref())?)]
    x0: DMatrix<f64>,
    #[state(init = x0.clone())]
    x: DMatrix<f64>,
    #[state(init = x0.clone())]
    next: DMatrix<f64>,
    #[state(init = DMatrix::zeros(model.b.ncols(), 1))]
    u: DMatrix<f64>,
    #[state(init = DMatrix::zeros(model.c.nrows(), 1))]
    y: DMatrix<f64>,
}

/// `x0` as a column of n values (zeros when not given).
fn initial_state(model: &StateSpaceModel, x0: Option<&[f64]>) -> Result<DMatrix<f64>, ModuleError> {
    let n = model.a.nrows();
    match x0 {
        None => Ok(DMatrix::zeros(n, 1)),
        Some(x0) if x0.len() == n => Ok(DMatrix::from_column_slice(n, 1, x0)),
        Some(x0) => Err(ModuleError::param(
            "x0",
            format!("has {} values, expected {n} (one per state)", x0.len()),
        )),
    }
}

impl StateSpace {
    /// Simulates `model` from `x0` (n values).
    pub fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        model: StateSpaceModel,
        x0: &[f64],
    ) -> Result<Self, ModuleError> {
        let StateSpaceModel { a, b: bm, c, d } = model;
        let params = Params::new()
            .with("input", input)
            .with("output", output)
            .with("a", a)
            .with("b", bm)
            .with("c", c)
            .with("d", d)
            .with("x0", x0.to_vec());
        Self::build(b, &params)
    }

    /// Reads the input into `u`, which must be m × 1.
    fn read_input(&mut self) -> RoutineResult {
        let expected = self.u.shape();
        copy_in(&self.input, &mut self.u);
        if self.u.shape() != expected {
            let got = self.u.shape();
            self.u = DMatrix::zeros(expected.0, expected.1);
            return Err(shape_error("input", self.input.name(), got, expected));
        }
        Ok(())
    }
}

impl SampleModule for StateSpace {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        // Shapes are fixed by the constructor's checks and `read_input`: gemm cannot panic.
        self.y.gemm(1.0, &self.model.c, &self.x, 0.0);
        if self.feedthrough {
            self.read_input()?;
            self.y.gemm(1.0, &self.model.d, &self.u, 1.0);
        }
        copy_out(&self.output, &self.y)
    }

    fn state_update(&mut self, _: &SampleContext) -> RoutineResult {
        if !self.feedthrough {
            self.read_input()?;
        }
        self.next.gemm(1.0, &self.model.a, &self.x, 0.0);
        self.next.gemm(1.0, &self.model.b, &self.u, 1.0);
        std::mem::swap(&mut self.x, &mut self.next);
        Ok(())
    }

    fn startup(&mut self, _: &SampleContext) -> RoutineResult {
        self.x.copy_from(&self.x0);
        Ok(())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.x.copy_from(&self.x0);
        Ok(())
    }
}

/// Registers `state_space`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<StateSpace>();
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use ndds_runtime::Params;

    use super::{StateSpace, StateSpaceModel};
    use crate::testing::{TestResult, assert_refuses, refusal, runtime, trace};

    const DT: f64 = 0.01;

    fn matrix(rows: usize, cols: usize, values: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(rows, cols, values)
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn state_space_double_integrator_matches_hand_iteration() -> TestResult {
        let rt = runtime(1.0 / DT, &[("u", &[2.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("a", matrix(2, 2, &[1.0, DT, 0.0, 1.0]))
            .with("b", vec![DT * DT / 2.0, DT])
            .with("c", matrix(1, 2, &[1.0, 0.0]))
            .with("x0", vec![0.5, -1.0]);
        rt.install_component("h", "plant", "state_space", &params)?;
        let [y] = &trace(&rt, &["y"], 100)?[..] else {
            unreachable!()
        };
        let (mut p, mut v) = (0.5, -1.0);
        for (k, y) in y.iter().enumerate() {
            assert!(close(*y, p), "y[{k}] = {y}, expected {p}");
            (p, v) = (p + DT * v + DT * DT / 2.0 * 2.0, v + DT * 2.0);
        }
        // Exact for a constant acceleration: p(t) = p0 + v0·t + t²; at t = 0.99 s:
        assert!((y[99] - (0.5 - 0.99 + 0.99 * 0.99)).abs() < 1e-9);

        // With D ≠ 0 the input is fed through in the same sample.
        let rt = runtime(1.0 / DT, &[("u", &[2.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("a", 1.0)
            .with("b", 1.0)
            .with("c", 1.0)
            .with("d", 3.0);
        rt.install_component("h", "plant", "state_space", &params)?;
        assert_eq!(trace(&rt, &["y"], 3)?[0], [6.0, 8.0, 10.0]);
        Ok(())
    }

    /// A strictly proper model has a p × m zero `D` and reads its input in `state_update`
    /// only, so a controller fed by its output may drive it in the same habitat.
    #[test]
    fn a_strictly_proper_model_closes_a_loop() -> TestResult {
        let wide = StateSpaceModel::strictly_proper(
            DMatrix::identity(3, 3),
            DMatrix::zeros(3, 2),
            DMatrix::zeros(1, 3),
        );
        assert_eq!(wide.d, DMatrix::zeros(1, 2));

        // x⁺ = x + u, y = x, u = −0.5·y: y halves every sample.
        let rt = runtime(1.0 / DT, &[])?;
        let one = || DMatrix::from_element(1, 1, 1.0);
        rt.install("h", "plant", |b| {
            let model = StateSpaceModel::strictly_proper(one(), one(), one());
            StateSpace::new(b, "u", "y", model, &[1.0])
        })?;
        let gain = Params::new()
            .with("input", "y")
            .with("output", "u")
            .with("k", -0.5);
        rt.install_component("h", "controller", "gain", &gain)?;
        let y = &trace(&rt, &["y"], 6)?[0];
        assert_eq!(y, &[1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125]);
        Ok(())
    }

    #[test]
    fn bad_matrices_and_initial_states_are_refused_by_name() -> TestResult {
        let rt = runtime(1.0 / DT, &[("u", &[0.0])])?;
        let ss = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("a", matrix(2, 2, &[1.0, 0.0, 0.0, 1.0]))
            .with("b", vec![1.0, 0.0, 0.0])
            .with("c", matrix(1, 2, &[1.0, 0.0]));
        let err = refusal(&rt, "state_space", &ss);
        assert_refuses(&err, "b", &["3x1, expected 2x1"]);
        let ss = ss.with("b", vec![0.0, 1.0]);
        let err = refusal(&rt, "state_space", &ss.clone().with("x0", vec![1.0]));
        assert_refuses(&err, "x0", &["expected 2"]);
        let err = refusal(&rt, "state_space", &ss.with("d", vec![1.0, 2.0]));
        assert_refuses(&err, "d", &["2x1, expected 1x1"]);
        Ok(())
    }
}

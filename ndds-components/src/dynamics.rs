//! Linear dynamics and the PID controller: discrete transfer functions and state-space
//! systems, and PID on the measurement with output limits and anti-windup.
//!
//! | type                | module                | reads                   | writes   |
//! |---------------------|-----------------------|-------------------------|----------|
//! | `transfer_function` | [`TransferFunction`]  | `input` (state if b0=0) | `output` |
//! | `state_space`       | [`StateSpace`]        | `input` (state if D=0)  | `output` |
//! | `pid`               | [`Pid`]               | `measured`, `reference` | `output` |
//!
//! A system without direct feedthrough (`b0 = 0`, `D = 0`) reads its input only in
//! `state_update`, so it can close a loop with a controller (a simulated plant). Every state
//! starts from its initial value when sampling begins (`startup`) and on `reset`.

use nalgebra::DMatrix;

use super::sources::param_checks::{finite, problem};
use super::{copy_in, copy_out, distinct, scalar_param, shape_of};
use ndds_runtime::Mat;
use ndds_runtime::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule, Shape};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Params, Registry};

fn shape_error(
    what: &str,
    mat: &Mat,
    got: (usize, usize),
    expected: (usize, usize),
) -> ModuleError {
    ModuleError::Failed(format!(
        "{what} `{}` is {}x{}, expected {}x{}",
        mat.name(),
        got.0,
        got.1,
        expected.0,
        expected.1
    ))
}

fn all_finite(name: &str, values: &[f64]) -> Result<(), ModuleError> {
    values.iter().try_for_each(|x| finite(name, *x).map(drop))
}

/// A discrete SISO transfer function applied to each element of `input` on its own:
///
/// `H(z) = (b0 + b1·z⁻¹ + … + bm·z⁻ᵐ) / (a0 + a1·z⁻¹ + … + an·z⁻ⁿ)`
///
/// normalised by `a0` and computed in direct form II transposed. With `b0 = 0` (a delay) the
/// input is read only in `state_update`, so the block can sit in a loop. The state (one per
/// element, sized at the first sample) is zero when sampling begins and after `reset`.
pub struct TransferFunction {
    input: Mat,
    output: Mat,
    /// Numerator and denominator, normalised, both `order + 1` long (`den[0] = 1`).
    num: Vec<f64>,
    den: Vec<f64>,
    /// `state[(i, j)]`: delay `i` of element `j`.
    state: DMatrix<f64>,
    /// The input, then (feedthrough) the output.
    value: DMatrix<f64>,
    /// Without feedthrough: this sample's output, used by `state_update`.
    y: DMatrix<f64>,
}

/// Coefficients of `num` or `den` at most.
const MAX_COEFFICIENTS: usize = 256;
/// State values of one transfer function at most (128 MiB).
const MAX_STATE: usize = 1 << 24;

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
        distinct(&[input, output])?;
        if num.is_empty() {
            return Err(problem("num", "expected at least one coefficient"));
        }
        for (name, c) in [("num", num), ("den", den)] {
            if c.len() > MAX_COEFFICIENTS {
                return Err(problem(
                    name,
                    format!("has {} coefficients; at most {MAX_COEFFICIENTS}", c.len()),
                ));
            }
        }
        all_finite("num", num)?;
        all_finite("den", den)?;
        let a0 = match den.first() {
            Some(&a0) if a0 != 0.0 => a0,
            _ => return Err(problem("den", "the leading coefficient a0 must not be 0")),
        };
        let len = num.len().max(den.len());
        let padded = |c: &[f64]| -> Vec<f64> {
            (0..len).map(|i| c.get(i).map_or(0.0, |x| x / a0)).collect()
        };
        let (num, den) = (padded(num), padded(den));
        let input = if num[0] == 0.0 {
            b.state_input(input, Shape::Any)
        } else {
            b.input(input, Shape::Any)
        };
        Ok(Self {
            output: b.output_same_as(output, &input),
            input,
            state: DMatrix::zeros(len - 1, 0),
            num,
            den,
            value: DMatrix::zeros(0, 0),
            y: DMatrix::zeros(0, 0),
        })
    }

    fn order(&self) -> usize {
        self.num.len() - 1
    }

    /// Whether `b0 ≠ 0` (the input is read in `execute`).
    fn feedthrough(&self) -> bool {
        self.num[0] != 0.0
    }

    /// Zero state for `elements` elements (allocates only when the count changes; refuses
    /// more than [`MAX_STATE`] values).
    fn size_state(&mut self, elements: usize) -> RoutineResult {
        if self.state.ncols() != elements {
            if self.order().saturating_mul(elements) > MAX_STATE {
                return Err(ModuleError::Failed(format!(
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
            self.state[(i, j)] = self.num[i + 1] * u - self.den[i + 1] * y + next;
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
                let y = self.num[0] * u + self.first_state(j);
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
                &self.input,
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
    /// A system without direct feedthrough (`D = 0`).
    pub fn strictly_proper(a: DMatrix<f64>, b: DMatrix<f64>, c: DMatrix<f64>) -> Self {
        let d = DMatrix::zeros(c.nrows(), b.ncols());
        Self { a, b, c, d }
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
                return Err(problem(
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

/// A discrete linear system `x⁺ = A·x + B·u`, `y = C·x + D·u`, `u` = `input` (m × 1),
/// `y` = `output` (p × 1). With `D = 0` the input is read only in `state_update` (no direct
/// feedthrough: a plant in a loop); otherwise in `execute`. The state starts at `x0` when
/// sampling begins and after `reset`.
pub struct StateSpace {
    input: Mat,
    output: Mat,
    model: StateSpaceModel,
    feedthrough: bool,
    x0: DMatrix<f64>,
    x: DMatrix<f64>,
    next: DMatrix<f64>,
    u: DMatrix<f64>,
    y: DMatrix<f64>,
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
        distinct(&[input, output])?;
        let (n, m, p) = model.dimensions()?;
        if x0.len() != n {
            return Err(problem(
                "x0",
                format!("has {} values, expected {n} (one per state)", x0.len()),
            ));
        }
        all_finite("x0", x0)?;
        let feedthrough = model.d.iter().any(|x| *x != 0.0);
        let input = if feedthrough {
            b.input(input, (m, 1))
        } else {
            b.state_input(input, (m, 1))
        };
        let x0 = DMatrix::from_column_slice(n, 1, x0);
        Ok(Self {
            input,
            output: b.output(output, (p, 1)),
            model,
            feedthrough,
            x: x0.clone(),
            next: x0.clone(),
            x0,
            u: DMatrix::zeros(m, 1),
            y: DMatrix::zeros(p, 1),
        })
    }

    /// Reads the input into `u`, which must be m × 1.
    fn read_input(&mut self) -> RoutineResult {
        let expected = self.u.shape();
        copy_in(&self.input, &mut self.u);
        if self.u.shape() != expected {
            let got = self.u.shape();
            self.u = DMatrix::zeros(expected.0, expected.1);
            return Err(shape_error("input", &self.input, got, expected));
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

/// Gains, derivative filter and output limits of a [`Pid`]. `Default` is all gains 0, no
/// filter and no limits; set what you need:
/// `PidTuning { kp: 2.0, ki: 1.0, ..PidTuning::default() }`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PidTuning {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain (1/s).
    pub ki: f64,
    /// Derivative gain (s).
    pub kd: f64,
    /// Time constant of the derivative's first-order filter (s, 0 = none).
    pub tau: f64,
    /// Lowest output (may be −∞).
    pub lower: f64,
    /// Highest output (may be +∞).
    pub upper: f64,
}

impl Default for PidTuning {
    fn default() -> Self {
        Self {
            kp: 0.0,
            ki: 0.0,
            kd: 0.0,
            tau: 0.0,
            lower: f64::NEG_INFINITY,
            upper: f64::INFINITY,
        }
    }
}

impl PidTuning {
    fn check(&self) -> RoutineResult {
        for (name, x) in [
            ("kp", self.kp),
            ("ki", self.ki),
            ("kd", self.kd),
            ("tau", self.tau),
        ] {
            finite(name, x)?;
        }
        if self.tau < 0.0 {
            return Err(problem("tau", format!("{} is negative", self.tau)));
        }
        if self.lower.is_nan() || self.upper.is_nan() || self.lower > self.upper {
            return Err(problem(
                "lower",
                format!("{} must be ≤ `upper` {}", self.lower, self.upper),
            ));
        }
        Ok(())
    }
}

/// PID control on the measurement, element by element (n × 1):
///
/// `u = clamp(kp·e + I + kd·D, lower, upper)`, `e = r − y`, `I = Σ ki·e·dt`,
/// `D = (tau·D⁻ − (y − y⁻)) / (tau + dt)` (the derivative of −y through a first-order filter
/// with time constant `tau`; for `tau = 0`, `−(y − y⁻)/dt`).
///
/// The derivative acts on the measurement, so reference steps do not kick. Anti-windup is
/// conditional integration: while the unclamped output is above `upper` the integrator does
/// not grow, and while it is below `lower` it does not shrink; it only moves in the direction
/// that brings the output back inside the limits. `kp`, `ki`, `kd`, `tau`, `lower`, `upper`
/// are the 1 × 1 parameters `"{module}.kp"`, `.ki`, … (tunable while sampling; `I` holds
/// `ki·∫e`, so changing `ki` does not bump the output). Enabling or resetting it clears the
/// integrator and the filter and takes the current measurement as the previous one.
pub struct Pid {
    measured: Mat,
    reference: Mat,
    output: Mat,
    kp: Mat,
    ki: Mat,
    kd: Mat,
    tau: Mat,
    lower: Mat,
    upper: Mat,
    y: DMatrix<f64>,
    r: DMatrix<f64>,
    u: DMatrix<f64>,
    /// State: the integral term, the filtered derivative, the last measurement.
    integral: DMatrix<f64>,
    derivative: DMatrix<f64>,
    previous: DMatrix<f64>,
    /// This sample's integrator increment and derivative, committed by `state_update`.
    increment: DMatrix<f64>,
    next_derivative: DMatrix<f64>,
    primed: bool,
    computed: bool,
}

impl Pid {
    /// Reads `measured` and `reference` (n × 1 each), writes `output` (n × 1).
    pub fn new(
        b: &mut Binder<'_>,
        measured: &str,
        reference: &str,
        output: &str,
        tuning: PidTuning,
    ) -> Result<Self, ModuleError> {
        distinct(&[measured, reference, output])?;
        tuning.check()?;
        let measured_mat = b.input(measured, Shape::Any);
        let shape = shape_of(&measured_mat, Shape::Any);
        let empty = || DMatrix::zeros(0, 0);
        Ok(Self {
            reference: b.input(reference, shape),
            output: b.output_same_as(output, &measured_mat),
            measured: measured_mat,
            kp: scalar_param(b, "kp", tuning.kp),
            ki: scalar_param(b, "ki", tuning.ki),
            kd: scalar_param(b, "kd", tuning.kd),
            tau: scalar_param(b, "tau", tuning.tau),
            lower: scalar_param(b, "lower", tuning.lower),
            upper: scalar_param(b, "upper", tuning.upper),
            y: empty(),
            r: empty(),
            u: empty(),
            integral: empty(),
            derivative: empty(),
            previous: empty(),
            increment: empty(),
            next_derivative: empty(),
            primed: false,
            computed: false,
        })
    }

    /// Fresh state shaped like the measurement (allocates only when the shape changes).
    fn prime(&mut self) {
        let (rows, cols) = self.y.shape();
        for buffer in [
            &mut self.u,
            &mut self.integral,
            &mut self.derivative,
            &mut self.increment,
            &mut self.next_derivative,
        ] {
            if buffer.shape() != (rows, cols) {
                *buffer = DMatrix::zeros(rows, cols);
            }
            buffer.fill(0.0);
        }
        if self.previous.shape() != (rows, cols) {
            self.previous = self.y.clone();
        }
        self.previous.copy_from(&self.y);
        self.primed = true;
    }
}

impl SampleModule for Pid {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.computed = false;
        let kp = self.kp.read().get(0, 0)?;
        let ki = self.ki.read().get(0, 0)?;
        let kd = self.kd.read().get(0, 0)?;
        let tau = self.tau.read().get(0, 0)?;
        // One statement each: a guard lives to the end of its statement (one lock at a time).
        let lower = self.lower.read().get(0, 0)?;
        let upper = self.upper.read().get(0, 0)?;
        if tau.is_nan() || tau < 0.0 {
            return Err(ModuleError::Failed(format!(
                "`{}` is {tau}, expected ≥ 0",
                self.tau.name()
            )));
        }
        if lower.is_nan() || upper.is_nan() || lower > upper {
            return Err(ModuleError::Failed(format!(
                "`{}` {lower} is not ≤ `{}` {upper}",
                self.lower.name(),
                self.upper.name()
            )));
        }
        copy_in(&self.measured, &mut self.y);
        copy_in(&self.reference, &mut self.r);
        if self.r.shape() != self.y.shape() {
            return Err(shape_error(
                "reference",
                &self.reference,
                self.r.shape(),
                self.y.shape(),
            ));
        }
        if !self.primed || self.integral.shape() != self.y.shape() {
            self.prime();
        }
        let dt = ctx.dt();
        for i in 0..self.y.len() {
            let (y, e) = (self.y[i], self.r[i] - self.y[i]);
            let d = (tau * self.derivative[i] - (y - self.previous[i])) / (tau + dt);
            let unclamped = kp * e + self.integral[i] + kd * d;
            let step = ki * e * dt;
            let winding_up = (unclamped > upper && step > 0.0) || (unclamped < lower && step < 0.0);
            self.increment[i] = if winding_up { 0.0 } else { step };
            self.next_derivative[i] = d;
            self.u[i] = if unclamped > upper {
                upper
            } else if unclamped < lower {
                lower
            } else {
                unclamped
            };
        }
        self.computed = true;
        copy_out(&self.output, &self.u)
    }

    fn state_update(&mut self, _: &SampleContext) -> RoutineResult {
        if self.computed {
            self.integral += &self.increment;
            self.derivative.copy_from(&self.next_derivative);
            self.previous.copy_from(&self.y);
            self.computed = false;
        }
        Ok(())
    }

    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        self.primed = false;
        Ok(())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.primed = false;
        Ok(())
    }
}

/// `transfer_function`.
pub const TRANSFER_FUNCTION: ComponentSpec = ComponentSpec {
    name: "transfer_function",
    summary: "Discrete H(z) = (b0 + b1·z⁻¹ + … + bm·z⁻ᵐ)/(a0 + a1·z⁻¹ + … + an·z⁻ⁿ), applied \
              to each element on its own (direct form II transposed); with b0 = 0 the input \
              is a state input (usable in loops).",
    params: &[
        P::required("input", K::Input, "u, any shape"),
        P::required("output", K::Output, "y, the shape of u"),
        P::required("num", K::Numbers, "numerator [b0, b1, …] in powers of z⁻¹"),
        P::required(
            "den",
            K::Numbers,
            "denominator [a0, a1, …] in powers of z⁻¹ (a0 ≠ 0)",
        ),
    ],
};

/// `state_space`.
pub const STATE_SPACE: ComponentSpec = ComponentSpec {
    name: "state_space",
    summary: "Discrete x⁺ = A·x + B·u, y = C·x + D·u; with D = 0 the input is a state input \
              (usable in loops, e.g. as a simulated plant).",
    params: &[
        P::required("input", K::Input, "u (m × 1)"),
        P::required("output", K::Output, "y (p × 1)"),
        P::required("a", K::Matrix, "A (n × n)"),
        P::required("b", K::Matrix, "B (n × m)"),
        P::required("c", K::Matrix, "C (p × n)"),
        P::optional("d", K::Matrix, "zeros", "D (p × m)"),
        P::optional("x0", K::Numbers, "zeros", "initial state (n values)"),
    ],
};

/// `pid`.
pub const PID: ComponentSpec = ComponentSpec {
    name: "pid",
    summary: "PID on the measurement: u = clamp(kp·e + ki·∫e + kd·d(−y)/dt, lower, upper), \
              e = r − y, element by element; the derivative optionally filtered (tau); \
              anti-windup by conditional integration (the integrator does not move further \
              into the limit the output is held at).",
    params: &[
        P::required("measured", K::Input, "y (n × 1)"),
        P::required("reference", K::Input, "r (n × 1)"),
        P::required("output", K::Output, "u (n × 1)"),
        P::required(
            "kp",
            K::Number,
            "proportional gain (a CSMat `<module>.kp`, tunable)",
        ),
        P::optional(
            "ki",
            K::Number,
            "0",
            "integral gain (1/s; `<module>.ki`, tunable)",
        ),
        P::optional(
            "kd",
            K::Number,
            "0",
            "derivative gain (s; `<module>.kd`, tunable)",
        ),
        P::optional(
            "lower",
            K::Number,
            "none",
            "lowest output (`<module>.lower`, tunable)",
        ),
        P::optional(
            "upper",
            K::Number,
            "none",
            "highest output, ≥ lower (`<module>.upper`, tunable)",
        ),
        P::optional(
            "tau",
            K::Number,
            "0",
            "derivative filter time constant (s, 0 = unfiltered; `<module>.tau`, tunable)",
        ),
    ],
};

fn state_space(b: &mut Binder<'_>, p: &Params) -> Result<StateSpace, ModuleError> {
    let (a, bm, c) = (p.matrix("a")?, p.matrix("b")?, p.matrix("c")?);
    let d = if p.has("d") {
        p.matrix("d")?
    } else {
        DMatrix::zeros(c.nrows(), bm.ncols())
    };
    let x0 = p.numbers_or("x0", &vec![0.0; a.nrows()])?;
    let model = StateSpaceModel { a, b: bm, c, d };
    StateSpace::new(b, p.text("input")?, p.text("output")?, model, &x0)
}

fn pid(b: &mut Binder<'_>, p: &Params) -> Result<Pid, ModuleError> {
    let tuning = PidTuning {
        kp: p.number("kp")?,
        ki: p.number_or("ki", 0.0)?,
        kd: p.number_or("kd", 0.0)?,
        tau: p.number_or("tau", 0.0)?,
        lower: p.number_or("lower", f64::NEG_INFINITY)?,
        upper: p.number_or("upper", f64::INFINITY)?,
    };
    Pid::new(
        b,
        p.text("measured")?,
        p.text("reference")?,
        p.text("output")?,
        tuning,
    )
}

/// Registers this file's component types.
pub(crate) fn register(registry: &mut Registry) {
    registry.add(&TRANSFER_FUNCTION, |b, p| {
        TransferFunction::new(
            b,
            p.text("input")?,
            p.text("output")?,
            &p.numbers("num")?,
            &p.numbers("den")?,
        )
    });
    registry.add(&STATE_SPACE, state_space);
    registry.add(&PID, pid);
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use ndds_runtime::{Clock, CsMat, HabitatOptions, Params, Runtime};

    type TestResult = Result<(), Box<dyn std::error::Error>>;
    type Outcome<T> = Result<T, Box<dyn std::error::Error>>;

    const DT: f64 = 0.01;

    /// A runtime with a manual 100 Hz habitat `h` and the column CSMats `mats`.
    fn runtime(mats: &[(&str, &[f64])]) -> Outcome<Runtime> {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(1.0 / DT).clock(Clock::Manual))?;
        for (name, values) in mats {
            rt.create_mat(CsMat::from_row_slice(*name, values.len(), 1, values)?)?;
        }
        Ok(rt)
    }

    /// Starts `h` and records element 0 of each of `mats` after each of `samples` samples.
    fn run(rt: &Runtime, mats: &[&str], samples: usize) -> Outcome<Vec<Vec<f64>>> {
        let h = rt.habitat("h");
        h.start()?;
        let mut out = vec![Vec::new(); mats.len()];
        for _ in 0..samples {
            h.step()?;
            for (trace, name) in out.iter_mut().zip(mats) {
                trace.push(rt.mat(name).value(0, 0));
            }
        }
        assert_eq!(h.stats().module_errors, 0);
        Ok(out)
    }

    fn matrix(rows: usize, cols: usize, values: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(rows, cols, values)
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn transfer_function_step_response() -> TestResult {
        // H = 0.5 / (1 − 0.5 z⁻¹): the step response is 1 − 0.5^(k+1). (Given as 2 / (4 − 2 z⁻¹)
        // to check the normalisation.)
        let rt = runtime(&[("u", &[1.0, 2.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("num", vec![2.0])
            .with("den", vec![4.0, -2.0]);
        rt.install_component("h", "tf", "transfer_function", &params)?;
        let [y] = &run(&rt, &["y"], 20)?[..] else {
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
        let rt = runtime(&[])?;
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
        let out = run(&rt, &["y_tf", "y_lp"], 200)?;
        for (k, (tf, lp)) in out[0].iter().zip(&out[1]).enumerate() {
            assert!(close(*tf, *lp), "sample {k}: {tf} vs {lp}");
        }
        assert!(out[0].iter().any(|y| y.abs() > 0.1));
        Ok(())
    }

    #[test]
    fn a_pure_delay_closes_a_loop() -> TestResult {
        // y = z⁻¹·(1 + y): without feedthrough the loop is legal, and y counts samples.
        let rt = runtime(&[("one", &[1.0])])?;
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
        let [y] = &run(&rt, &["y"], 5)?[..] else {
            unreachable!()
        };
        assert_eq!(y, &[0.0, 1.0, 2.0, 3.0, 4.0]);
        Ok(())
    }

    #[test]
    fn state_space_double_integrator_matches_hand_iteration() -> TestResult {
        let rt = runtime(&[("u", &[2.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("a", matrix(2, 2, &[1.0, DT, 0.0, 1.0]))
            .with("b", vec![DT * DT / 2.0, DT])
            .with("c", matrix(1, 2, &[1.0, 0.0]))
            .with("x0", vec![0.5, -1.0]);
        rt.install_component("h", "plant", "state_space", &params)?;
        let [y] = &run(&rt, &["y"], 100)?[..] else {
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
        let rt = runtime(&[("u", &[2.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("a", 1.0)
            .with("b", 1.0)
            .with("c", 1.0)
            .with("d", 3.0);
        rt.install_component("h", "plant", "state_space", &params)?;
        assert_eq!(run(&rt, &["y"], 3)?[0], [6.0, 8.0, 10.0]);
        Ok(())
    }

    /// `plant`: y⁺ = 0.9·y + 0.1·u (DC gain 1); `pid` from `r` and `y` to `u`.
    fn pid_loop(rt: &Runtime, pid: Params) -> TestResult {
        let plant = Params::new()
            .with("input", "u")
            .with("output", "y")
            .with("a", 0.9)
            .with("b", 0.1)
            .with("c", 1.0);
        rt.install_component("h", "plant", "state_space", &plant)?;
        let pid = pid
            .with("measured", "y")
            .with("reference", "r")
            .with("output", "u");
        rt.install_component("h", "pid", "pid", &pid)?;
        Ok(())
    }

    #[test]
    fn pid_known_answers() -> TestResult {
        // e = 0.8: u0 = kp·e, then the integral adds ki·e·dt each sample.
        let rt = runtime(&[("y", &[0.2]), ("r", &[1.0])])?;
        let params = Params::new()
            .with("measured", "y")
            .with("reference", "r")
            .with("output", "u")
            .with("kp", 2.0)
            .with("ki", 10.0);
        rt.install_component("h", "pid", "pid", &params)?;
        let u = &run(&rt, &["u"], 3)?[0];
        assert!(
            close(u[0], 1.6) && close(u[1], 1.68) && close(u[2], 1.76),
            "{u:?}"
        );
        // The limits are tunable; crossed limits fail the sample, naming them.
        rt.mat("pid.upper").write().set(0, 0, 1.0)?;
        let h = rt.habitat("h");
        h.step()?;
        assert_eq!(rt.mat("u").value(0, 0), 1.0);
        rt.mat("pid.lower").write().set(0, 0, 2.0)?;
        h.step()?;
        assert_eq!(h.stats().module_errors, 1);

        // The derivative of the measurement y = 3·t, first unfiltered, then through tau.
        for tau in [0.0, 0.02] {
            let rt = runtime(&[("r", &[5.0])])?;
            let ramp = Params::new().with("output", "y").with("slope", 3.0);
            rt.install_component("h", "ramp", "ramp", &ramp)?;
            let params = Params::new()
                .with("measured", "y")
                .with("reference", "r")
                .with("output", "u")
                .with("kp", 0.0)
                .with("kd", 0.5)
                .with("tau", tau);
            rt.install_component("h", "pid", "pid", &params)?;
            let u = &run(&rt, &["u"], 4)?[0];
            let mut d = 0.0;
            assert_eq!(u[0], 0.0, "enabled without a derivative jump");
            for (k, u) in u.iter().enumerate().skip(1) {
                d = (tau * d - 3.0 * DT) / (tau + DT);
                assert!(
                    close(*u, 0.5 * d),
                    "tau {tau}, u[{k}] = {u}, expected {}",
                    0.5 * d
                );
            }
        }
        Ok(())
    }

    #[test]
    fn pid_reaches_the_reference_without_steady_state_error() -> TestResult {
        let rt = runtime(&[("r", &[1.0])])?;
        pid_loop(&rt, Params::new().with("kp", 2.0).with("ki", 5.0))?;
        let [y] = &run(&rt, &["y"], 1000)?[..] else {
            unreachable!()
        };
        assert!((y[999] - 1.0).abs() < 1e-6, "y = {}", y[999]);
        Ok(())
    }

    /// Samples after index `from` until `trace` stays within `tolerance` of `target`.
    fn settling(trace: &[f64], from: usize, target: f64, tolerance: f64) -> usize {
        let last_out = trace
            .iter()
            .rposition(|y| (y - target).abs() > tolerance)
            .unwrap_or(0);
        last_out.saturating_sub(from)
    }

    #[test]
    fn pid_does_not_wind_up_while_saturated() -> TestResult {
        // The reference 2 is out of reach for u ≤ 1.2 (y → 1.2) for 5 s, then drops to 1.
        let (kp, ki, upper, switch) = (2.0, 5.0, 1.2, 500);
        let rt = runtime(&[])?;
        let reference = Params::new()
            .with("output", "r")
            .with("initial", 2.0)
            .with("final", 1.0)
            .with("at", switch as f64 * DT);
        rt.install_component("h", "ref", "step", &reference)?;
        let limits = Params::new()
            .with("kp", kp)
            .with("ki", ki)
            .with("lower", -upper)
            .with("upper", upper);
        pid_loop(&rt, limits)?;
        let out = run(&rt, &["y", "u"], 1500)?;
        let (y, u) = (&out[0], &out[1]);
        assert!(
            u.iter().all(|u| u.abs() <= upper),
            "output outside its limits"
        );
        assert!(
            (y[switch - 1] - upper).abs() < 1e-3,
            "y = {}",
            y[switch - 1]
        );
        // The integrator held near 0, so the loop settles like a fresh PI step (about 2 s).
        let settle = settling(y, switch, 1.0, 0.01);
        assert!(
            settle < 300,
            "took {settle} samples to settle after the saturation"
        );
        assert!((y[1499] - 1.0).abs() < 1e-6);

        // The same loop integrating all the time winds up to I ≈ 10 and is still more than 1 %
        // off 10 s later.
        let (mut plant, mut integral, mut windup) = (0.0, 0.0, Vec::new());
        for k in 0..1500 {
            let r = if k < switch { 2.0 } else { 1.0 };
            let e = r - plant;
            let u = (kp * e + integral).clamp(-upper, upper);
            integral += ki * e * DT;
            plant = 0.9 * plant + 0.1 * u;
            windup.push(plant);
        }
        let windup_settle = settling(&windup, switch, 1.0, 0.01);
        assert!(windup_settle > 3 * settle, "{windup_settle} vs {settle}");
        Ok(())
    }

    #[test]
    fn bad_parameters_fail_the_install_naming_them() -> TestResult {
        let rt = runtime(&[("u", &[0.0])])?;
        let error = |type_name: &str, params: Params| {
            let params = params.with("input", "u").with("output", "y");
            match rt.install_component("h", "m", type_name, &params) {
                Ok(()) => panic!("{type_name} with bad parameters was installed"),
                Err(err) => err.to_string(),
            }
        };
        let tf = |den: Vec<f64>| Params::new().with("num", vec![1.0]).with("den", den);
        let err = error("transfer_function", tf(vec![0.0, 1.0]));
        assert!(err.contains("`den`") && err.contains("a0"), "{err}");
        let ss = Params::new()
            .with("a", matrix(2, 2, &[1.0, 0.0, 0.0, 1.0]))
            .with("b", vec![1.0, 0.0, 0.0])
            .with("c", matrix(1, 2, &[1.0, 0.0]));
        let err = error("state_space", ss.clone());
        assert!(
            err.contains("`b`") && err.contains("3x1, expected 2x1"),
            "{err}"
        );
        let ss = ss.with("b", vec![0.0, 1.0]).with("x0", vec![1.0]);
        let err = error("state_space", ss);
        assert!(err.contains("`x0`"), "{err}");
        let pid = Params::new()
            .with("measured", "u")
            .with("reference", "r")
            .with("output", "y")
            .with("kp", 1.0);
        let err = error("pid", pid.clone().with("lower", 1.0).with("upper", -1.0));
        assert!(err.contains("`lower`") && err.contains("`upper`"), "{err}");
        let err = error("pid", pid.with("tau", -0.1));
        assert!(err.contains("`tau`") && err.contains("negative"), "{err}");
        Ok(())
    }
}

//! Built-in components: what the paper's PD/LQG example needs, and the registry entries that
//! let systems name them as data. (The full component library comes with description files.)
//!
//! | type                 | module                     | reads            | writes   |
//! |----------------------|----------------------------|------------------|----------|
//! | `gain`               | [`Gain`]                   | `input`          | `output` |
//! | `lowpass`            | [`LowPass`]                | `input`          | `output` |
//! | `pd`                 | [`Pd`]                     | `measured`, `reference` | `output` |
//! | `estimator`          | [`Estimator`]              | `measured`, `command` (state) | `estimate` |
//! | `state_feedback`     | [`StateFeedback`]          | `estimate`, `reference` | `output` |
//! | `mass_spring_damper` | [`MassSpringDamper`]       | `force` (state)  | `position`, `angle` |

mod arm;
mod control;
mod dynamics;
mod lqg;
mod math;
mod plant;
mod recorder;
mod sources;
mod trajectory;

pub use arm::*;
pub use dynamics::*;
pub use lqg::*;
pub use math::*;
pub use recorder::*;
pub use sources::*;
pub use trajectory::*;

pub use control::{
    Estimator, LqgDesign, LqgWeights, Pd, StateFeedback, design_lqg, discretize, dlqr, kalman_gain,
    reference_gain,
};
pub use plant::{MassSpringDamper, Physical};

use nalgebra::DMatrix;

use ndds_runtime::Mat;
use ndds_runtime::csmat::CsMat;
use ndds_runtime::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule, Shape};
use ndds_runtime::{Registry, Runtime};

/// Fails when two of a module's CSMats are the same (a module holds both locks at once).
pub(crate) fn distinct(names: &[&str]) -> Result<(), ModuleError> {
    for (i, a) in names.iter().enumerate() {
        if names[i + 1..].contains(a) {
            return Err(ModuleError::Failed(format!(
                "CSMat `{a}` is used twice by this module; inputs and outputs must differ"
            )));
        }
    }
    Ok(())
}

/// Copies `mat`'s values into the module's own `buffer` and releases the lock at once:
/// built-in modules never hold two CSMat locks at a time, so habitats that feed each other
/// cannot deadlock. Allocates only when the shape changes (the first sample).
pub(crate) fn copy_in(mat: &Mat, buffer: &mut DMatrix<f64>) {
    let value = mat.read();
    if buffer.shape() == value.shape() {
        buffer.copy_from(value.matrix());
    } else {
        *buffer = value.matrix().clone();
    }
}

/// Writes `values` into `mat` (same shape required).
pub(crate) fn copy_out(mat: &Mat, values: &DMatrix<f64>) -> RoutineResult {
    let mut out = mat.write();
    if out.shape() != values.shape() {
        return Err(shape_error("output", &out, values.shape()));
    }
    out.matrix_mut().copy_from(values);
    Ok(())
}

/// The shape of `mat` if it exists, else `fallback`.
pub(crate) fn shape_of(mat: &Mat, fallback: Shape) -> Shape {
    if mat.is_bound() {
        mat.shape().into()
    } else {
        fallback
    }
}

/// A scalar parameter CSMat `"{module}.{name}"` (created with `value` if absent).
pub(crate) fn scalar_param(b: &mut Binder<'_>, name: &str, value: f64) -> Mat {
    let full = format!("{}.{name}", b.module_name());
    b.param_or(
        &full,
        CsMat::from_row_slice(&full, 1, 1, &[value]).unwrap_or_else(|_| CsMat::zeros(&full, 1, 1)),
    )
}

/// A matrix parameter CSMat `"{module}.{name}"` created from `value`.
pub(crate) fn matrix_param(b: &mut Binder<'_>, name: &str, value: &DMatrix<f64>) -> Mat {
    let full = format!("{}.{name}", b.module_name());
    let mut mat = CsMat::zeros(&full, value.nrows(), value.ncols());
    mat.matrix_mut().copy_from(value);
    b.param_or(&full, mat)
}

fn shape_error(what: &str, mat: &CsMat, expected: (usize, usize)) -> ModuleError {
    ModuleError::Failed(format!(
        "{what} `{}` is {}x{}, expected {}x{}",
        mat.name(),
        mat.rows(),
        mat.cols(),
        expected.0,
        expected.1
    ))
}

/// `y = k·u`, element by element (`k` is the 1 × 1 parameter `"{module}.k"`).
pub struct Gain {
    input: Mat,
    output: Mat,
    k: Mat,
    value: DMatrix<f64>,
}

impl Gain {
    /// Reads `input`, writes `output` (same shape).
    pub fn new(b: &mut Binder<'_>, input: &str, output: &str, k: f64) -> Result<Self, ModuleError> {
        distinct(&[input, output])?;
        let input_mat = b.input(input, Shape::Any);
        Ok(Self {
            output: b.output_same_as(output, &input_mat),
            input: input_mat,
            k: scalar_param(b, "k", k),
            value: DMatrix::zeros(0, 0),
        })
    }
}

impl SampleModule for Gain {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let k = self.k.read().get(0, 0)?;
        copy_in(&self.input, &mut self.value);
        self.value.scale_mut(k);
        copy_out(&self.output, &self.value)
    }
}

/// First-order low-pass filter `y += a·(u − y)`, `a = dt / (tau + dt)`; `tau` in seconds is
/// the 1 × 1 parameter `"{module}.tau"`. Enabling it starts from the current input (no step).
pub struct LowPass {
    input: Mat,
    output: Mat,
    tau: Mat,
    state: DMatrix<f64>,
    value: DMatrix<f64>,
    primed: bool,
}

impl LowPass {
    /// Filters `input` into `output` (same shape).
    pub fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        tau: f64,
    ) -> Result<Self, ModuleError> {
        distinct(&[input, output])?;
        let input_mat = b.input(input, Shape::Any);
        Ok(Self {
            output: b.output_same_as(output, &input_mat),
            input: input_mat,
            tau: scalar_param(b, "tau", tau),
            state: DMatrix::zeros(0, 0),
            value: DMatrix::zeros(0, 0),
            primed: false,
        })
    }

    fn prime(&mut self) {
        copy_in(&self.input, &mut self.state);
        self.primed = true;
    }
}

impl SampleModule for LowPass {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        if !self.primed {
            self.prime();
        }
        let tau = self.tau.read().get(0, 0)?.max(0.0);
        let a = ctx.dt() / (tau + ctx.dt());
        copy_in(&self.input, &mut self.value);
        if self.value.shape() != self.state.shape() {
            self.prime();
        }
        self.state.zip_apply(&self.value, |s, u| *s += a * (u - *s));
        copy_out(&self.output, &self.state)
    }

    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        self.prime();
        Ok(())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.primed = false;
        Ok(())
    }
}

use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P};

/// `gain`.
pub const GAIN: ComponentSpec = ComponentSpec {
    name: "gain",
    summary: "y = k·u, element by element.",
    params: &[
        P::required("input", K::Input, "u, any shape"),
        P::required("output", K::Output, "y, the shape of u"),
        P::optional(
            "k",
            K::Number,
            "1",
            "the gain (a 1 × 1 CSMat `<module>.k`, tunable)",
        ),
    ],
};

/// `lowpass`.
pub const LOWPASS: ComponentSpec = ComponentSpec {
    name: "lowpass",
    summary: "First-order low-pass y += a·(u − y), a = dt/(tau + dt); starts from its input \
              when enabled.",
    params: &[
        P::required("input", K::Input, "u, any shape"),
        P::required("output", K::Output, "y, the shape of u"),
        P::required(
            "tau",
            K::Number,
            "time constant (s), a CSMat `<module>.tau`",
        ),
    ],
};

/// `pd`.
pub const PD: ComponentSpec = ComponentSpec {
    name: "pd",
    summary: "PD on the measurement: u = kp·(r − y) − kd·ẏ (the derivative of the \
              measurement, so reference steps do not kick).",
    params: &[
        P::required("measured", K::Input, "y (n × 1)"),
        P::required("reference", K::Input, "r (n × 1)"),
        P::required("output", K::Output, "u (n × 1)"),
        P::required("kp", K::Number, "proportional gain"),
        P::required("kd", K::Number, "derivative gain (s)"),
    ],
};

/// `mass_spring_damper`.
pub const MASS_SPRING_DAMPER: ComponentSpec = ComponentSpec {
    name: "mass_spring_damper",
    summary: "Simulated plant m·p̈ = f − c·ṗ − k·p, exact zero-order-hold integration; \
              writes the position and a lever angle (position / length).",
    params: &[
        P::required("force", K::Input, "f (N, 1 × 1), read in state_update"),
        P::required("position", K::Output, "p (m, 1 × 1)"),
        P::required("angle", K::Output, "p / length (rad, 1 × 1)"),
        P::optional("mass", K::Number, "1", "m (kg)"),
        P::optional("stiffness", K::Number, "4", "k (N/m)"),
        P::optional("damping", K::Number, "0.4", "c (N·s/m)"),
        P::optional("length", K::Number, "0.5", "lever length (m)"),
    ],
};

/// Adds the whole library to `runtime`'s registry, so that its description files can name
/// every component type documented in `docs/components.md`.
pub fn register(runtime: &Runtime) {
    runtime.add_library(library());
}

/// The whole library as a registry of its own (for [`Runtime::add_library`]).
pub fn library() -> Registry {
    let mut registry = Registry::empty();
    register_into(&mut registry);
    registry
}

fn register_into(registry: &mut Registry) {
    registry.add(&GAIN, |b, p| {
        Gain::new(
            b,
            p.text("input")?,
            p.text("output")?,
            p.number_or("k", 1.0)?,
        )
    });
    registry.add(&LOWPASS, |b, p| {
        LowPass::new(b, p.text("input")?, p.text("output")?, p.number("tau")?)
    });
    registry.add(&PD, |b, p| {
        Pd::new(
            b,
            p.text("measured")?,
            p.text("reference")?,
            p.text("output")?,
            p.number("kp")?,
            p.number("kd")?,
        )
    });
    registry.add(&MASS_SPRING_DAMPER, |b, p| {
        MassSpringDamper::new(
            b,
            p.text("force")?,
            p.text("position")?,
            p.text("angle")?,
            Physical {
                mass: p.number_or("mass", 1.0)?,
                stiffness: p.number_or("stiffness", 4.0)?,
                damping: p.number_or("damping", 0.4)?,
                length: p.number_or("length", 0.5)?,
            },
        )
    });
    sources::register(registry);
    math::register(registry);
    dynamics::register(registry);
    trajectory::register(registry);
    recorder::register(registry);
    arm::register(registry);
    lqg::register(registry);
}

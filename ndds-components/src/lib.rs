//! ControlShell's component library for `ndds-runtime`: the sample modules a system is built
//! from (sources, arithmetic, filters and dynamic systems, PD/PID/LQG controllers,
//! trajectories, a recorder and simulated plants), each with the registry entry that lets a
//! description file name it as data, and the design maths its controllers need (zero-order-hold
//! discretisation, discrete LQR, steady-state Kalman gains, LQG design).
//!
//! What it does not do: it holds no runtime machinery (CSMats, habitats, the registry, the
//! loader and state machines are `ndds-runtime`'s), touches no network and reads no files
//! except the `recorder`'s CSV output. A runtime starts with an empty registry; nothing here is
//! registered until the application asks:
//!
//! ```
//! use ndds_runtime::Runtime;
//!
//! let runtime = Runtime::new("example");
//! ndds_components::register(&runtime); // every type of docs/components.md
//! assert!(runtime.component_spec("lqg").is_some());
//!
//! // Or as a registry of its own, e.g. for the system loader:
//! let library = ndds_components::library();
//! assert!(library.spec("pid").is_some());
//! ```
//!
//! Every type also has a Rust constructor ([`Gain::new`], [`Lqg::new`], ...) for
//! `Runtime::install`. A refused parameter is `ModuleError::Param { name, reason }`, `name`
//! being the key a description file gives it (`plant.stiffness` for a key of the table
//! `plant`), so the loader can point at it; other failures are `ModuleError::Failed`.
//!
//! # Layout
//!
//! One component type per file, in directories by the chapters of docs/components.md; each
//! chapter's `mod.rs` holds its table of types and what its files share. Every type but
//! `product` is a `#[derive(Component)]` struct: its fields are its inputs, outputs and
//! parameters (the doc comment of each is its line in docs/components.md) and its state, and
//! its Rust constructor builds the same `Params` a description file gives and calls the
//! derived factory. `product` keeps a hand-written spec and factory (`Registry::add_with`):
//! whether its inputs must share a shape, and how its output's shape follows them, depend on
//! its `matrix` parameter.
//!
//! | file | holds |
//! |------|-------|
//! | `lib.rs` | this, the re-exports, [`register`] and [`library`] |
//! | `params.rs` | checks of parameter values, shared by every component |
//! | `mats.rs` | a module's CSMats and buffers: copy in/out, parameter CSMats, checked product |
//! | `sources/` | `constant.rs`, `step.rs`, `ramp.rs`, `sine.rs`, `noise.rs` |
//! | `arithmetic/` | `gain.rs`, `sum.rs`, `product.rs`, `saturation.rs`, `dead_band.rs`; `bounded.rs` (what the last two share) |
//! | `filters/` | `lowpass.rs`, `transfer_function.rs`, `state_space.rs` |
//! | `control/` | `pd.rs`, `pid.rs`, `lqg/` (`mod.rs` the module, `model.rs` its plant models, `weights.rs` its weights); `estimator.rs` and `state_feedback.rs` (Rust only, no type) |
//! | `trajectories/` | `trapezoidal.rs`, `quintic.rs` |
//! | `recorder.rs` | `recorder` and its [`RecorderHandle`] |
//! | `plants/` | `mass_spring_damper.rs`, `two_link_arm.rs`; `arm_model.rs` (the arm's physics) |
//! | `design/` | design maths, no modules: `discrete.rs`, `riccati.rs`, `lqg.rs` |
//! | `testing.rs` | what the unit tests share (tests only) |

#![warn(missing_docs)]

mod arithmetic;
mod control;
mod design;
mod filters;
mod mats;
mod params;
mod plants;
mod recorder;
mod sources;
#[cfg(test)]
mod testing;
mod trajectories;

pub use arithmetic::{
    dead_band::DeadBand, gain::Gain, product::Product, saturation::Saturation, sum::Sum,
};
pub use control::{
    estimator::Estimator,
    lqg::{ArmOutput, Lqg, LqgModel, MassOutput},
    pd::Pd,
    pid::{Pid, PidTuning},
    state_feedback::StateFeedback,
};
pub use design::{
    LqgDesign, LqgWeights, design_lqg, discretize, dlqr, kalman_gain, reference_gain,
};
pub use filters::{
    lowpass::LowPass,
    state_space::{StateSpace, StateSpaceModel},
    transfer_function::TransferFunction,
};
pub use plants::{
    arm_model::ArmModel,
    mass_spring_damper::{MassSpringDamper, Physical},
    two_link_arm::TwoLinkArm,
};
pub use recorder::{Recorder, RecorderHandle};
pub use sources::{constant::Constant, noise::Noise, ramp::Ramp, sine::Sine, step::Step};
pub use trajectories::{PointToPoint, quintic::Quintic, trapezoidal::Trapezoidal};

use ndds_runtime::{Registry, Runtime};

/// Adds the whole library to `runtime`'s registry, so that its description files can name
/// every component type documented in `docs/components.md`.
pub fn register(runtime: &Runtime) {
    runtime.add_library(library());
}

/// The whole library as a registry of its own (for [`Runtime::add_library`] or the system
/// loader's `LoadOptions::with_library`).
pub fn library() -> Registry {
    let mut registry = Registry::empty();
    sources::register(&mut registry);
    arithmetic::register(&mut registry);
    filters::register(&mut registry);
    control::register(&mut registry);
    trajectories::register(&mut registry);
    recorder::register(&mut registry);
    plants::register(&mut registry);
    registry
}

//! # ndds-runtime
//!
//! ControlShell on ndds: the real-time component layer control programs build on the SDK
//! (`ndds-client`). It holds the runtime's machinery, not its component library: a
//! [`Runtime`] starts with an empty registry, and `ndds_components::register(&runtime)` adds
//! the built-in library (`ndds run` does so).
//!
//! - [`CsMat`]: named matrices with field names and units; [`Mat`] is the shared handle the
//!   linking database gives out.
//! - [`Runtime`]: the linking database (every named object, reference before creation,
//!   [`verify`](Runtime::verify)), the component registry, the configuration manager
//!   (modules → groups → categories → configurations) and the network bindings.
//! - [`SampleModule`]: the nine entry routines; [`Binder`] declares a module's CSMats.
//! - [`Habitat`]: a periodic task running a dependency-sorted execution list, with
//!   statistics ([`HabitatStats`]) published on the network.
//! - [`fsm`]: finite state machines driving configurations; [`system`]: whole systems loaded
//!   from description files.
//!
//! ```
//! use ndds_runtime::{Binder, Clock, CsMat, HabitatOptions, Mat, ModuleError, RoutineResult,
//!     Runtime, SampleContext, SampleModule};
//!
//! /// `output = k · input`.
//! struct Scale { input: Mat, output: Mat, k: f64 }
//!
//! impl Scale {
//!     fn new(b: &mut Binder<'_>, input: &str, output: &str, k: f64) -> Result<Self, ModuleError> {
//!         Ok(Self { input: b.input(input, (1, 1)), output: b.output(output, (1, 1)), k })
//!     }
//! }
//!
//! impl SampleModule for Scale {
//!     fn execute(&mut self, _: &SampleContext) -> RoutineResult {
//!         let x = self.input.value(0, 0);
//!         self.output.write().set(0, 0, self.k * x)?;
//!         Ok(())
//!     }
//! }
//!
//! let rt = Runtime::new("example");
//! rt.create_mat(CsMat::from_row_slice("setpoint", 1, 1, &[1.5])?)?;
//! rt.create_habitat("servo", HabitatOptions::rate(1000.0).clock(Clock::Manual))?;
//! // Installed out of order: the list is sorted so `scale` runs after `double`.
//! rt.install("servo", "scale", |b| Scale::new(b, "doubled", "out", 10.0))?;
//! rt.install("servo", "double", |b| Scale::new(b, "setpoint", "doubled", 2.0))?;
//! assert!(rt.verify().is_ok());
//! let servo = rt.habitat("servo");
//! assert_eq!(servo.order(), ["double", "scale"]);
//! servo.start()?;
//! servo.step()?;
//! assert_eq!(rt.mat("out").value(0, 0), 30.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Layout
//! - `csmat`, `mat`, `database`, `registry`: data, the linking database, component types.
//! - `module`, `list`, `sort`, `habitat`, `clock`, `stats`: modules and how they run.
//! - `config`, `verify`, `binding`, `network`, `command`: configurations, checks, the network.
//! - [`fsm`], [`system`]: state machines and description files.
#![warn(missing_docs)]

// The derive's generated code names `::ndds_runtime`, which must resolve inside this crate's
// own tests and docs too.
#[allow(unused_extern_crates)]
extern crate self as ndds_runtime;

mod binding;
mod clock;
mod command;
pub mod component;
mod config;
pub mod csmat;
mod database;
pub mod describe;
mod error;
pub mod fsm;
mod habitat;
mod list;
mod mat;
mod module;
mod network;
mod registry;
mod requests;
#[allow(clippy::module_inception)]
mod runtime;
mod sort;
mod stats;
mod sync;
pub mod system;
mod verify;

pub use binding::{Freshness, InputStatus, stale_after};
pub use clock::pin_to_cpu;
pub use command::{HabitatAction, RuntimeCommand, command_port};
pub use component::Component;
pub use csmat::{CsMat, Field, MatError};
pub use database::ObjectKind;
pub use error::RuntimeError;
pub use habitat::{
    Clock, Habitat, HabitatError, HabitatLink, HabitatOptions, MAX_RATE_HZ, MIN_RATE_HZ,
};
pub use mat::Mat;
pub use module::{
    Binder, Interface, ModuleError, Port, RoutineResult, SampleContext, SampleModule, Shape, Use,
};
/// The matrix crate CSMats are made of (a component's own state is often a `DMatrix<f64>`):
/// the same version as the runtime's.
pub use nalgebra;
/// `#[derive(Component)]`: see [`Component`](trait@Component) and the attributes documented on
/// the macro.
pub use ndds_derive::Component;
pub use registry::{
    ComponentSpec, Factory, ParamError, ParamKind, ParamSpec, ParamValue, Params, Registry,
};
pub use runtime::Runtime;
pub use sort::{SortError, SortNode, sort};
pub use stats::{BEHIND_BELOW, HabitatStats, Pace, Percentiles};
pub use verify::{Problem, VerifyReport};

pub(crate) use runtime::Inner;

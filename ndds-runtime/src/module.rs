//! Sample modules: the [`SampleModule`] trait with ControlShell's nine entry routines, and the
//! [`Binder`] through which a module declares the CSMats it reads and writes.
//!
//! See [`SampleModule`] for when each routine is called.
//!
//! One module's routines never run at the same time. `execute` and `state_update` run on the
//! habitat's sampler (its thread, or the caller of `step`); `enable` and `disable` of a switch,
//! and the routines of a module being installed or removed, run on the thread that asked,
//! while the habitat keeps sampling (the table on [`SampleModule`]). Requests a routine makes
//! of its runtime or habitat are queued or refused, never carried out re-entrantly.
//!
//! A module reaches its CSMats through [`Mat::read`] and [`Mat::write`]; those only its own
//! habitat names take no lock in its sampler (the `mat` module's doc).

use std::time::Duration;

use super::csmat::{CsMat, MatError};
use super::mat::Mat;

/// What a module knows about the sample it is called for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleContext {
    /// The habitat's sample period now.
    pub period: Duration,
    /// Samples executed since sampling began (the first is 0).
    pub sample: u64,
    /// Nominal time of this sample since sampling began (sum of the periods).
    pub time: Duration,
}

impl SampleContext {
    /// The period in seconds, as controllers use it.
    pub fn dt(&self) -> f64 {
        self.period.as_secs_f64()
    }
}

/// A module's routine failed. The habitat counts it (see
/// [`HabitatStats::module_errors`](super::HabitatStats::module_errors)), logs the first failure of
/// each module, and goes on sampling.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ModuleError {
    /// Matrix arithmetic refused its operands.
    #[error(transparent)]
    Mat(#[from] MatError),
    /// A parameter is missing, mistyped or out of range: `name` is the key a description
    /// file gives it (`plant.stiffness` for a key of a table), so the loader can point at it.
    #[error("parameter `{name}`: {reason}")]
    Param {
        /// The parameter (dotted for a key inside a table parameter).
        name: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The module publishes or subscribes and its runtime has no participant.
    #[error("needs the network, and its runtime has no participant (Runtime::with_participant)")]
    NeedsParticipant,
    /// Anything else, in the module's words.
    #[error("{0}")]
    Failed(String),
}

impl ModuleError {
    /// A [`ModuleError::Param`].
    pub fn param(name: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Param {
            name: name.into(),
            reason: reason.into(),
        }
    }
}

/// Result of an entry routine.
pub type RoutineResult = Result<(), ModuleError>;

/// A sample module: the unit of reusable sampled-data code. Every routine defaults to doing
/// nothing. When the habitat calls each:
///
/// | routine          | when it is called                                                      | on which thread |
/// |------------------|------------------------------------------------------------------------|-----------------|
/// | `execute`        | once each sample period, active modules, in dependency order           | the habitat's (the caller of `step` for a manual one) |
/// | `state_update`   | each sample, after every active module's `execute`, same order         | the habitat's |
/// | `enable`         | when the module joins the active set while sampling: at `start` after the startups; at a configuration switch *before* its first sample, while the old set still samples (so it can read the leaving modules' outputs and may take long: an LQG design costs no sample); when installed into a running habitat, before it joins | `start`'s caller; the caller of `switch` or `install` |
/// | `disable`        | when it leaves the active set while sampling: at a switch *after* its last sample; at removal; at `stop` before the shutdowns | the caller of `switch`, `remove`, `stop` |
/// | `startup`        | when sampling begins, every installed module (active or not), list order | `start`'s caller (`install`'s for a module installed while sampling) |
/// | `shutdown`       | when sampling ends, every installed module                             | `stop`'s caller (`remove`'s) |
/// | `timing_changed` | when the habitat's rate changes, every installed module, at the next sample boundary | the habitat's when it samples on a thread of its own, else `set_rate`'s caller |
/// | `reset`          | after [`Habitat::reset`](super::Habitat::reset), every installed module, at the next sample boundary | as `timing_changed` |
/// | `terminate`      | when the module is unloaded (removed, or its runtime dropped)          | the caller of `remove` (or the last holder of the runtime) |
///
/// One module's routines never run concurrently, and a habitat never waits for a routine
/// that runs elsewhere: `enable` and `disable` run on modules lent out of the list, while the
/// habitat samples the others (see `config.rs`). Because `disable` runs after the switch, it
/// must not write the module's outputs: a module that entered may write them now.
///
/// A routine may ask its runtime or habitat for work: [`Runtime::switch`](super::Runtime::switch)
/// and a habitat's `start`, `stop`, `set_rate` and `reset` are queued and carried out on the
/// runtime's request thread once the routine has returned (their outcome is logged);
/// `install`, `remove`, `step` and declaring groups or configurations are refused with an
/// `InsideRoutine` error. Neither can deadlock.
#[allow(unused_variables)]
pub trait SampleModule: Send + 'static {
    /// Once each sample period.
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        Ok(())
    }
    /// After all executes of the sample are done.
    fn state_update(&mut self, ctx: &SampleContext) -> RoutineResult {
        Ok(())
    }
    /// When this module is made active.
    fn enable(&mut self, ctx: &SampleContext) -> RoutineResult {
        Ok(())
    }
    /// When it is removed from the active set.
    fn disable(&mut self, ctx: &SampleContext) -> RoutineResult {
        Ok(())
    }
    /// When sampling begins.
    fn startup(&mut self, ctx: &SampleContext) -> RoutineResult {
        Ok(())
    }
    /// When sampling ends.
    fn shutdown(&mut self, ctx: &SampleContext) -> RoutineResult {
        Ok(())
    }
    /// When the sample rate changes (`ctx.period` is the new period).
    fn timing_changed(&mut self, ctx: &SampleContext) -> RoutineResult {
        Ok(())
    }
    /// When the user resets the habitat.
    fn reset(&mut self, ctx: &SampleContext) -> RoutineResult {
        Ok(())
    }
    /// When the module is unloaded.
    fn terminate(&mut self) {}
}

/// The shape a module expects of a CSMat.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// Whatever it is (rate transitions, publishers).
    Any,
    /// Exactly `rows × cols`.
    Exact(usize, usize),
}

impl From<(usize, usize)> for Shape {
    fn from((rows, cols): (usize, usize)) -> Self {
        Shape::Exact(rows, cols)
    }
}

impl std::fmt::Display for Shape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Shape::Any => f.write_str("any shape"),
            Shape::Exact(rows, cols) => write!(f, "{rows}x{cols}"),
        }
    }
}

/// How a module uses an input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Use {
    /// Read in `execute`: every writer must run before this module in the same sample.
    Feedthrough,
    /// Read only in `state_update` (or before being written): does not order the list, so a
    /// loop through it is legal.
    State,
    /// A parameter (gain, constant): set by the application, not by modules.
    Parameter,
}

/// One declared use of a CSMat.
#[derive(Clone, Debug)]
pub struct Port {
    /// The module's own name for it.
    pub role: String,
    /// The CSMat.
    pub mat: Mat,
    /// The shape the module expects.
    pub shape: Shape,
}

/// Everything a module reads and writes.
#[derive(Clone, Debug, Default)]
pub struct Interface {
    /// Inputs, with how each is used.
    pub inputs: Vec<(Port, Use)>,
    /// Outputs (this module writes them).
    pub outputs: Vec<Port>,
}

impl Interface {
    /// Names of the CSMats written.
    pub fn output_names(&self) -> impl Iterator<Item = &str> {
        self.outputs.iter().map(|port| port.mat.name())
    }

    /// Names of the CSMats read with [`Use::Feedthrough`].
    pub fn feedthrough_names(&self) -> impl Iterator<Item = &str> {
        self.inputs
            .iter()
            .filter(|(_, usage)| *usage == Use::Feedthrough)
            .map(|(port, _)| port.mat.name())
    }
}

/// Declares a module's CSMats while it is being built: each call looks the matrix up in the
/// linking database (creating a placeholder if it does not exist yet) and records the use.
pub struct Binder<'a> {
    pub(crate) lookup: &'a mut dyn FnMut(&str) -> Mat,
    pub(crate) module: String,
    pub(crate) interface: Interface,
    /// `(output, input)`: outputs that take their input's shape once it is known.
    pub(crate) follows: Vec<(String, String)>,
    /// CSMats this module's declarations created (undone if the install fails).
    pub(crate) created: Vec<Mat>,
    /// The habitat the module is installed into (none for a detached binder).
    pub(crate) habitat: Option<super::habitat::HabitatLink>,
}

impl<'a> Binder<'a> {
    /// A binder attached to no runtime, for building a module in a unit test or a tool:
    /// `lookup` supplies the CSMat for each name the module declares.
    pub fn detached(module: &str, lookup: &'a mut dyn FnMut(&str) -> Mat) -> Self {
        Self {
            lookup,
            module: module.to_owned(),
            interface: Interface::default(),
            follows: Vec::new(),
            created: Vec::new(),
            habitat: None,
        }
    }

    /// The habitat the module is being installed into (`None` for a detached binder): keep it
    /// to ask, from a routine, for the habitat's clock source and rate, or to change its rate,
    /// reset, start or stop it (queued to the sample boundary, see [`SampleModule`]).
    pub fn habitat(&self) -> Option<super::habitat::HabitatLink> {
        self.habitat.clone()
    }

    /// The declarations made so far.
    pub fn interface(&self) -> &Interface {
        &self.interface
    }

    /// The name of the module being built (use it to name private CSMats: `"{name}.state"`).
    pub fn module_name(&self) -> &str {
        &self.module
    }

    /// A direct-feedthrough input: read in `execute`.
    pub fn input(&mut self, mat: &str, shape: impl Into<Shape>) -> Mat {
        self.declare_input(mat, mat, shape.into(), Use::Feedthrough)
    }

    /// An input read only in `state_update` (closes feedback loops).
    pub fn state_input(&mut self, mat: &str, shape: impl Into<Shape>) -> Mat {
        self.declare_input(mat, mat, shape.into(), Use::State)
    }

    /// A parameter (set by the application).
    pub fn param(&mut self, mat: &str, shape: impl Into<Shape>) -> Mat {
        self.declare_input(mat, mat, shape.into(), Use::Parameter)
    }

    /// A parameter with a default: if nobody created the CSMat yet, it is created from
    /// `default` (whose shape it then must keep).
    pub fn param_or(&mut self, mat: &str, default: CsMat) -> Mat {
        let shape = Shape::Exact(default.rows(), default.cols());
        let handle = self.declare_input(mat, mat, shape, Use::Parameter);
        if !handle.is_bound() {
            handle.bind(default);
            self.created.push(handle.clone());
        }
        handle
    }

    /// An output: this module writes it. An unbound CSMat is created here, zero, with the
    /// declared shape.
    pub fn output(&mut self, mat: &str, shape: impl Into<Shape>) -> Mat {
        let shape = shape.into();
        let handle = (self.lookup)(mat);
        if let (false, Shape::Exact(rows, cols)) = (handle.is_bound(), shape) {
            handle.bind(CsMat::zeros(mat, rows, cols));
            self.created.push(handle.clone());
        }
        self.interface.outputs.push(Port {
            role: mat.to_owned(),
            mat: handle.clone(),
            shape,
        });
        handle
    }

    /// An output with the same shape as `input` (one of this module's inputs): created as
    /// soon as the input's shape is known, even if that is after this module is installed.
    pub fn output_same_as(&mut self, mat: &str, input: &Mat) -> Mat {
        let shape = if input.is_bound() {
            Shape::Exact(input.shape().0, input.shape().1)
        } else {
            self.follows.push((mat.to_owned(), input.name().to_owned()));
            Shape::Any
        };
        self.output(mat, shape)
    }

    /// An output created, if it does not exist yet, from `template` (with its field names and
    /// units).
    pub fn output_like(&mut self, mat: &str, template: CsMat) -> Mat {
        let shape = Shape::Exact(template.rows(), template.cols());
        let handle = self.output(mat, Shape::Any);
        if !handle.is_bound() {
            handle.bind(template);
            self.created.push(handle.clone());
        }
        if let Some(port) = self.interface.outputs.last_mut() {
            port.shape = shape;
        }
        handle
    }

    fn declare_input(&mut self, role: &str, mat: &str, shape: Shape, usage: Use) -> Mat {
        let handle = (self.lookup)(mat);
        self.interface.inputs.push((
            Port {
                role: role.to_owned(),
                mat: handle.clone(),
                shape,
            },
            usage,
        ));
        handle
    }
}

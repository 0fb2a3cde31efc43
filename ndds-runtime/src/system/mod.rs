//! Systems built at run time from description files (ControlShell's way of assembling whole
//! control hierarchies from data): habitats, CSMats, components from the library, module
//! groups and configurations, network bindings, rate transitions, state machines, triggers
//! and ports, in TOML files that may include each other.
//!
//! [`System::load`] reads and checks every file, reporting each problem where it was written
//! (`file:line:column: what is wrong; expected what`), builds the system through the linking
//! database and runs [`verify`](crate::Runtime::verify) before anything goes live;
//! [`System::start`] starts the habitats, state machines and ports; [`System::stop`] (or
//! dropping it) stops them through their shutdown routines. The format is described in
//! `docs/description-files.md`.
//!
//! ```
//! use ndds_runtime::system::System;
//!
//! let text = r#"
//! [[habitat]]
//! name = "servo"
//! rate = 100.0
//! clock = "manual"
//!
//! [[component]]
//! name = "source"
//! type = "constant"
//! habitat = "servo"
//! value = [1.5]
//! output = "setpoint"
//!
//! [[component]]
//! name = "double"
//! type = "gain"
//! habitat = "servo"
//! input = "setpoint"
//! output = "out"
//! k = 2.0
//! "#;
//! // The built-in library (ndds-components, a dev-dependency here) makes `constant` and `gain`.
//! let system = System::from_str("servo.toml", text, None, ndds_components::library())?;
//! system.start()?;
//! system.runtime().habitat("servo").step()?;
//! assert_eq!(system.runtime().mat("out").value(0, 0), 3.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod build;
pub(crate) mod decl;
mod source;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock, Weak};

pub use build::PortReply;
pub use decl::{SECTION_KEYS, SECTIONS, Serves};
pub use source::{
    Diagnostic, Diagnostics, Location, MAX_FILE_BYTES, MAX_FILES, MAX_INCLUDE_DEPTH, Overlay,
    overlay_key,
};

use crate::fsm::{FsmError, MachineState, StateMachine};
use crate::sync::lock;
use crate::{HabitatStats, Registry, Runtime, RuntimeError};
use ndds_client::Participant;

/// Why a system could not be loaded or started.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SystemError {
    /// The description is wrong: every problem, each where it was written.
    #[error("{0}")]
    Invalid(Diagnostics),
    /// Loaded without a participant, the description is right but needs the network: each
    /// network binding and port (or module that needs a participant), where it was written.
    /// Load it again with a participant. Reported only when nothing else is wrong
    /// ([`Invalid`](Self::Invalid) comes first).
    #[error("{0}")]
    NeedsParticipant(Diagnostics),
    /// The runtime refused to start.
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
    /// A state machine refused to start.
    #[error(transparent)]
    Fsm(#[from] FsmError),
    /// A port could not be declared.
    #[error("port `{port}`: {message}")]
    Port {
        /// The port.
        port: String,
        /// What went wrong.
        message: String,
    },
    /// [`System::start`] was called twice.
    #[error("system `{0}` was started already")]
    AlreadyStarted(String),
    /// [`System::start`] of a system loaded with [`LoadOptions::check`].
    #[error("system `{0}` was loaded to be checked only; load it without `check` to run it")]
    CheckOnly(String),
}

/// Where triggers and ports find a state machine once the system runs. A weak reference: only
/// the [`System`] owns its machines, and stopping it joins their threads on the caller's
/// thread (a trigger or a machine's own thread never ends up dropping a machine).
pub(crate) type MachineSlot = Arc<OnceLock<Weak<StateMachine>>>;

/// A state machine of the system: verified at load, running after `start`.
pub(crate) struct MachineEntry {
    pub(crate) slot: MachineSlot,
    pub(crate) running: Mutex<Option<Arc<StateMachine>>>,
    pub(crate) pending: build::PendingMachine,
}

/// A loaded system: its runtime (the linking database with everything the files declared),
/// the state machines and ports it starts.
pub struct System {
    name: String,
    /// The topics its bindings and state machines publish and take.
    topics: Vec<String>,
    files: Vec<PathBuf>,
    runtime: Runtime,
    participant: Option<Participant>,
    description: Option<String>,
    display: Vec<String>,
    machines: BTreeMap<String, MachineEntry>,
    ports: Vec<decl::PortDecl>,
    servers: Mutex<Vec<build::PortServer>>,
    started: Mutex<bool>,
    /// Loaded with [`LoadOptions::check`]: never started.
    check_only: bool,
    /// [`simulate`](Self::simulate)'s clock: simulated seconds, samples per habitat.
    simulated: Mutex<(f64, Vec<u64>)>,
}

impl System {
    /// Reads `path` and the files it includes, checks them, builds the system and verifies
    /// it. Its components are made from `library`'s types (the built-in library is
    /// `ndds_components::library()`). With a participant, network bindings, state machines
    /// and ports are on the network; without one, a description that publishes, subscribes
    /// or declares ports is refused with [`SystemError::NeedsParticipant`].
    pub fn load(
        path: impl AsRef<Path>,
        participant: Option<&Participant>,
        library: Registry,
    ) -> Result<Self, SystemError> {
        Self::load_with(
            path,
            participant,
            LoadOptions::default().with_library(library),
        )
    }

    /// [`load`](Self::load) with options.
    pub fn load_with(
        path: impl AsRef<Path>,
        participant: Option<&Participant>,
        options: LoadOptions,
    ) -> Result<Self, SystemError> {
        let path = path.as_ref();
        let files = source::read_all(path, &options.overlay).map_err(SystemError::Invalid)?;
        let stem = path
            .file_stem()
            .map_or_else(|| "system".to_owned(), |s| s.to_string_lossy().into_owned());
        build::build(files, &stem, participant, options)
    }

    /// Reads `path` into an existing runtime (one with component types of your own
    /// registered, see [`Runtime::register_component`]); the runtime's name and participant are
    /// used, `[system] name` is not.
    pub fn load_into(runtime: Runtime, path: impl AsRef<Path>) -> Result<Self, SystemError> {
        let files =
            source::read_all(path.as_ref(), &Overlay::new()).map_err(SystemError::Invalid)?;
        let participant = runtime.participant().cloned();
        build::build_into(files, runtime, participant.as_ref(), LoadOptions::default())
    }

    /// The same from text (named `name` in messages; includes are relative to the current
    /// directory).
    pub fn from_str(
        name: &str,
        text: &str,
        participant: Option<&Participant>,
        library: Registry,
    ) -> Result<Self, SystemError> {
        let files = source::read_text(name, text, Path::new(".")).map_err(SystemError::Invalid)?;
        let stem = Path::new(name)
            .file_stem()
            .map_or_else(|| "system".to_owned(), |s| s.to_string_lossy().into_owned());
        let options = LoadOptions::default().with_library(library);
        build::build(files, &stem, participant, options)
    }

    /// The topics the system's bindings publish and subscribe to, and its state machines'
    /// state and stimulus topics (`fsm/M/state`, `fsm/M/events`), sorted; its statistics and
    /// configuration topics are `cs/NAME/...` (what `ndds run --record` records).
    pub fn topics(&self) -> &[String] {
        &self.topics
    }

    /// The system's name (`[system] name`, else the top file's name without extension); also
    /// its runtime's name, so its habitats' statistics are on `cs/<name>/<habitat>/stats`.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// `[system] description`.
    pub fn description(&self) -> Option<&str> {
        self.description.as_deref()
    }

    /// The files read, the top file last.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// The runtime the system was built in.
    pub fn runtime(&self) -> &Runtime {
        &self.runtime
    }

    /// The CSMats `[system] display` names.
    pub fn display(&self) -> &[String] {
        &self.display
    }

    /// Names of the state machines.
    pub fn machine_names(&self) -> Vec<String> {
        self.machines.keys().cloned().collect()
    }

    /// The running state machine `name` (between [`start`](Self::start) and
    /// [`stop`](Self::stop)).
    pub fn machine(&self, name: &str) -> Option<Arc<StateMachine>> {
        self.machines
            .get(name)
            .and_then(|entry| lock(&entry.running).clone())
    }

    /// Starts the state machines (so the first trigger finds its machine), the habitats,
    /// then the ports.
    pub fn start(&self) -> Result<(), SystemError> {
        let mut started = lock(&self.started);
        if *started {
            return Err(SystemError::AlreadyStarted(self.name.clone()));
        }
        if self.check_only {
            return Err(SystemError::CheckOnly(self.name.clone()));
        }
        // Once only, even if starting fails half way (load the system anew to retry).
        *started = true;
        for (name, entry) in &self.machines {
            match entry
                .pending
                .start(&self.runtime, self.participant.as_ref())
            {
                Ok(machine) => {
                    let machine = Arc::new(machine);
                    let _ = entry.slot.set(Arc::downgrade(&machine));
                    *lock(&entry.running) = Some(machine);
                }
                Err(err) => {
                    tracing::debug!(machine = %name, "state machine did not start: {err}");
                    self.stop_inner();
                    return Err(err.into());
                }
            }
        }
        if let Err(err) = self.runtime.start_all() {
            self.stop_inner();
            return Err(err.into());
        }
        if let Some(participant) = &self.participant {
            let mut servers = lock(&self.servers);
            for port in &self.ports {
                match build::PortServer::start(self, participant, port) {
                    Ok(server) => servers.push(server),
                    Err(err) => {
                        drop(servers);
                        self.stop_inner();
                        return Err(err);
                    }
                }
            }
        }
        Ok(())
    }

    /// Runs a system loaded with [`LoadOptions::simulated`] for `seconds` of simulated time:
    /// each habitat samples at its own rate, in time order (habitats due at the same time in
    /// name order), as fast as the machine allows; simulated time goes on
    /// from one call to the next. Returns the samples run.
    pub fn simulate(&self, seconds: f64) -> Result<u64, SystemError> {
        let habitats: Vec<_> = self
            .runtime
            .habitats()
            .into_iter()
            .filter(|h| h.is_created())
            .collect();
        // Simulated time goes on from call to call: samples run so far, per habitat.
        let mut clock = lock(&self.simulated);
        clock.1.resize(habitats.len(), 0);
        let end = clock.0 + seconds.max(0.0);
        let due = |i: usize, count: u64| count as f64 * habitats[i].period().as_secs_f64();
        let mut samples = 0;
        loop {
            // A habitat a state machine stopped takes no more samples.
            let next = (0..habitats.len())
                .filter(|&i| habitats[i].is_running())
                .map(|i| (due(i, clock.1[i]), i))
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let Some((at, i)) = next else { break };
            // A nanosecond's grace: sums of short steps must not run a sample early.
            if at + 1e-9 >= end {
                break;
            }
            habitats[i]
                .step()
                .map_err(|e| SystemError::Runtime(e.into()))?;
            samples += 1;
            clock.1[i] += 1;
        }
        clock.0 = end;
        Ok(samples)
    }

    /// Stops ports, habitats (their disable and shutdown routines run) and state machines.
    /// Stopping a stopped system does nothing; a stopped system, or one whose `start` failed,
    /// cannot be started again (load it anew).
    pub fn stop(&self) {
        self.stop_inner();
    }

    fn stop_inner(&self) {
        // The reverse of starting: ports, habitats (their disable and shutdown routines), then
        // the state machines, joined here (no trigger can reach them any more).
        for server in lock(&self.servers).drain(..) {
            server.stop();
        }
        self.runtime.stop_all();
        for entry in self.machines.values() {
            let machine = lock(&entry.running).take();
            if let Some(machine) = machine {
                machine.stop();
                drop(machine);
            }
        }
    }

    /// What the system is doing now: habitats with rate and jitter, the configuration, state
    /// machines, subscribed inputs (received, never received or stale), and the displayed
    /// CSMats.
    pub fn status(&self) -> Status {
        Status {
            system: self.name.clone(),
            configuration: self.runtime.current_configuration(),
            habitats: self
                .runtime
                .habitats()
                .iter()
                .filter(|h| h.is_created())
                .map(|h| self.runtime.habitat_stats(h))
                .collect(),
            machines: self
                .machines
                .values()
                .filter_map(|entry| lock(&entry.running).as_ref().map(|m| m.snapshot()))
                .collect(),
            inputs: self.runtime.inputs(),
            display: self
                .display
                .iter()
                .map(|name| {
                    let value = self.runtime.mat(name).read().clone();
                    (name.clone(), value)
                })
                .collect(),
        }
    }
}

impl Drop for System {
    fn drop(&mut self) {
        self.stop_inner();
    }
}

impl Status {
    /// Module routine failures counted by all habitats since they started.
    pub fn module_errors(&self) -> u64 {
        self.habitats.iter().map(|h| h.module_errors).sum()
    }
}

/// How a description is loaded.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// The component types the description may name (empty by default: the built-in library
    /// is `ndds_components::library()`, see [`with_library`](Self::with_library)).
    pub library: Registry,
    /// The system's name instead of the files' (`[system] name`, else the top file's name):
    /// for a second copy of a system in one domain. Its runtime, statistics and command port
    /// take this name; its topics and state machines keep the names the files give them.
    pub name: Option<String>,
    /// Load to verify only: the system is never started, so its runtime serves nothing and
    /// does not hold its name in the domain (a running copy does not refuse it).
    pub check: bool,
    /// Every habitat is clocked by [`System::simulate`] (or [`Habitat::step`](
    /// crate::Habitat::step)) instead of its timer or clock topic: simulated time,
    /// as fast as the machine allows (for tests, and for trying a system without its hardware).
    /// A topic the system both publishes and subscribes to is passed on inside the process
    /// (as a rate transition from the published CSMat), so a loop closed through it runs in
    /// simulated time too; the topic is still published for others to watch. Samples from
    /// other programs still travel in real time: a loop closed through another process is
    /// not time-accurate in simulation.
    pub simulated: bool,
    /// Texts that stand in for files (an editor's unsaved files, keyed by [`overlay_key`]):
    /// the description files, included files and state-machine files named there are read
    /// from here instead of the disk. Empty by default.
    pub overlay: Arc<Overlay>,
}

impl LoadOptions {
    /// Simulated time and otherwise the defaults: every habitat clocked by
    /// [`System::simulate`].
    pub fn simulated() -> Self {
        Self {
            simulated: true,
            ..Self::default()
        }
    }

    /// These options with `library` as the component types.
    pub fn with_library(mut self, library: Registry) -> Self {
        self.library = library;
        self
    }
}

/// A snapshot of a running system, as `ndds run` prints it.
#[derive(Clone, Debug)]
pub struct Status {
    /// The system's name.
    pub system: String,
    /// The active configuration (`None` before any switch).
    pub configuration: Option<String>,
    /// Each habitat's statistics.
    pub habitats: Vec<HabitatStats>,
    /// Each state machine's state.
    pub machines: Vec<MachineState>,
    /// Each subscribed CSMat: what it received and when.
    pub inputs: Vec<crate::InputStatus>,
    /// The displayed CSMats' values.
    pub display: Vec<(String, crate::CsMat)>,
}

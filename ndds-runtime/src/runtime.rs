//! [`Runtime`]: one process's ControlShell system — its linking database (CSMats, modules,
//! habitats), component registry and verification. The configuration manager is in
//! `config.rs`, network bindings and services in `network.rs`, errors in `error.rs`.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex, MutexGuard, Weak};
use std::thread::JoinHandle;

use super::binding::{InputStatus, Reception, Subscriber};
use super::csmat::CsMat;
use super::database::{Database, ModuleEntry, ObjectKind};
use super::error::RuntimeError;
use super::habitat::{
    Habitat, HabitatError, HabitatOptions, period_is_usable, stats_interval_is_usable,
};
use super::list::{Routine, Slot, inside_routine, run_routine};
use super::mat::Mat;
use super::module::{Binder, Interface, ModuleError, SampleModule};
use super::registry::{Params, Registry};
use super::requests::{self, Request};
use super::stats::HabitatStats;
use super::verify::{VerifyReport, verify};
use ndds_client::{CallbackConsumer, Participant};

pub(crate) use super::sync::lock;

/// Refuses a call made inside a module's routine that cannot be queued.
pub(crate) fn refuse_inside_routine(operation: &'static str) -> Result<(), RuntimeError> {
    if inside_routine() {
        return Err(RuntimeError::InsideRoutine { operation });
    }
    Ok(())
}

/// What a failed install undoes: the CSMats its declarations bound, the placeholders it
/// added, its shape-following entries.
struct Undo {
    created: Vec<Mat>,
    new_names: Vec<String>,
    follows_before: usize,
}

impl Undo {
    fn apply(&self, db: &mut Database) {
        for mat in &self.created {
            mat.unbind();
        }
        for name in &self.new_names {
            db.mats.remove(name);
        }
        db.follows.truncate(self.follows_before);
    }
}

/// The runtime's shared state.
pub(crate) struct Inner {
    pub(crate) name: String,
    db: Mutex<Database>,
    pub(crate) participant: Option<Participant>,
    registry: Mutex<Registry>,
    pub(crate) services: Mutex<Option<Services>>,
    /// Subscribed CSMats by module (`subscribe:<topic>`): habitat and what it records. Never
    /// locked by a habitat thread.
    inputs: Mutex<BTreeMap<String, (String, Arc<Reception>)>>,
    /// Held for the whole of every change to habitats and their lists (install, remove,
    /// switch, start, stop, rate, reset), including the routines those run off the habitat
    /// threads. Never taken by a habitat thread or inside a routine, so changes take turns
    /// without a habitat ever waiting for one. Lock order: `structure`, then `db`, then a
    /// list; `db` is never held while waiting for a list.
    structure: Mutex<()>,
    /// The request thread's queue (started with the first request, see `requests.rs`).
    requests: Mutex<Option<Sender<Request>>>,
    /// This runtime, for the request thread.
    this: Weak<Inner>,
    /// What a loaded system adds to its description (`describe.rs`). Never locked by a
    /// habitat thread.
    extras: Mutex<super::describe::Extras>,
}

pub(crate) struct Services {
    pub(crate) stop: Arc<AtomicBool>,
    pub(crate) stats: Option<JoinHandle<()>>,
    /// The command port's server (`super::command`).
    pub(crate) commands: Option<JoinHandle<()>>,
    pub(crate) _configure: CallbackConsumer,
}

impl Inner {
    pub(crate) fn verify(&self) -> VerifyReport {
        verify(&lock(&self.db))
    }

    /// Takes the structure lock (see the field).
    pub(crate) fn structure(&self) -> MutexGuard<'_, ()> {
        lock(&self.structure)
    }

    /// Queues a request made inside a routine (see `requests.rs`).
    pub(crate) fn request(&self, request: Request) {
        let mut queue = lock(&self.requests);
        if queue.is_none() {
            match requests::spawn(Weak::clone(&self.this)) {
                Ok(tx) => *queue = Some(tx),
                Err(error) => {
                    tracing::error!(runtime = %self.name, ?request, %error,
                        "cannot start the request thread; request dropped");
                    return;
                }
            }
        }
        if let Some(tx) = queue.as_ref() {
            // The receiver lives as long as the runtime: a send cannot fail while `self` does.
            let _ = tx.send(request);
        }
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        if let Some(mut services) = lock(&self.services).take() {
            services.stop.store(true, Ordering::Release);
            // The last handle may be the one the statistics or command thread holds for a
            // moment.
            for thread in [services.stats.take(), services.commands.take()]
                .into_iter()
                .flatten()
            {
                if thread.thread().id() != std::thread::current().id() {
                    let _ = thread.join();
                }
            }
        }
        let habitats: Vec<Habitat> = lock(&self.db).habitats.values().cloned().collect();
        for habitat in habitats {
            habitat.stop();
            lock(&habitat.shared.list).terminate();
        }
    }
}

/// One process's ControlShell system.
///
/// ```
/// use ndds_components::Gain; // the built-in library (a dev-dependency here)
/// use ndds_runtime::{Clock, CsMat, HabitatOptions, Runtime};
///
/// let rt = Runtime::new("demo");
/// rt.create_mat(CsMat::from_row_slice("x", 1, 1, &[2.0])?)?;
/// rt.create_habitat("servo", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
/// rt.install("servo", "double", |b| Gain::new(b, "x", "y", 2.0))?;
/// let servo = rt.habitat("servo");
/// servo.start()?;
/// servo.step()?;
/// assert_eq!(rt.mat("y").value(0, 0), 4.0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone)]
pub struct Runtime {
    pub(crate) inner: Arc<Inner>,
}

impl std::fmt::Debug for Runtime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Runtime")
            .field("name", &self.inner.name)
            .finish_non_exhaustive()
    }
}

pub(crate) fn check_name(kind: ObjectKind, name: &str) -> Result<(), RuntimeError> {
    let slash = kind == ObjectKind::Habitat && name.contains('/');
    let why = if name.is_empty() {
        "empty"
    } else if name.chars().any(char::is_control) {
        "control characters are not allowed"
    } else if slash {
        "`/` is not allowed (the name is part of topic names)"
    } else {
        return Ok(());
    };
    Err(RuntimeError::BadName {
        kind,
        name: name.to_owned(),
        why,
    })
}

impl Runtime {
    /// A runtime without network access (bindings and services need
    /// [`with_participant`](Self::with_participant)). Its component registry starts empty:
    /// add a library with [`add_library`](Self::add_library) (for the built-in one,
    /// `ndds_components::register(&runtime)`) or single types with
    /// [`add_component`](Self::add_component).
    pub fn new(name: &str) -> Self {
        Self::build(name, None)
    }

    fn build(name: &str, participant: Option<Participant>) -> Self {
        let registry = Registry::empty();
        Self {
            inner: Arc::new_cyclic(|this| Inner {
                name: name.to_owned(),
                db: Mutex::new(Database::default()),
                participant,
                registry: Mutex::new(registry),
                services: Mutex::new(None),
                inputs: Mutex::new(BTreeMap::new()),
                structure: Mutex::new(()),
                requests: Mutex::new(None),
                this: Weak::clone(this),
                extras: Mutex::new(super::describe::Extras::default()),
            }),
        }
    }

    pub(crate) fn from_inner(inner: Arc<Inner>) -> Self {
        Self { inner }
    }

    /// A runtime on the network: CSMats can be bound to topics, each habitat's statistics are
    /// published on `cs/<runtime>/<habitat>/stats` once per statistics interval, and a string
    /// sample on `cs/<runtime>/configure` switches to the configuration it names.
    pub fn with_participant(name: &str, participant: &Participant) -> Result<Self, RuntimeError> {
        let rt = Self::with_participant_unserved(name, participant)?;
        rt.start_services(participant)?;
        Ok(rt)
    }

    /// A runtime whose bindings are on the network but which starts no services (statistics,
    /// configure topic, command port), so it does not hold its name in the domain: for
    /// loading a description only to verify it while a copy of it runs.
    pub(crate) fn with_participant_unserved(
        name: &str,
        participant: &Participant,
    ) -> Result<Self, RuntimeError> {
        check_name(ObjectKind::Habitat, name).map_err(|_| RuntimeError::BadName {
            kind: ObjectKind::Habitat,
            name: name.to_owned(),
            why: "a runtime name must be non-empty, without `/` or control characters",
        })?;
        Ok(Self::build(name, Some(participant.clone())))
    }

    /// Its name.
    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// Its participant, if it has one.
    pub fn participant(&self) -> Option<&Participant> {
        self.inner.participant.as_ref()
    }

    pub(crate) fn db(&self) -> MutexGuard<'_, Database> {
        lock(&self.inner.db)
    }

    /// What a loaded system adds to the runtime's description.
    pub(crate) fn extras(&self) -> super::describe::Extras {
        lock(&self.inner.extras).clone()
    }

    pub(crate) fn set_extras(&self, extras: super::describe::Extras) {
        *lock(&self.inner.extras) = extras;
    }

    /// Adds every component type of `library` to this runtime's registry (replacing types of
    /// the same name).
    pub fn add_library(&self, library: Registry) {
        lock(&self.inner.registry).extend(library);
    }

    /// Registers a component type (replacing one of the same name).
    pub fn register_component<F, M>(&self, name: &str, description: &str, factory: F)
    where
        F: Fn(&mut Binder<'_>, &super::registry::Params) -> Result<M, ModuleError>
            + Send
            + Sync
            + 'static,
        M: SampleModule,
    {
        lock(&self.inner.registry).register(name, description, factory);
    }

    /// The registered component types with their descriptions.
    pub fn component_types(&self) -> Vec<(String, String)> {
        lock(&self.inner.registry)
            .types()
            .map(|(n, d)| (n.to_owned(), d.to_owned()))
            .collect()
    }

    /// Registers a documented component type: description files are checked against `spec`.
    pub fn add_component<F, M>(&self, spec: &'static super::registry::ComponentSpec, factory: F)
    where
        F: Fn(&mut Binder<'_>, &super::registry::Params) -> Result<M, ModuleError>
            + Send
            + Sync
            + 'static,
        M: SampleModule,
    {
        lock(&self.inner.registry).add_with(spec, factory);
    }

    /// The documented parameters of component type `name` (`None` if unknown or registered
    /// without a spec).
    pub fn component_spec(&self, name: &str) -> Option<&'static super::registry::ComponentSpec> {
        lock(&self.inner.registry).spec(name)
    }

    /// Every documented component type.
    pub fn component_specs(&self) -> Vec<&'static super::registry::ComponentSpec> {
        lock(&self.inner.registry).specs().collect()
    }

    // ----- the linking database -----

    /// The CSMat named `name`: the existing one, or a placeholder (unbound, 0 × 0) that is
    /// bound when the matrix is created.
    pub fn mat(&self, name: &str) -> Mat {
        let mut db = self.db();
        let mat = db.mat(name);
        if let Some(entry) = db.mats.get_mut(name) {
            entry.looked_up = true;
        }
        mat
    }

    /// Creates a CSMat with its value (a source: it needs no writer module). If a module
    /// already declared it as an output, the shapes must agree and `value` becomes its
    /// initial value.
    pub fn create_mat(&self, value: CsMat) -> Result<Mat, RuntimeError> {
        let name = value.name().to_owned();
        check_name(ObjectKind::Mat, &name)?;
        let mut db = self.db();
        let mat = db.mat(&name);
        let entry = db.mats.get_mut(&name).expect("just inserted");
        if entry.by_application {
            return Err(RuntimeError::Duplicate {
                kind: ObjectKind::Mat,
                name,
            });
        }
        if mat.is_bound() && mat.shape() != value.shape() {
            let (rows, cols) = mat.shape();
            return Err(RuntimeError::ShapeConflict {
                name,
                rows,
                cols,
                new_rows: value.rows(),
                new_cols: value.cols(),
            });
        }
        entry.by_application = true;
        mat.bind(value);
        db.propagate_shapes();
        Ok(mat)
    }

    /// The habitat named `name`: the existing one, or a placeholder bound when it is created.
    pub fn habitat(&self, name: &str) -> Habitat {
        let mut db = self.db();
        self.habitat_in(&mut db, name)
    }

    pub(crate) fn habitat_in(&self, db: &mut Database, name: &str) -> Habitat {
        db.habitats
            .entry(name.to_owned())
            .or_insert_with(|| Habitat::placeholder(name, Arc::downgrade(&self.inner)))
            .clone()
    }

    /// Creates a habitat.
    pub fn create_habitat(
        &self,
        name: &str,
        options: HabitatOptions,
    ) -> Result<Habitat, RuntimeError> {
        check_name(ObjectKind::Habitat, name)?;
        if !period_is_usable(options.period) {
            return Err(HabitatError::InvalidRate {
                habitat: name.to_owned(),
                hz: 1.0 / options.period.as_secs_f64(),
            }
            .into());
        }
        if !stats_interval_is_usable(options.stats_interval) {
            return Err(HabitatError::InvalidStatsInterval {
                habitat: name.to_owned(),
                interval: options.stats_interval,
            }
            .into());
        }
        let mut db = self.db();
        let habitat = self.habitat_in(&mut db, name);
        if habitat.is_created() {
            return Err(RuntimeError::Duplicate {
                kind: ObjectKind::Habitat,
                name: name.to_owned(),
            });
        }
        habitat.create(options);
        Ok(habitat)
    }

    /// The habitat named `name` if it was created (a lookup that never makes a placeholder).
    pub fn find_habitat(&self, name: &str) -> Option<Habitat> {
        self.db()
            .habitats
            .get(name)
            .filter(|h| h.is_created())
            .cloned()
    }

    /// Every habitat (created or referenced), by name.
    pub fn habitats(&self) -> Vec<Habitat> {
        self.db().habitats.values().cloned().collect()
    }

    /// Builds a module with `build` and installs it in `habitat` (created or not yet). The
    /// module's CSMats are declared through the [`Binder`]; `build` must not call back into
    /// the runtime. The module is active unless it belongs to a group that is not.
    pub fn install<M, F>(&self, habitat: &str, module: &str, build: F) -> Result<(), RuntimeError>
    where
        M: SampleModule,
        F: FnOnce(&mut Binder<'_>) -> Result<M, ModuleError>,
    {
        let mut reception = None;
        self.install_boxed(habitat, module, |b| {
            build(b).map(|m| {
                // A subscription tells the status what it receives.
                let any: &dyn std::any::Any = &m;
                reception = any.downcast_ref::<Subscriber>().map(Subscriber::reception);
                Box::new(m) as Box<dyn SampleModule>
            })
        })?;
        if let Some(reception) = reception {
            lock(&self.inner.inputs).insert(module.to_owned(), (habitat.to_owned(), reception));
        }
        Ok(())
    }

    /// Installs an instance of a registered component type.
    pub fn install_component(
        &self,
        habitat: &str,
        module: &str,
        type_name: &str,
        params: &Params,
    ) -> Result<(), RuntimeError> {
        let factory = {
            let registry = lock(&self.inner.registry);
            match registry.get(type_name) {
                Some(factory) => factory.clone(),
                None => {
                    return Err(RuntimeError::UnknownType {
                        name: type_name.to_owned(),
                        known: registry
                            .types()
                            .map(|(n, _)| n)
                            .collect::<Vec<_>>()
                            .join(", "),
                    });
                }
            }
        };
        self.install_boxed(habitat, module, |b| factory(b, params))
    }

    fn install_boxed(
        &self,
        habitat: &str,
        module: &str,
        build: impl FnOnce(&mut Binder<'_>) -> Result<Box<dyn SampleModule>, ModuleError>,
    ) -> Result<(), RuntimeError> {
        refuse_inside_routine("install")?;
        check_name(ObjectKind::Module, module)?;
        check_name(ObjectKind::Habitat, habitat)?;
        let _structure = self.inner.structure();
        let (target, built, active, undo) = self.build_module(habitat, module, build)?;
        // The database knows the module now; the list gets it without the database lock.
        let installed = self.insert_into_list(&target, module, built, active);
        if let Err(source) = installed {
            let mut db = self.db();
            db.modules.remove(module);
            undo.apply(&mut db);
            return Err(RuntimeError::Sort {
                habitat: habitat.to_owned(),
                source,
            });
        }
        self.assign_owners();
        Ok(())
    }

    /// Gives each habitat the CSMats that only its modules name, for them to reach without a
    /// lock (the mat module's doc). Called after every install and removal, under the
    /// structure lock; the lists take the change over without waiting (now or at a boundary).
    fn assign_owners(&self) {
        let plan: Vec<(Habitat, Vec<Mat>)> = {
            let mut db = self.db();
            // CSMat name -> (the one habitat naming it, or None once two do; the handle).
            let mut users: BTreeMap<&str, (Option<&str>, &Mat)> = BTreeMap::new();
            for entry in db.modules.values() {
                let ports = entry.interface.inputs.iter().map(|(port, _)| port);
                for port in ports.chain(&entry.interface.outputs) {
                    let user = users
                        .entry(port.mat.name())
                        .or_insert((Some(&entry.habitat), &port.mat));
                    if user.0 != Some(entry.habitat.as_str()) {
                        user.0 = None;
                    }
                }
            }
            let mut per_habitat: BTreeMap<String, Vec<Mat>> = db
                .habitats
                .keys()
                .map(|name| (name.clone(), Vec::new()))
                .collect();
            for (habitat, mat) in users.into_values() {
                if let Some(habitat) = habitat
                    && mat.is_bound()
                {
                    per_habitat
                        .entry(habitat.to_owned())
                        .or_default()
                        .push(mat.clone());
                }
            }
            per_habitat
                .into_iter()
                .map(|(name, mats)| (self.habitat_in(&mut db, &name), mats))
                .collect()
        };
        for (habitat, mats) in plan {
            lock(&habitat.shared.list).owned.want(mats);
        }
    }

    /// Builds `module` against the database and records it there (active or not).
    fn build_module(
        &self,
        habitat: &str,
        module: &str,
        build: impl FnOnce(&mut Binder<'_>) -> Result<Box<dyn SampleModule>, ModuleError>,
    ) -> Result<(Habitat, Slot, bool, Undo), RuntimeError> {
        let mut db = self.db();
        if db.modules.contains_key(module) {
            return Err(RuntimeError::Duplicate {
                kind: ObjectKind::Module,
                name: module.to_owned(),
            });
        }
        let target = self.habitat_in(&mut db, habitat);
        let mut undo = Undo {
            created: Vec::new(),
            new_names: Vec::new(),
            follows_before: db.follows.len(),
        };
        let built = {
            let db_ref: &mut Database = &mut db;
            let new_names = &mut undo.new_names;
            let mut lookup = |name: &str| {
                if !db_ref.mats.contains_key(name) {
                    new_names.push(name.to_owned());
                }
                db_ref.mat(name)
            };
            let mut binder = Binder::detached(module, &mut lookup);
            binder.habitat = Some(target.downgrade());
            let result = super::list::as_routine(|| build(&mut binder));
            let Binder {
                interface,
                follows,
                created,
                ..
            } = binder;
            undo.created = created;
            result.map(|built| (interface, built, follows))
        };
        let (interface, built) = match built {
            Ok((interface, built, follows)) => {
                db.follows.extend(follows);
                (interface, built)
            }
            Err(source) => {
                undo.apply(&mut db);
                return Err(RuntimeError::Build {
                    module: module.to_owned(),
                    source,
                });
            }
        };
        let active = db.is_active_with(module, &db.active_groups());
        if active && let Some((mat, other)) = Self::writer_elsewhere(&db, habitat, &interface) {
            undo.apply(&mut db);
            return Err(RuntimeError::DoubleWriter {
                mat,
                first: other,
                second: module.to_owned(),
            });
        }
        db.propagate_shapes();
        db.modules.insert(
            module.to_owned(),
            ModuleEntry {
                habitat: habitat.to_owned(),
                interface: interface.clone(),
                active,
            },
        );
        let slot = Slot::new(module.to_owned(), interface, built);
        Ok((target, slot, active, undo))
    }

    /// Puts a built module into its habitat's list: the new order is sorted without the
    /// list's lock, and a sampling habitat's new module gets `startup` (and `enable` if
    /// active) on this thread before it joins, so the habitat never waits for them.
    fn insert_into_list(
        &self,
        target: &Habitat,
        module: &str,
        mut slot: Slot,
        active: bool,
    ) -> Result<(), crate::SortError> {
        let (mut layout, sampling, ctx) = {
            let list = lock(&target.shared.list);
            (list.layout(), list.sampling, list.ctx)
        };
        let n = layout.names().count();
        layout.push(module, slot.interface.clone());
        let order = match layout.plan(|i, _| if i == n { active } else { layout.is_active(i) }) {
            Ok(order) => order,
            Err(err) => {
                // Refused: the module was built, so it is unloaded.
                crate::list::terminate(slot.module_mut());
                return Err(err);
            }
        };
        let mut failures = Vec::new();
        if sampling {
            let routines: &[Routine] = if active {
                &[Routine::Startup, Routine::Enable]
            } else {
                &[Routine::Startup]
            };
            for &routine in routines {
                if let Err(err) = run_routine(slot.module_mut(), routine, &ctx) {
                    failures.push((routine, err));
                }
            }
        }
        lock(&target.shared.list).install(slot, active, order, failures);
        Ok(())
    }

    /// An active module of another habitat writing one of `interface`'s outputs (a writer in
    /// the same habitat is the sort's to refuse).
    fn writer_elsewhere(
        db: &Database,
        habitat: &str,
        interface: &Interface,
    ) -> Option<(String, String)> {
        let active = db.active_groups();
        interface.output_names().find_map(|mat| {
            db.modules
                .iter()
                .filter(|(_, m)| m.habitat != habitat)
                .find(|(name, m)| {
                    m.interface.output_names().any(|o| o == mat) && db.is_active_with(name, &active)
                })
                .map(|(name, _)| (mat.to_owned(), name.clone()))
        })
    }

    /// Unloads a module: `disable` and `shutdown` if its habitat samples, then `terminate`
    /// (on this thread, after the module has left the list).
    pub fn remove(&self, module: &str) -> Result<(), RuntimeError> {
        refuse_inside_routine("remove")?;
        let _structure = self.inner.structure();
        let habitat = {
            let mut db = self.db();
            let entry = db
                .modules
                .remove(module)
                .ok_or_else(|| RuntimeError::Unknown {
                    kind: ObjectKind::Module,
                    name: module.to_owned(),
                })?;
            lock(&self.inner.inputs).remove(module);
            self.habitat_in(&mut db, &entry.habitat)
        };
        let (taken, sampling, ctx) = {
            let mut list = lock(&habitat.shared.list);
            let taken = list.position(module).and_then(|index| list.take(index));
            (taken, list.sampling, list.ctx)
        };
        if let Some((slot, mut built)) = taken {
            if sampling {
                if slot.active {
                    let _ = run_routine(built.as_mut(), Routine::Disable, &ctx);
                }
                let _ = run_routine(built.as_mut(), Routine::Shutdown, &ctx);
            }
            crate::list::terminate(built.as_mut());
        }
        self.assign_owners();
        Ok(())
    }

    /// Names of the installed modules.
    pub fn modules(&self) -> Vec<String> {
        self.db().modules.keys().cloned().collect()
    }

    /// Checks the whole system: unbound references, shape mismatches, missing producers,
    /// double writers and algebraic loops, for the active set and for every configuration.
    /// Habitats refuse to start until it passes.
    pub fn verify(&self) -> VerifyReport {
        self.inner.verify()
    }

    // ----- habitats -----

    /// Starts every created habitat that is not sampling (verifying once, first).
    pub fn start_all(&self) -> Result<(), RuntimeError> {
        let report = self.verify();
        if !report.is_ok() {
            return Err(HabitatError::Verify {
                habitat: "*".into(),
                report,
            }
            .into());
        }
        for habitat in self.habitats() {
            if habitat.is_created() && !habitat.is_running() {
                habitat.start()?;
            }
        }
        Ok(())
    }

    /// Stops every habitat.
    pub fn stop_all(&self) {
        for habitat in self.habitats() {
            habitat.stop();
        }
    }

    /// Every subscribed CSMat: what it received and when, in its habitat's time (read from
    /// atomics the habitat writes: no lock a habitat holds is taken).
    pub fn inputs(&self) -> Vec<InputStatus> {
        lock(&self.inner.inputs)
            .values()
            .map(|(habitat, reception)| reception.status(habitat))
            .collect()
    }

    /// A habitat's statistics with the runtime's name and configuration filled in.
    pub fn habitat_stats(&self, habitat: &Habitat) -> HabitatStats {
        let mut stats = habitat.stats();
        stats.runtime = self.inner.name.clone();
        stats.configuration = self.current_configuration().unwrap_or_default();
        stats
    }
}

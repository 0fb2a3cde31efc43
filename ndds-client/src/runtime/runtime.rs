//! [`Runtime`]: one process's ControlShell system — its linking database, habitats, component
//! registry, configuration manager and network bindings.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use super::binding::{Publisher, RateIn, RateOut, Subscriber};
use super::components;
use super::csmat::CsMat;
use super::database::{CategoryEntry, Database, GroupEntry, ModuleEntry, ObjectKind};
use super::habitat::{
    Habitat, HabitatError, HabitatOptions, period_is_usable, stats_interval_is_usable,
};
use super::list::{ExecList, Slot};
use super::mat::Mat;
use super::module::{Binder, Interface, ModuleError, SampleModule};
use super::registry::{Params, Registry};
use super::sort::SortError;
use super::stats::HabitatStats;
use super::verify::{VerifyReport, verify};
use crate::error::DeclareError;
use crate::{CallbackConsumer, ConsumerQos, Participant, Producer, ProducerQos, Reliability};

/// What can go wrong building or changing a system.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RuntimeError {
    /// A second object of one kind with one name.
    #[error("{kind} `{name}` already exists")]
    Duplicate {
        /// Its kind.
        kind: ObjectKind,
        /// Its name.
        name: String,
    },
    /// An object that must exist does not.
    #[error("unknown {kind} `{name}`")]
    Unknown {
        /// Its kind.
        kind: ObjectKind,
        /// Its name.
        name: String,
    },
    /// An empty name, or one with a `/` where topic names are derived from it.
    #[error("bad {kind} name `{name}`: {why}")]
    BadName {
        /// Its kind.
        kind: ObjectKind,
        /// The name.
        name: String,
        /// What is wrong with it.
        why: &'static str,
    },
    /// No component type of that name is registered.
    #[error("unknown component type `{name}` (registered: {known})")]
    UnknownType {
        /// The name asked for.
        name: String,
        /// The registered ones.
        known: String,
    },
    /// The module's constructor failed.
    #[error("module `{module}` could not be built: {source}")]
    Build {
        /// The module.
        module: String,
        /// Why.
        source: ModuleError,
    },
    /// Adding the module (or switching) would leave a habitat's active set unsortable.
    #[error("habitat `{habitat}`: {source}")]
    Sort {
        /// The habitat.
        habitat: String,
        /// The double writer or algebraic loop.
        source: SortError,
    },
    /// Two active modules in different habitats would write one CSMat.
    #[error("CSMat `{mat}` would be written by `{first}` and `{second}`")]
    DoubleWriter {
        /// The CSMat.
        mat: String,
        /// One writer.
        first: String,
        /// The other.
        second: String,
    },
    /// A CSMat created with another shape than it already has.
    #[error("CSMat `{name}` is already {rows}x{cols}; cannot create it as {new_rows}x{new_cols}")]
    ShapeConflict {
        /// The CSMat.
        name: String,
        /// Its rows.
        rows: usize,
        /// Its columns.
        cols: usize,
        /// Rows asked for.
        new_rows: usize,
        /// Columns asked for.
        new_cols: usize,
    },
    /// A group used with a category it does not belong to.
    #[error("module group `{group}` belongs to category `{actual}`, not `{category}`")]
    WrongCategory {
        /// The group.
        group: String,
        /// The category named.
        category: String,
        /// Its category.
        actual: String,
    },
    /// Network bindings and services need a participant.
    #[error("runtime `{0}` has no participant: create it with Runtime::with_participant")]
    NoParticipant(String),
    /// A producer or consumer could not be declared.
    #[error("declaring topic `{topic}`: {source}")]
    Declare {
        /// The topic.
        topic: String,
        /// Why.
        source: DeclareError,
    },
    /// A habitat operation failed.
    #[error(transparent)]
    Habitat(#[from] HabitatError),
}

pub(crate) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The runtime's shared state.
pub(crate) struct Inner {
    pub(crate) name: String,
    db: Mutex<Database>,
    pub(crate) participant: Option<Participant>,
    registry: Mutex<Registry>,
    services: Mutex<Option<Services>>,
}

struct Services {
    stop: Arc<AtomicBool>,
    stats: Option<JoinHandle<()>>,
    _commands: CallbackConsumer,
}

impl Inner {
    pub(crate) fn verify(&self) -> VerifyReport {
        verify(&lock(&self.db))
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        if let Some(mut services) = lock(&self.services).take() {
            services.stop.store(true, Ordering::Release);
            // The last handle may be the one the statistics thread holds for a moment.
            if let Some(thread) = services.stats.take()
                && thread.thread().id() != std::thread::current().id()
            {
                let _ = thread.join();
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
/// use ndds_client::runtime::{components::Gain, CsMat, HabitatOptions, Clock, Runtime};
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
    inner: Arc<Inner>,
}

impl std::fmt::Debug for Runtime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Runtime")
            .field("name", &self.inner.name)
            .finish_non_exhaustive()
    }
}

fn check_name(kind: ObjectKind, name: &str) -> Result<(), RuntimeError> {
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
    /// [`with_participant`](Self::with_participant)). Its registry holds the built-in
    /// components (see [`components`]).
    pub fn new(name: &str) -> Self {
        Self::build(name, None)
    }

    fn build(name: &str, participant: Option<Participant>) -> Self {
        let mut registry = Registry::empty();
        components::register_builtin(&mut registry);
        Self {
            inner: Arc::new(Inner {
                name: name.to_owned(),
                db: Mutex::new(Database::default()),
                participant,
                registry: Mutex::new(registry),
                services: Mutex::new(None),
            }),
        }
    }

    /// A runtime on the network: CSMats can be bound to topics, each habitat's statistics are
    /// published on `cs/<runtime>/<habitat>/stats` once per statistics interval, and a string
    /// sample on `cs/<runtime>/configure` switches to the configuration it names.
    pub fn with_participant(name: &str, participant: &Participant) -> Result<Self, RuntimeError> {
        check_name(ObjectKind::Habitat, name).map_err(|_| RuntimeError::BadName {
            kind: ObjectKind::Habitat,
            name: name.to_owned(),
            why: "a runtime name must be non-empty, without `/` or control characters",
        })?;
        let rt = Self::build(name, Some(participant.clone()));
        rt.start_services(participant)?;
        Ok(rt)
    }

    fn start_services(&self, participant: &Participant) -> Result<(), RuntimeError> {
        let topic = format!("cs/{}/configure", self.inner.name);
        let qos = ConsumerQos {
            reliability: Reliability::Reliable { depth: 64 },
            depth: 64,
            ..ConsumerQos::default()
        };
        let consumer = participant
            .consumer::<String>(&topic, qos)
            .map_err(|source| RuntimeError::Declare {
                topic: topic.clone(),
                source,
            })?;
        let weak = Arc::downgrade(&self.inner);
        let commands = consumer
            .on_sample(move |sample| {
                if let Some(inner) = weak.upgrade() {
                    let rt = Runtime { inner };
                    match rt.switch(sample.value.trim()) {
                        Ok(()) => tracing::info!(runtime = %rt.name(), configuration = %sample.value, "configuration switched from the network"),
                        Err(err) => tracing::warn!(runtime = %rt.name(), error = %err, "configuration command refused"),
                    }
                }
            })
            .map_err(|err| RuntimeError::Build {
                module: topic,
                source: ModuleError::Failed(err.to_string()),
            })?;
        let stop = Arc::new(AtomicBool::new(false));
        let weak = Arc::downgrade(&self.inner);
        let stop_flag = Arc::clone(&stop);
        let stats = std::thread::Builder::new()
            .name(format!("cs-{}-stats", self.inner.name))
            .spawn(move || publish_stats(&weak, &stop_flag))
            .ok();
        *lock(&self.inner.services) = Some(Services {
            stop,
            stats,
            _commands: commands,
        });
        Ok(())
    }

    /// Its name.
    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// Its participant, if it has one.
    pub fn participant(&self) -> Option<&Participant> {
        self.inner.participant.as_ref()
    }

    fn db(&self) -> MutexGuard<'_, Database> {
        lock(&self.inner.db)
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

    fn habitat_in(&self, db: &mut Database, name: &str) -> Habitat {
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
        self.install_boxed(habitat, module, |b| {
            build(b).map(|m| Box::new(m) as Box<dyn SampleModule>)
        })
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
        check_name(ObjectKind::Module, module)?;
        check_name(ObjectKind::Habitat, habitat)?;
        let mut db = self.db();
        if db.modules.contains_key(module) {
            return Err(RuntimeError::Duplicate {
                kind: ObjectKind::Module,
                name: module.to_owned(),
            });
        }
        let target = self.habitat_in(&mut db, habitat);
        let follows_before = db.follows.len();
        let mut new_names: Vec<String> = Vec::new();
        let created: Vec<Mat>;
        let built = {
            let db_ref: &mut Database = &mut db;
            let new_names = &mut new_names;
            let mut lookup = |name: &str| {
                if !db_ref.mats.contains_key(name) {
                    new_names.push(name.to_owned());
                }
                db_ref.mat(name)
            };
            let mut binder = Binder {
                lookup: &mut lookup,
                module: module.to_owned(),
                interface: Interface::default(),
                follows: Vec::new(),
                created: Vec::new(),
            };
            let result = build(&mut binder);
            let Binder {
                interface,
                follows,
                created: made,
                ..
            } = binder;
            created = made;
            result.map(|built| (interface, built, follows))
        };
        let (interface, built) = match built {
            Ok((interface, built, follows)) => {
                db.follows.extend(follows);
                (interface, built)
            }
            Err(source) => {
                Self::undo(&mut db, &created, &new_names, follows_before);
                return Err(RuntimeError::Build {
                    module: module.to_owned(),
                    source,
                });
            }
        };
        let active = db.is_active_with(module, &db.active_groups());
        if active && let Some((mat, other)) = Self::writer_elsewhere(&db, habitat, &interface) {
            Self::undo(&mut db, &created, &new_names, follows_before);
            return Err(RuntimeError::DoubleWriter {
                mat,
                first: other,
                second: module.to_owned(),
            });
        }
        let slot = Slot::new(module.to_owned(), interface.clone(), built);
        let installed = lock(&target.shared.list).install(slot, active);
        if let Err(source) = installed {
            Self::undo(&mut db, &created, &new_names, follows_before);
            return Err(RuntimeError::Sort {
                habitat: habitat.to_owned(),
                source,
            });
        }
        db.propagate_shapes();
        db.modules.insert(
            module.to_owned(),
            ModuleEntry {
                habitat: habitat.to_owned(),
                interface,
                active,
            },
        );
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

    /// Undoes what a failed install created: the CSMats its declarations bound, the
    /// placeholders it added, its shape-following entries.
    fn undo(db: &mut Database, created: &[Mat], new_names: &[String], follows_before: usize) {
        for mat in created {
            mat.unbind();
        }
        for name in new_names {
            db.mats.remove(name);
        }
        db.follows.truncate(follows_before);
    }

    /// Unloads a module: `disable` and `shutdown` if its habitat samples, then `terminate`.
    pub fn remove(&self, module: &str) -> Result<(), RuntimeError> {
        let mut db = self.db();
        let entry = db
            .modules
            .remove(module)
            .ok_or_else(|| RuntimeError::Unknown {
                kind: ObjectKind::Module,
                name: module.to_owned(),
            })?;
        let habitat = self.habitat_in(&mut db, &entry.habitat);
        let mut list = lock(&habitat.shared.list);
        if let Some(index) = list.position(module) {
            list.remove(index);
        }
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

    // ----- configuration manager -----

    /// Creates module group `group` in `category` with `modules` (which may be installed
    /// later). The first group of a category becomes its active group.
    pub fn group(&self, category: &str, group: &str, modules: &[&str]) -> Result<(), RuntimeError> {
        check_name(ObjectKind::Category, category)?;
        check_name(ObjectKind::Group, group)?;
        let mut db = self.db();
        if db.groups.contains_key(group) {
            return Err(RuntimeError::Duplicate {
                kind: ObjectKind::Group,
                name: group.to_owned(),
            });
        }
        let before = db.active_groups();
        db.groups.insert(
            group.to_owned(),
            GroupEntry {
                category: category.to_owned(),
                modules: modules.iter().map(|m| (*m).to_owned()).collect(),
            },
        );
        let entry = db.categories.entry(category.to_owned()).or_default();
        entry.groups.push(group.to_owned());
        if entry.active.is_none() {
            entry.active = Some(group.to_owned());
        }
        let after = db.active_groups();
        if let Err(err) = self.apply(&mut db, &after) {
            db.groups.remove(group);
            let entry = db.categories.entry(category.to_owned()).or_default();
            entry.groups.retain(|g| g != group);
            entry.active = before.get(category).cloned().flatten();
            if entry.groups.is_empty() {
                db.categories.remove(category);
            }
            return Err(err);
        }
        Ok(())
    }

    /// Names configuration `name`: which group is active in each category it lists (groups
    /// may be created later; categories it does not list keep their active group).
    pub fn configuration(
        &self,
        name: &str,
        selections: &[(&str, &str)],
    ) -> Result<(), RuntimeError> {
        check_name(ObjectKind::Configuration, name)?;
        let mut db = self.db();
        if db.configurations.contains_key(name) {
            return Err(RuntimeError::Duplicate {
                kind: ObjectKind::Configuration,
                name: name.to_owned(),
            });
        }
        let mut map = BTreeMap::new();
        for (category, group) in selections {
            if map
                .insert((*category).to_owned(), (*group).to_owned())
                .is_some()
            {
                return Err(RuntimeError::Duplicate {
                    kind: ObjectKind::Category,
                    name: format!("{category} (listed twice in configuration `{name}`)"),
                });
            }
        }
        db.configurations.insert(name.to_owned(), map);
        Ok(())
    }

    /// Switches to configuration `name`, atomically at each habitat's next sample boundary:
    /// the leaving modules' `disable`, then the entering modules' `enable` (which can still
    /// read the leaving modules' outputs), then the lists are re-sorted. If the new active
    /// set cannot be sorted nothing changes.
    pub fn switch(&self, name: &str) -> Result<(), RuntimeError> {
        let mut db = self.db();
        let selections =
            db.configurations
                .get(name)
                .cloned()
                .ok_or_else(|| RuntimeError::Unknown {
                    kind: ObjectKind::Configuration,
                    name: name.to_owned(),
                })?;
        let mut active = db.active_groups();
        for (category, group) in &selections {
            Self::check_group(&db, category, group)?;
            active.insert(category.clone(), Some(group.clone()));
        }
        self.apply(&mut db, &active)?;
        db.current = Some(name.to_owned());
        Ok(())
    }

    /// Makes `group` the active group of `category` (the configuration becomes unnamed).
    pub fn activate_group(&self, category: &str, group: &str) -> Result<(), RuntimeError> {
        let mut db = self.db();
        Self::check_group(&db, category, group)?;
        let mut active = db.active_groups();
        active.insert(category.to_owned(), Some(group.to_owned()));
        self.apply(&mut db, &active)?;
        db.current = None;
        Ok(())
    }

    fn check_group(db: &Database, category: &str, group: &str) -> Result<(), RuntimeError> {
        match db.groups.get(group) {
            None => Err(RuntimeError::Unknown {
                kind: ObjectKind::Group,
                name: group.to_owned(),
            }),
            Some(entry) if entry.category != category => Err(RuntimeError::WrongCategory {
                group: group.to_owned(),
                category: category.to_owned(),
                actual: entry.category.clone(),
            }),
            Some(_) => Ok(()),
        }
    }

    /// The configuration last switched to, if the active groups still are its.
    pub fn current_configuration(&self) -> Option<String> {
        self.db().current.clone()
    }

    /// Each category's active group.
    pub fn active_groups(&self) -> BTreeMap<String, String> {
        self.db()
            .categories
            .iter()
            .filter_map(|(c, e)| e.active.clone().map(|g| (c.clone(), g)))
            .collect()
    }

    /// Applies a new set of active groups to every habitat, all or nothing.
    fn apply(
        &self,
        db: &mut Database,
        active: &BTreeMap<String, Option<String>>,
    ) -> Result<(), RuntimeError> {
        // Writers in different habitats, from the database (no lock needed); writers in one
        // habitat are the sort's to refuse, with its own error.
        let mut writers: BTreeMap<&str, (&str, &str)> = BTreeMap::new();
        for (name, entry) in &db.modules {
            if !db.is_active_with(name, active) {
                continue;
            }
            for mat in entry.interface.output_names() {
                match writers.get(mat) {
                    Some((first, habitat)) if *habitat != entry.habitat => {
                        return Err(RuntimeError::DoubleWriter {
                            mat: mat.to_owned(),
                            first: (*first).to_owned(),
                            second: name.clone(),
                        });
                    }
                    Some(_) => {}
                    None => {
                        writers.insert(mat, (name, &entry.habitat));
                    }
                }
            }
        }
        // Only the habitats whose active set changes are locked (each at its next sample
        // boundary, all together, in name order), so a switch never waits on the others.
        let affected: Vec<Habitat> = db
            .habitats
            .values()
            .filter(|h| {
                db.modules.iter().any(|(name, m)| {
                    m.habitat == h.name() && m.active != db.is_active_with(name, active)
                })
            })
            .cloned()
            .collect();
        let mut lists: Vec<MutexGuard<'_, ExecList>> =
            affected.iter().map(|h| lock(&h.shared.list)).collect();
        let mut plans = Vec::with_capacity(lists.len());
        for (habitat, list) in affected.iter().zip(&lists) {
            let next: Vec<bool> = list
                .slots
                .iter()
                .map(|slot| db.is_active_with(&slot.name, active))
                .collect();
            let order = list
                .plan(|i| next[i])
                .map_err(|source| RuntimeError::Sort {
                    habitat: habitat.name().to_owned(),
                    source,
                })?;
            plans.push((next, order));
        }
        drop(writers);
        for (list, (next, _)) in lists.iter_mut().zip(&plans) {
            list.leave(next);
        }
        for (list, (next, order)) in lists.iter_mut().zip(plans) {
            list.enter(&next, order);
        }
        drop(lists);
        let flags: Vec<(String, bool)> = db
            .modules
            .keys()
            .map(|name| (name.clone(), db.is_active_with(name, active)))
            .collect();
        for (name, on) in flags {
            if let Some(entry) = db.modules.get_mut(&name) {
                entry.active = on;
            }
        }
        for (category, group) in active {
            if let Some(entry) = db.categories.get_mut(category) {
                entry.active = group.clone();
            } else if let Some(group) = group {
                db.categories.insert(
                    category.clone(),
                    CategoryEntry {
                        groups: vec![group.clone()],
                        active: Some(group.clone()),
                    },
                );
            }
        }
        Ok(())
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

    /// A habitat's statistics with the runtime's name and configuration filled in.
    pub fn habitat_stats(&self, habitat: &Habitat) -> HabitatStats {
        let mut stats = habitat.stats();
        stats.runtime = self.inner.name.clone();
        stats.configuration = self.current_configuration().unwrap_or_default();
        stats
    }

    // ----- network bindings -----

    fn participant_or_err(&self) -> Result<&Participant, RuntimeError> {
        self.inner
            .participant
            .as_ref()
            .ok_or_else(|| RuntimeError::NoParticipant(self.inner.name.clone()))
    }

    /// Publishes CSMat `mat` on `topic` every sample: a module `publish:<topic>` in
    /// `habitat`, ordered after the CSMat's writer. A reliable producer here never blocks the
    /// habitat: its `when_full` is made [`WhenFull::DropOldest`](crate::WhenFull), so a slow
    /// consumer loses old samples (and is told so) instead of stalling the loop.
    pub fn publish(
        &self,
        habitat: &str,
        mat: &str,
        topic: &str,
        qos: ProducerQos,
    ) -> Result<(), RuntimeError> {
        let producer: Producer<CsMat> =
            self.participant_or_err()?
                .producer(topic, qos)
                .map_err(|source| RuntimeError::Declare {
                    topic: topic.to_owned(),
                    source,
                })?;
        self.install(habitat, &format!("publish:{topic}"), |b| {
            Ok(Publisher::new(b, mat, producer))
        })
    }

    /// Writes the newest sample received on `topic` into CSMat `mat` (created with `shape`
    /// if it does not exist) at the start of each sample: a module `subscribe:<topic>` in
    /// `habitat`, which is the CSMat's writer.
    pub fn subscribe(
        &self,
        habitat: &str,
        mat: &str,
        shape: impl Into<super::module::Shape>,
        topic: &str,
        qos: ConsumerQos,
    ) -> Result<(), RuntimeError> {
        let shape = shape.into();
        let consumer = self
            .participant_or_err()?
            .raw_consumer(topic, crate::TypeDescription::of::<CsMat>(), qos)
            .map_err(|source| RuntimeError::Declare {
                topic: topic.to_owned(),
                source,
            })?;
        self.install(habitat, &format!("subscribe:{topic}"), |b| {
            Ok(Subscriber::new(b, mat, shape, consumer))
        })
    }

    /// Passes CSMat `from.1` (written in habitat `from.0`) to CSMat `to.1` read in habitat
    /// `to.0`, whatever their rates: module `<name>.in` copies it into a buffer each sample of
    /// the source habitat, module `<name>.out` copies the newest complete value out at the
    /// start of each sample of the destination. Neither ever sees a half-written matrix.
    pub fn rate_transition(
        &self,
        name: &str,
        from: (&str, &str),
        to: (&str, &str),
    ) -> Result<(), RuntimeError> {
        let source = self.db().mat(from.1);
        let buffer = Arc::new(Mutex::new(None));
        let shared = Arc::clone(&buffer);
        self.install(from.0, &format!("{name}.in"), |b| {
            Ok(RateIn::new(b, from.1, shared))
        })?;
        let result = self.install(to.0, &format!("{name}.out"), |b| {
            Ok(RateOut::new(b, to.1, &source, buffer))
        });
        if result.is_err() {
            let _ = self.remove(&format!("{name}.in"));
        }
        result
    }
}

/// The statistics service: every habitat's stats on `cs/<runtime>/<habitat>/stats`.
fn publish_stats(weak: &std::sync::Weak<Inner>, stop: &AtomicBool) {
    let mut producers: BTreeMap<String, Producer<HabitatStats>> = BTreeMap::new();
    let tick = Duration::from_millis(100);
    let mut next: BTreeMap<String, std::time::Instant> = BTreeMap::new();
    while !stop.load(Ordering::Acquire) {
        std::thread::sleep(tick);
        let Some(inner) = weak.upgrade() else { return };
        let rt = Runtime { inner };
        let Some(participant) = rt.inner.participant.clone() else {
            return;
        };
        for habitat in rt.habitats() {
            if !habitat.is_created() {
                continue;
            }
            let now = std::time::Instant::now();
            let interval = habitat.stats_interval();
            let due = next.entry(habitat.name().to_owned()).or_insert(now);
            if now < *due {
                continue;
            }
            *due = now
                .checked_add(interval)
                .unwrap_or(now + Duration::from_secs(3600));
            let name = habitat.name().to_owned();
            if !producers.contains_key(&name) {
                let topic = format!("cs/{}/{}/stats", rt.inner.name, name);
                match participant.producer::<HabitatStats>(&topic, ProducerQos::default()) {
                    Ok(p) => {
                        producers.insert(name.clone(), p);
                    }
                    Err(err) => {
                        tracing::warn!(topic, error = %err, "cannot publish habitat statistics");
                        continue;
                    }
                }
            }
            let stats = rt.habitat_stats(&habitat);
            if let Some(producer) = producers.get(&name)
                && let Err(err) = producer.write(&stats)
            {
                tracing::debug!(habitat = %name, error = %err, "habitat statistics not sent");
            }
        }
    }
}

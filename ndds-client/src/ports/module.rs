//! Modules (Shin, 1985, section 5): a module declares its tasks, the ports it owns and uses
//! with their restrictions, its response and exception handlers, its named subprograms and
//! its `order`; [`ModuleBuilder::load`] checks all of it before anything runs and reports
//! every problem at once ([`LoadError`]); [`Module::start`] runs it.
//!
//! **How a module runs.** Its background code (the *body*) and its handlers run on one thread,
//! the module's (`module-<NAME>`), so that they never run at once: a handler runs only at a
//! *preemption point* of the body, and only when the module's [`Order`] lets it — it outranks
//! the innermost section running (see [`ndds_core::ports::order`]). The points are:
//! - the entry and exit of a named section ([`ModuleContext::section`]: a subprogram such as
//!   GRASP or INSERT);
//! - every wait in a port primitive called through the [`ModuleContext`] (`send`, `query`,
//!   `receive`, and [`ModuleContext::delay`]) — the section that waits still counts as
//!   running: a handler that does not outrank it waits too;
//! - [`ModuleContext::point`], wherever the body calls it.
//!
//! After the body returns, the module thread serves its handlers until the module stops.
//!
//! **Handlers.** A *response handler* `PORT.NAME` answers queries: from the port's users on a
//! port the module owns (usage `Response`), or from the port's owner on a port the module
//! uses (usage `Response`: LOAD_CARD answering LOAD_IT's `ASK_CHILD1.STATUS`). One listener
//! thread per such port takes each query off the network and posts it; the module thread runs
//! the handler at a point and the listener sends the answer. An *exception handler*
//! `PORT.TIMEOUT` runs when an operation on the port through the module context times out:
//! the operation returns the timeout to the body, and the handler runs at the next point the
//! order allows (at once, if it outranks what runs). Rust code is never interrupted anywhere
//! else.
//!
//! **Tasks** declared with the module start with it on threads of their own (`task-<NAME>`);
//! they are other tasks, not sections of the module, and the order does not rank them.

use std::any::Any;
use std::collections::{HashMap, VecDeque};
use std::pin::pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use ndds_core::ports::schedule::Call;
use ndds_core::ports::{
    LoadError, LoadProblem, ModuleSpec, Order, Performed, PortDecl, Sections, WorkSchedule,
};
use serde::Serialize;
use serde::de::DeserializeOwned;

use super::description::{FileEnd, FilePort};
use super::wait::{self, Either, Notify};
use super::{ModuleInfo, PortError, PortOwner, PortUser, ReplyHandle, Restrictions, Usage};
use crate::{Participant, TypeDescription};

/// What a module failed with.
#[derive(Debug, thiserror::Error)]
pub enum ModuleError {
    /// Its declarations do not hold together (every problem is listed).
    #[error(transparent)]
    Load(#[from] LoadError),
    /// A port could not be declared, or a thread started.
    #[error(transparent)]
    Port(#[from] PortError),
    /// Its specification file cannot be used (every problem is listed).
    #[error(transparent)]
    File(#[from] super::ModuleFileError),
    /// The module is stopping: the body should return.
    #[error("module `{0}` is stopping")]
    Stopping(String),
    /// `costart` named a module that is no child of this one, or one started already.
    #[error(
        "module `{module}` has no child `{child}` to start (not declared with `child`, or started already)"
    )]
    NoChild {
        /// The module.
        module: String,
        /// The child named.
        child: String,
    },
    /// The context was asked for a port the module did not declare at that end with these
    /// types.
    #[error("module `{module}` declared no port `{port}` {what}")]
    NoPort {
        /// The module.
        module: String,
        /// The port.
        port: String,
        /// At which end and with which types it was asked for.
        what: String,
    },
}

/// Handlers run that [`RunningModule::handled`] remembers, at most (the most recent).
pub const HANDLED_KEPT: usize = 1024;

/// How long a listener waits for a message before it looks whether the module stops.
const LISTEN_SLICE: Duration = Duration::from_millis(100);

/// An event waiting for a handler.
enum Event {
    /// A query: its payload, and where the encoded answer goes.
    Query {
        payload: Vec<u8>,
        answer: mpsc::SyncSender<Result<Vec<u8>, String>>,
    },
    /// A timeout on the handler's port.
    Timeout,
}

type ResponseBody = Box<dyn FnMut(&[u8]) -> Result<Vec<u8>, String> + Send>;
type ExceptionBody = Box<dyn FnMut(&ModuleContext) + Send>;
type Body = Box<dyn FnOnce(&ModuleContext) + Send>;
type TaskBody = Box<dyn FnOnce(&TaskContext) + Send>;
type Declare = Box<dyn FnOnce(&Participant, &str) -> Result<Declared, PortError> + Send>;
/// Starts a port's listener for the module's response handler (given the handler's name).
type Listen = Box<dyn FnOnce(Arc<Shared>, String) -> JoinHandle<()> + Send>;

/// A port declared by a module, type-erased, with what listens on it for queries.
struct Declared {
    port: String,
    /// More handles under names of their own (a filtered port's `FILTER/<port>`).
    extra: Vec<(String, Arc<dyn Any + Send + Sync>)>,
    handle: Arc<dyn Any + Send + Sync>,
    /// Starts the thread that takes queries for the module's response handler, if the port
    /// has one.
    listen: Option<Listen>,
}

/// A module being declared (see the module docs).
pub struct ModuleBuilder {
    participant: Participant,
    spec: ModuleSpec,
    order_problem: Option<String>,
    ports: Vec<Declare>,
    responses: HashMap<String, ResponseBody>,
    response_formats: Vec<(String, (u64, u64))>,
    exceptions: HashMap<String, ExceptionBody>,
    tasks: Vec<(String, TaskBody)>,
    body: Option<Body>,
    children: Vec<ModuleBuilder>,
    schedule: Option<WorkSchedule<Call>>,
    schedule_problems: Vec<String>,
    /// Owned ports with a filter of their own.
    filtered: Vec<String>,
    /// The module's specification file, when it was read from one: the code only binds.
    file: Option<FileBinding>,
    /// Calls that made no sense for this module (binding a file's port without a file).
    misuse: Vec<LoadProblem>,
}

/// What a module read from a specification file still needs from its code, and what its
/// code declared that the file does not.
struct FileBinding {
    path: String,
    /// Ports declared there whose types are not bound yet.
    unbound: Vec<FilePort>,
    /// Tasks declared there (name, where).
    tasks: Vec<(String, String)>,
    /// Children declared there (name, where).
    children: Vec<(String, String)>,
    /// Problems found binding (something declared in code, or bound twice).
    problems: Vec<LoadProblem>,
}

impl FileBinding {
    fn not_in_file(&mut self, what: String) {
        self.problems.push(LoadProblem::Specification {
            at: self.path.clone(),
            what: format!("{what} is declared in code but not in the module's specification: declare it in the file"),
        });
    }
}

/// The module's state shared by its thread, its listeners and its context.
struct Shared {
    name: String,
    sections: Mutex<Sections<Event>>,
    events: Notify,
    stop: AtomicBool,
    responses: Mutex<HashMap<String, ResponseBody>>,
    exceptions: Mutex<HashMap<String, ExceptionBody>>,
    /// Handlers run so far, in order, with the section they preempted (for tests and
    /// `ndds`' views).
    log: Mutex<VecDeque<String>>,
    /// Children started by `costart`: they stop before their parent.
    started: Mutex<Vec<RunningModule>>,
}

impl Shared {
    fn sections(&self) -> MutexGuard<'_, Sections<Event>> {
        self.sections.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn post(&self, handler: &str, event: Event) -> bool {
        let posted = self.sections().post(handler, event).is_ok();
        if posted {
            self.events.notify();
        } else {
            tracing::warn!(module = %self.name, handler, "too many events wait for handlers: dropped");
        }
        posted
    }
}

impl ModuleBuilder {
    /// Starts declaring module `name` (also its background code's section name, and the task
    /// name its ports are declared under).
    pub fn new(participant: &Participant, name: &str) -> Self {
        ModuleBuilder {
            participant: participant.clone(),
            spec: ModuleSpec {
                name: name.to_owned(),
                ..ModuleSpec::default()
            },
            order_problem: None,
            ports: Vec::new(),
            responses: HashMap::new(),
            response_formats: Vec::new(),
            exceptions: HashMap::new(),
            tasks: Vec::new(),
            body: None,
            children: Vec::new(),
            schedule: None,
            schedule_problems: Vec::new(),
            filtered: Vec::new(),
            file: None,
            misuse: Vec::new(),
        }
    }

    /// Module `name` of a specification file (see [`ModuleFile`](super::ModuleFile)): its
    /// tasks, ports and restrictions, handlers, subprograms, order, schedule and children are
    /// the file's. The code binds them: [`port`](Self::port) (or
    /// [`port_filtered`](Self::port_filtered)) gives a port its message types,
    /// [`response`](Self::response), [`exception`](Self::exception) and
    /// [`task`](Self::task) give bodies to what the file names, [`child`](Self::child)
    /// gives a child's builder, [`body`](Self::body) the background code. Anything the file
    /// declares and the code does not bind, and anything the code declares that the file does
    /// not, is a load problem naming where ([`LoadProblem::Specification`]).
    pub fn from_file(
        participant: &Participant,
        file: &super::ModuleFile,
        name: &str,
    ) -> Result<Self, super::ModuleFileError> {
        let module = file.module(name)?;
        let mut builder = Self::new(participant, name);
        let spec = module.spec();
        builder.spec = ModuleSpec {
            owns: Vec::new(),
            uses: Vec::new(),
            ..spec
        };
        if let Some(text) = &module.schedule {
            builder.schedule = WorkSchedule::parse(text).ok();
        }
        builder.file = Some(FileBinding {
            path: file.path().to_owned(),
            unbound: module.ports.clone(),
            tasks: module.tasks.clone(),
            children: module.children.clone(),
            problems: Vec::new(),
        });
        Ok(builder)
    }

    /// Binds port `port` of the module's specification file to request type `Q` and reply
    /// type `R`: it is owned or used as the file declares, with the file's restrictions
    /// (see [`from_file`](Self::from_file)).
    pub fn port<Q, R>(mut self, port: &str) -> Self
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        match self.take_file_port(port) {
            Some(FileEnd::Owner(restrictions)) => self.own_port::<Q, R>(port, restrictions),
            Some(FileEnd::User { usages, timeout }) => {
                self.use_port::<Q, R>(port, &usages, timeout)
            }
            None => self,
        }
    }

    /// Binds owned port `port` of the module's specification file to its types, with
    /// `filter` spliced in at its end (see [`owns_filtered`](Self::owns_filtered)).
    pub fn port_filtered<Q, R, F>(mut self, port: &str, filter: F) -> Self
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
        F: super::RequestFilter<Q, R>,
        F::Message: Sync,
    {
        match self.take_file_port(port) {
            Some(FileEnd::Owner(restrictions)) => {
                // The code's filter is the one: a file's buffer, or usages other than the
                // filter's own, would be silently replaced.
                let own = filter.usages();
                let what = if restrictions.filter.is_some() {
                    Some(
                        "has a `buffer`, and the code splices in a filter of its own: keep one"
                            .to_owned(),
                    )
                } else if !own.is_empty()
                    && !restrictions.usages.is_empty()
                    && own != restrictions.usages
                {
                    Some(format!(
                        "declares usages {:?}, and the code's filter takes the users' messages with {own:?}: declare those",
                        restrictions.usages
                    ))
                } else {
                    None
                };
                if let (Some(what), Some(file)) = (what, &mut self.file) {
                    file.problems.push(LoadProblem::Specification {
                        at: file.path.clone(),
                        what: format!("port `{port}` {what}"),
                    });
                }
                self.own_filtered_port::<Q, R, F>(port, restrictions, filter)
            }
            Some(FileEnd::User { .. }) => {
                if let Some(file) = &mut self.file {
                    file.problems.push(LoadProblem::Specification {
                        at: file.path.clone(),
                        what: format!("port `{port}` is used, not owned: a filter of the module's own goes on a port it owns"),
                    });
                }
                self
            }
            None => self,
        }
    }

    /// The file's declaration of `port`, taken to be bound (a problem, and `None`, when
    /// there is no file, no such port, or it was bound already).
    fn take_file_port(&mut self, port: &str) -> Option<FileEnd> {
        let Some(file) = &mut self.file else {
            self.misuse.push(LoadProblem::Specification {
                at: format!("module `{}`", self.spec.name),
                what: format!("`port(\"{port}\")` binds a port of a module file, and this module was not read from one: declare the port with `owns` or `uses`"),
            });
            return None;
        };
        match file.unbound.iter().position(|p| p.port == port) {
            Some(at) => Some(file.unbound.remove(at).end),
            None => {
                let bound = self
                    .spec
                    .owns
                    .iter()
                    .chain(&self.spec.uses)
                    .any(|d| d.port == port);
                if bound {
                    file.problems.push(LoadProblem::Duplicate {
                        kind: "port binding",
                        name: port.to_owned(),
                    });
                } else {
                    file.not_in_file(format!("port `{port}`"));
                }
                None
            }
        }
    }

    /// The module's work schedule, in the paper's notation (one step per line:
    /// `1) GRASP(1), INSERT(10.5, 20, 3)`). Each call must name a subprogram of the module
    /// ([`subprogram`](Self::subprogram)); the body runs it with [`ModuleContext::perform`].
    pub fn schedule(mut self, text: &str) -> Self {
        if let Some(file) = &mut self.file {
            file.not_in_file("a work schedule".to_owned());
            return self;
        }
        match WorkSchedule::parse(text) {
            Ok(schedule) => self.schedule = Some(schedule),
            Err(err) => self.schedule_problems.push(err.to_string()),
        }
        self
    }

    /// The work schedule, read from a file (so that moving a chip is an edit of that file,
    /// not of the module).
    pub fn schedule_file(self, path: impl AsRef<std::path::Path>) -> Self {
        let path = path.as_ref();
        match std::fs::read_to_string(path) {
            Ok(text) => {
                let before = self.schedule_problems.len();
                let mut this = self.schedule(&text);
                if this.schedule_problems.len() > before
                    && let Some(last) = this.schedule_problems.last_mut()
                {
                    *last = format!("{}: {last}", path.display());
                }
                this
            }
            Err(err) => {
                let mut this = self;
                this.schedule_problems
                    .push(format!("{}: {err}", path.display()));
                this
            }
        }
    }

    /// A child module this one may start with [`ModuleContext::costart`]; it is checked (and
    /// its ports declared) when this one loads, with the parent.
    pub fn child(mut self, child: ModuleBuilder) -> Self {
        let bound = self.children.iter().any(|c| c.spec.name == child.spec.name);
        match &mut self.file {
            Some(file) if !file.children.iter().any(|(c, _)| *c == child.spec.name) => {
                file.not_in_file(format!("child `{}`", child.spec.name));
                return self;
            }
            Some(_) if bound => {
                self.bound_twice("child", &child.spec.name);
                return self;
            }
            Some(_) => {}
            None => self.spec.children.push(child.spec.name.clone()),
        }
        self.children.push(child);
        self
    }

    /// A name of the specification file given a body (or a builder) twice.
    fn bound_twice(&mut self, kind: &'static str, name: &str) {
        if let Some(file) = &mut self.file {
            file.problems.push(LoadProblem::Specification {
                at: file.path.clone(),
                what: format!("{kind} `{name}` is given a body twice in code"),
            });
        }
    }

    /// Takes handler `handler` (a `kind`, declared in `list`): without a specification file
    /// the code declares it; with one, the file must declare it and the code bind it once.
    /// False (and the problem recorded) when its body is not to be taken.
    fn take_handler(
        &mut self,
        handler: &str,
        kind: &'static str,
        bound: bool,
        list: impl Fn(&mut ModuleSpec) -> &mut Vec<String>,
    ) -> bool {
        let Some(file) = &mut self.file else {
            list(&mut self.spec).push(handler.to_owned());
            return true;
        };
        if !list(&mut self.spec).iter().any(|h| h == handler) {
            file.not_in_file(format!("{kind} `{handler}`"));
            return false;
        }
        if bound {
            self.bound_twice(kind, handler);
            return false;
        }
        true
    }

    /// The module owns `port`, with `restrictions` (its usages, timeout, ...). A module read
    /// from a specification file declares its ports there instead ([`port`](Self::port)).
    pub fn owns<Q, R>(mut self, port: &str, restrictions: Restrictions) -> Self
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        if let Some(file) = &mut self.file {
            file.not_in_file(format!("owned port `{port}`"));
            return self;
        }
        self.own_port::<Q, R>(port, restrictions)
    }

    fn own_port<Q, R>(mut self, port: &str, restrictions: Restrictions) -> Self
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        self.spec.owns.push(PortDecl {
            port: port.to_owned(),
            usages: restrictions.usages.clone(),
            timeout: restrictions.timeout_ms.is_some(),
            formats: Some(formats::<Q, R>()),
        });
        let answers =
            restrictions.usages.is_empty() || restrictions.usages.contains(&Usage::Response);
        let name = port.to_owned();
        self.ports.push(Box::new(move |participant, task| {
            let owner = Arc::new(PortOwner::<Q, R>::declare_with(
                participant,
                &name,
                task,
                restrictions,
            )?);
            let serving = Arc::clone(&owner);
            Ok(Declared {
                extra: Vec::new(),
                port: name,
                handle: owner,
                listen: answers.then(|| {
                    Box::new(move |shared: Arc<Shared>, handler: String| {
                        spawn_listener(&shared.name.clone(), &handler.clone(), move || {
                            serve_users(&shared, &handler, &serving);
                        })
                    }) as Listen
                }),
            })
        }));
        self
    }
    /// The module owns `port` with a filter of its own spliced in (see
    /// [`RequestFilter`](super::RequestFilter)); the body talks to the filter through the
    /// port `FILTER`, [`ModuleContext::filter`].
    pub fn owns_filtered<Q, R, F>(
        mut self,
        port: &str,
        restrictions: Restrictions,
        filter: F,
    ) -> Self
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
        F: super::RequestFilter<Q, R>,
        F::Message: Sync,
    {
        if let Some(file) = &mut self.file {
            file.not_in_file(format!("owned port `{port}`"));
            return self;
        }
        self.own_filtered_port::<Q, R, F>(port, restrictions, filter)
    }

    fn own_filtered_port<Q, R, F>(
        mut self,
        port: &str,
        restrictions: Restrictions,
        filter: F,
    ) -> Self
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
        F: super::RequestFilter<Q, R>,
        F::Message: Sync,
    {
        self.spec.owns.push(PortDecl {
            port: port.to_owned(),
            usages: restrictions.usages.clone(),
            timeout: restrictions.timeout_ms.is_some(),
            formats: Some(formats::<Q, R>()),
        });
        let name = port.to_owned();
        self.filtered.push(name.clone());
        self.ports.push(Box::new(move |participant, task| {
            let (owner, filter) = PortOwner::<Q, R>::declare_filtered(
                participant,
                &name,
                task,
                restrictions,
                filter,
            )?;
            Ok(Declared {
                extra: vec![(
                    format!("FILTER/{name}"),
                    Arc::new(filter) as Arc<dyn Any + Send + Sync>,
                )],
                port: name,
                handle: Arc::new(owner),
                listen: None,
            })
        }));
        self
    }

    /// The module uses `port` with `usages`; `timeout`, if given, bounds every operation on
    /// it through the module context (and allows a `PORT.TIMEOUT` handler). A module read
    /// from a specification file declares its ports there instead ([`port`](Self::port)).
    pub fn uses<Q, R>(mut self, port: &str, usages: &[Usage], timeout: Option<Duration>) -> Self
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        if let Some(file) = &mut self.file {
            file.not_in_file(format!("used port `{port}`"));
            return self;
        }
        self.use_port::<Q, R>(port, usages, timeout)
    }

    fn use_port<Q, R>(mut self, port: &str, usages: &[Usage], timeout: Option<Duration>) -> Self
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        self.spec.uses.push(PortDecl {
            port: port.to_owned(),
            usages: usages.to_vec(),
            timeout: timeout.is_some(),
            formats: Some(formats::<Q, R>()),
        });
        let (name, usages) = (port.to_owned(), usages.to_vec());
        let answers = usages.contains(&Usage::Response);
        self.ports.push(Box::new(move |participant, task| {
            let user = Arc::new(UsedPort {
                user: PortUser::<Q, R>::declare_with(participant, &name, task, &usages)?,
                timeout,
            });
            let serving = Arc::clone(&user);
            Ok(Declared {
                extra: Vec::new(),
                port: name,
                handle: user,
                listen: answers.then(|| {
                    Box::new(move |shared: Arc<Shared>, handler: String| {
                        spawn_listener(&shared.name.clone(), &handler.clone(), move || {
                            serve_owner(&shared, &handler, &serving.user);
                        })
                    }) as Listen
                }),
            })
        }));
        self
    }

    /// Declares the response handler `handler` (`PORT.NAME`) and its body, for queries of
    /// type `Q` answered with `R` (the port's types). One response handler per port.
    pub fn response<Q, R>(
        mut self,
        handler: &str,
        mut body: impl FnMut(Q) -> R + Send + 'static,
    ) -> Self
    where
        Q: Serialize + DeserializeOwned + 'static,
        R: Serialize + DeserializeOwned + 'static,
    {
        let bound = self.responses.contains_key(handler);
        if !self.take_handler(handler, "response handler", bound, |s| &mut s.responses) {
            return self;
        }
        self.response_formats
            .push((handler.to_owned(), formats::<Q, R>()));
        self.responses.insert(
            handler.to_owned(),
            Box::new(move |payload: &[u8]| {
                let query: Q = postcard::from_bytes(payload).map_err(|e| e.to_string())?;
                postcard::to_stdvec(&body(query)).map_err(|e| e.to_string())
            }),
        );
        self
    }

    /// Declares the exception handler `handler` (`PORT.TIMEOUT`) and its body.
    pub fn exception(
        mut self,
        handler: &str,
        body: impl FnMut(&ModuleContext) + Send + 'static,
    ) -> Self {
        let bound = self.exceptions.contains_key(handler);
        if !self.take_handler(handler, "exception handler", bound, |s| &mut s.exceptions) {
            return self;
        }
        self.exceptions.insert(handler.to_owned(), Box::new(body));
        self
    }

    /// Declares a named subprogram (a section the body enters with
    /// [`ModuleContext::section`]).
    pub fn subprogram(mut self, name: &str) -> Self {
        if let Some(file) = &mut self.file {
            file.not_in_file(format!("subprogram `{name}`"));
            return self;
        }
        self.spec.subprograms.push(name.to_owned());
        self
    }

    /// The module's order, in the paper's notation (`ORDER(A, B, C)`) or as names.
    pub fn order(mut self, text: &str) -> Self {
        if let Some(file) = &mut self.file {
            file.not_in_file("an order".to_owned());
            return self;
        }
        match Order::parse(text) {
            Ok(order) => self.spec.order = Some(order),
            Err(err) => self.order_problem = Some(err.to_string()),
        }
        self
    }

    /// A task created with the module, on a thread of its own.
    pub fn task(mut self, name: &str, body: impl FnOnce(&TaskContext) + Send + 'static) -> Self {
        let bound = self.tasks.iter().any(|(t, _)| t == name);
        match &mut self.file {
            Some(file) if !file.tasks.iter().any(|(t, _)| t == name) => {
                file.not_in_file(format!("task `{name}`"));
                return self;
            }
            Some(_) if bound => {
                self.bound_twice("task", name);
                return self;
            }
            Some(_) => {}
            None => self.spec.tasks.push(name.to_owned()),
        }
        self.tasks.push((name.to_owned(), Box::new(body)));
        self
    }

    /// The module's background code.
    pub fn body(mut self, body: impl FnOnce(&ModuleContext) + Send + 'static) -> Self {
        self.body = Some(Box::new(body));
        self
    }

    /// What the module declares.
    pub fn spec(&self) -> &ModuleSpec {
        &self.spec
    }

    /// Checks the module and its children (every problem at once) and declares their ports.
    pub fn load(self) -> Result<Module, ModuleError> {
        let mut problems = self.problems();
        // Between the modules of the tree: ports owned outside it are checked when they
        // match, so a port without an owner here is not a problem.
        let mut specs = Vec::new();
        self.collect_specs(&mut specs);
        problems.extend(
            ndds_core::ports::check_system(&specs)
                .into_iter()
                .filter(|p| !matches!(p, LoadProblem::NoOwner { .. })),
        );
        if !problems.is_empty() {
            return Err(LoadError {
                module: self.spec.name.clone(),
                problems,
            }
            .into());
        }
        self.declare(None)
    }

    fn collect_specs(&self, specs: &mut Vec<ModuleSpec>) {
        let mut spec = self.spec.clone();
        if self.file.is_some() {
            // A child the file declares and the code did not give is reported as such.
            spec.children
                .retain(|c| self.children.iter().any(|given| given.spec.name == *c));
        }
        specs.push(spec);
        for child in &self.children {
            child.collect_specs(specs);
        }
    }

    /// This module's problems, and its children's (named).
    fn problems(&self) -> Vec<LoadProblem> {
        let mut problems = self.spec.check(
            self.responses
                .keys()
                .chain(self.exceptions.keys())
                .map(String::as_str),
        );
        if let Some(file) = &self.file {
            // A port whose types are not bound is reported as such, not as unknown.
            problems.retain(|p| {
                !matches!(p, LoadProblem::UnknownPort { port, .. }
                    if file.unbound.iter().any(|u| u.port == *port))
            });
        }
        if let Some(problem) = &self.order_problem {
            problems.push(LoadProblem::UnknownSection {
                section: format!("(the order does not read: {problem})"),
            });
        }
        // A response handler takes the port's types.
        for (handler, handler_formats) in &self.response_formats {
            let port = handler
                .rsplit_once('.')
                .map_or(handler.as_str(), |(p, _)| p);
            let declared = self
                .spec
                .owns
                .iter()
                .chain(&self.spec.uses)
                .find(|d| d.port == port)
                .and_then(|d| d.formats);
            if let Some(port_formats) = declared
                && port_formats != *handler_formats
            {
                problems.push(LoadProblem::IncompatibleFormat {
                    port: port.to_owned(),
                    user: format!("{} (handler `{handler}`)", self.spec.name),
                    owner_formats: port_formats,
                    user_formats: *handler_formats,
                });
            }
        }
        for handler in &self.spec.responses {
            let port = handler
                .rsplit_once('.')
                .map_or(handler.as_str(), |(p, _)| p);
            if self.filtered.iter().any(|f| f == port) {
                problems.push(LoadProblem::HandlerWithoutUsage {
                    handler: handler.clone(),
                    why: format!(
                        "port `{port}` has a filter of its own: its requests go to the filter, not to a response handler"
                    ),
                });
            }
        }
        problems.extend(
            self.schedule_problems
                .iter()
                .map(|what| LoadProblem::Schedule { what: what.clone() }),
        );
        if let Some(schedule) = &self.schedule {
            for (step, call) in schedule
                .steps()
                .iter()
                .flat_map(|step| step.calls.iter().map(move |call| (step, call)))
            {
                if !self.spec.subprograms.contains(&call.name) {
                    problems.push(LoadProblem::Schedule {
                        what: format!(
                            "{}calls `{}`, which is not a subprogram of the module",
                            step.line.map(|l| format!("line {l} ")).unwrap_or_default(),
                            call.name
                        ),
                    });
                }
            }
        }
        problems.extend(self.misuse.iter().cloned());
        if let Some(file) = &self.file {
            problems.extend(file.problems.iter().cloned());
            for port in &file.unbound {
                problems.push(LoadProblem::Specification {
                    at: port.at.clone(),
                    what: format!(
                        "port `{}` is declared here but its message types are not bound: call `.port::<Q, R>(\"{}\")` on module `{}`'s builder",
                        port.port, port.port, self.spec.name
                    ),
                });
            }
            for (task, at) in &file.tasks {
                if !self.tasks.iter().any(|(t, _)| t == task) {
                    problems.push(LoadProblem::Specification {
                        at: at.clone(),
                        what: format!(
                            "task `{task}` has no body: give it with `.task(\"{task}\", body)`"
                        ),
                    });
                }
            }
            for (child, at) in &file.children {
                if !self.children.iter().any(|c| c.spec.name == *child) {
                    problems.push(LoadProblem::Specification {
                        at: at.clone(),
                        what: format!("child `{child}` is not given: build it and pass it with `.child(builder)`"),
                    });
                }
            }
        }
        for child in &self.children {
            problems.extend(
                child
                    .problems()
                    .into_iter()
                    .map(|problem| LoadProblem::InChild {
                        module: child.spec.name.clone(),
                        problem: Box::new(problem),
                    }),
            );
        }
        problems
    }

    /// Declares the ports of this module and its children (checked already).
    fn declare(self, parent: Option<String>) -> Result<Module, ModuleError> {
        let mut children = HashMap::new();
        for child in self.children {
            let name = child.spec.name.clone();
            children.insert(name, child.declare(Some(self.spec.name.clone()))?);
        }
        let mut ports = HashMap::new();
        let mut listeners = Vec::new();
        for declare in self.ports {
            let declared = declare(&self.participant, &self.spec.name)?;
            let prefix = format!("{}.", declared.port);
            if let Some(listen) = declared.listen
                && let Some(handler) = self.spec.responses.iter().find(|h| h.starts_with(&prefix))
            {
                listeners.push((handler.clone(), listen));
            }
            ports.insert(declared.port, declared.handle);
            ports.extend(declared.extra);
        }
        // Without an order, the body is the one section named.
        let order = match &self.spec.order {
            Some(order) => order.clone(),
            // Without an order, every handler may interrupt the body at its points.
            None => Order::new(
                self.spec
                    .exceptions
                    .iter()
                    .chain(&self.spec.responses)
                    .cloned()
                    .chain([self.spec.name.clone()]),
            )
            .map_err(|err| LoadError {
                module: self.spec.name.clone(),
                problems: vec![LoadProblem::UnknownSection {
                    section: format!("(the module's name is not a section name: {err})"),
                }],
            })?,
        };
        Ok(Module {
            participant: self.participant,
            parent,
            children,
            shared: Arc::new(Shared {
                name: self.spec.name.clone(),
                sections: Mutex::new(Sections::new(order)),
                events: Notify::default(),
                stop: AtomicBool::new(false),
                responses: Mutex::new(self.responses),
                exceptions: Mutex::new(self.exceptions),
                log: Mutex::new(VecDeque::new()),
                started: Mutex::new(Vec::new()),
            }),
            spec: self.spec,
            schedule: self.schedule,
            ports: Arc::new(ports),
            listeners,
            tasks: self.tasks,
            body: self.body,
        })
    }
}

fn formats<Q, R>() -> (u64, u64)
where
    Q: Serialize + DeserializeOwned + 'static,
    R: Serialize + DeserializeOwned + 'static,
{
    (
        TypeDescription::of::<Q>().fingerprint(),
        TypeDescription::of::<R>().fingerprint(),
    )
}

/// A used port and its timeout.
struct UsedPort<Q, R> {
    user: PortUser<Q, R>,
    timeout: Option<Duration>,
}

fn spawn_listener(
    module: &str,
    handler: &str,
    run: impl FnOnce() + Send + 'static,
) -> JoinHandle<()> {
    let name = format!("listen-{module}-{handler}");
    std::thread::Builder::new()
        .name(name.clone())
        .spawn(run)
        .unwrap_or_else(|err| {
            tracing::error!(module, handler, error = %err, "listener thread not started: its queries time out");
            std::thread::spawn(|| {})
        })
}

/// A listener's lasting failure (a replaced owner, a refusal), logged when it begins or
/// changes and when it ends — not at every retry.
#[derive(Default)]
struct Failing(Option<String>);

impl Failing {
    fn report(&mut self, shared: &Shared, handler: &str, err: &PortError) {
        let text = err.to_string();
        if self.0.as_ref() != Some(&text) {
            tracing::warn!(module = %shared.name, handler, error = %text,
                "the response handler's port fails: its queries wait until it is resolved");
            self.0 = Some(text);
        }
    }

    fn over<T>(&mut self, shared: &Shared, handler: &str, taken: T) -> T {
        if self.0.take().is_some() {
            tracing::info!(module = %shared.name, handler, "the response handler's port works again");
        }
        taken
    }
}

/// Posts a query for `handler` and waits for the module thread's answer (`None` when the
/// module stops first).
fn ask_module(shared: &Shared, handler: &str, payload: Vec<u8>) -> Option<Result<Vec<u8>, String>> {
    let (answer, answered) = mpsc::sync_channel(1);
    if !shared.post(handler, Event::Query { payload, answer }) {
        return Some(Err("the module has too many events waiting".to_owned()));
    }
    loop {
        match answered.recv_timeout(LISTEN_SLICE) {
            Ok(result) => return Some(result),
            Err(mpsc::RecvTimeoutError::Timeout) if !shared.stop.load(Ordering::Acquire) => {}
            Err(_) => return None,
        }
    }
}

/// The listener of an owned port with a response handler: users' queries.
fn serve_users<Q, R>(shared: &Shared, handler: &str, owner: &PortOwner<Q, R>)
where
    Q: Serialize + DeserializeOwned,
    R: Serialize + DeserializeOwned,
{
    listen(
        shared,
        handler,
        || owner.receive(LISTEN_SLICE),
        |reply: ReplyHandle<R>, answer| reply.reply_encoded(answer),
    );
}

/// The listener of a used port with usage `Response`: the owner's queries.
fn serve_owner<Q, R>(shared: &Shared, handler: &str, user: &PortUser<Q, R>)
where
    Q: Serialize + DeserializeOwned,
    R: Serialize + DeserializeOwned,
{
    listen(
        shared,
        handler,
        || wait::block_on(user.take_to_me(LISTEN_SLICE)).map(|(message, query)| (query, message)),
        |message, answer| {
            wait::block_on(user.answer_message(&message, answer, Duration::from_secs(2)))
        },
    );
}

/// A listener's loop until the module stops: `take` the next query (with what answers it),
/// have the module thread run `handler` on it, and `answer` with the encoded reply.
fn listen<Q: Serialize, T>(
    shared: &Shared,
    handler: &str,
    mut take: impl FnMut() -> Result<(Q, T), PortError>,
    mut answer: impl FnMut(T, Vec<u8>) -> Result<(), PortError>,
) {
    let mut failing = Failing::default();
    while !shared.stop.load(Ordering::Acquire) {
        let (query, to) = match take() {
            Ok(taken) => failing.over(shared, handler, taken),
            Err(PortError::Timeout { .. } | PortError::Codec { .. }) => continue,
            Err(err) => {
                failing.report(shared, handler, &err);
                std::thread::sleep(LISTEN_SLICE);
                continue;
            }
        };
        let Ok(payload) = postcard::to_stdvec(&query) else {
            continue;
        };
        match ask_module(shared, handler, payload) {
            Some(Ok(encoded)) => {
                if let Err(err) = answer(to, encoded) {
                    tracing::warn!(module = %shared.name, handler, error = %err, "answer not sent");
                }
            }
            Some(Err(err)) => {
                tracing::warn!(module = %shared.name, handler, error = %err, "handler failed")
            }
            None => return,
        }
    }
}

/// A module that loaded: [`start`](Module::start) runs it.
pub struct Module {
    participant: Participant,
    parent: Option<String>,
    children: HashMap<String, Module>,
    schedule: Option<WorkSchedule<Call>>,
    shared: Arc<Shared>,
    spec: ModuleSpec,
    ports: Arc<HashMap<String, Arc<dyn Any + Send + Sync>>>,
    listeners: Vec<(String, Listen)>,
    tasks: Vec<(String, TaskBody)>,
    body: Option<Body>,
}

impl Module {
    /// What the module declared.
    pub fn spec(&self) -> &ModuleSpec {
        &self.spec
    }

    /// Starts the module: its listeners, its tasks, and its thread (the body, then its
    /// handlers until it stops).
    pub fn start(self) -> Result<RunningModule, ModuleError> {
        let shared = Arc::clone(&self.shared);
        self.start_threads().inspect_err(|_| {
            // Whatever started stops.
            shared.stop.store(true, Ordering::Release);
            shared.events.notify();
        })
    }

    fn start_threads(self) -> Result<RunningModule, ModuleError> {
        let info = ModuleInfo {
            name: self.spec.name.clone(),
            parent: self.parent.clone(),
            children: self.spec.children.clone(),
            tasks: self.spec.tasks.clone(),
            owns: self.spec.owns.iter().map(|d| d.port.clone()).collect(),
            uses: self.spec.uses.iter().map(|d| d.port.clone()).collect(),
            pid: std::process::id(),
            host: gethostname::gethostname().to_string_lossy().into_owned(),
        };
        let topic = format!("module/{}", self.spec.name);
        let declaration =
            super::declaring_producer::<ModuleInfo>(&self.participant, &self.spec.name, &topic)?;
        declaration
            .write(&info)
            .map_err(|source| PortError::Write {
                port: self.spec.name.clone(),
                what: "the module's declaration".to_owned(),
                source,
            })?;
        let mut threads = Vec::new();
        for (handler, listen) in self.listeners {
            threads.push(listen(Arc::clone(&self.shared), handler));
        }
        for (task, body) in self.tasks {
            let context = TaskContext {
                participant: self.participant.clone(),
                name: task.clone(),
                module: self.spec.name.clone(),
                stop: Arc::clone(&self.shared),
            };
            let name = format!("task-{task}");
            threads.push(
                std::thread::Builder::new()
                    .name(name.clone())
                    .spawn(move || body(&context))
                    .map_err(|source| PortError::Spawn {
                        port: None,
                        thread: name,
                        source,
                    })?,
            );
        }
        let context = ModuleContext {
            shared: Arc::clone(&self.shared),
            ports: Arc::clone(&self.ports),
            children: Mutex::new(self.children),
            schedule: Mutex::new(self.schedule),
        };
        let body = self.body;
        let name = format!("module-{}", self.spec.name);
        let main = std::thread::Builder::new()
            .name(name.clone())
            .spawn(move || {
                if let Some(body) = body {
                    let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        context.in_section(&context.shared.name.clone(), || body(&context));
                    }));
                    if ran.is_err() {
                        tracing::error!(module = %context.shared.name,
                            "the module's body panicked: its handlers go on being served");
                    }
                }
                // Serve the handlers until the module stops.
                while !context.stopping() {
                    let seen = context.shared.events.generation();
                    context.point();
                    wait::block_on(wait::timeout_at(
                        wait::deadline(Instant::now(), LISTEN_SLICE),
                        context.shared.events.changed(seen),
                    ));
                }
            })
            .map_err(|source| PortError::Spawn {
                port: None,
                thread: name,
                source,
            })?;
        threads.push(main);
        Ok(RunningModule {
            shared: self.shared,
            threads,
            _declaration: Some(declaration),
        })
    }
}

/// A running module; dropping it (or [`stop`](RunningModule::stop)) stops it.
pub struct RunningModule {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    /// The module's declaration (`module/<name>`), withdrawn when it stops.
    _declaration: Option<crate::Producer<ModuleInfo>>,
}

impl RunningModule {
    /// The handlers run so far, in order, each with the section it ran in (`handler` alone
    /// when nothing else ran, `handler in SECTION` otherwise).
    pub fn handled(&self) -> Vec<String> {
        self.shared
            .log
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .cloned()
            .collect()
    }

    /// Stops the module: its context's primitives fail with [`ModuleError::Stopping`], and
    /// once the body, its tasks and listeners have returned, this returns.
    pub fn stop(mut self) {
        self.halt();
    }

    fn halt(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        self.shared.events.notify();
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
        // Its children stop once it has (the body cannot start one any more).
        let children = std::mem::take(
            &mut *self
                .shared
                .started
                .lock()
                .unwrap_or_else(|p| p.into_inner()),
        );
        drop(children);
    }

    /// The module's name.
    pub fn name(&self) -> &str {
        &self.shared.name
    }
}

impl Drop for RunningModule {
    fn drop(&mut self) {
        self.halt();
    }
}

/// What a task of a module sees.
pub struct TaskContext {
    participant: Participant,
    name: String,
    module: String,
    stop: Arc<Shared>,
}

impl TaskContext {
    /// The participant the module runs in (for the task's own ports and topics).
    pub fn participant(&self) -> &Participant {
        &self.participant
    }

    /// The task's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The module's name.
    pub fn module(&self) -> &str {
        &self.module
    }
    /// Whether the module is stopping (the task should return).
    pub fn stopping(&self) -> bool {
        self.stop.stop.load(Ordering::Acquire)
    }

    /// `send` through `user` (a port the task declared itself), given up as soon as the
    /// module stops ([`ModuleError::Stopping`]; the request is not withdrawn then: an owner
    /// that is still there may receive it).
    pub fn send<Q, R>(
        &self,
        user: &PortUser<Q, R>,
        value: &Q,
        timeout: Duration,
    ) -> Result<R, ModuleError>
    where
        Q: Serialize + DeserializeOwned,
        R: Serialize + DeserializeOwned,
    {
        user.require(Usage::Send)?;
        let mut exchange = pin!(user.exchange(value, timeout));
        loop {
            let seen = self.stop.events.generation();
            if self.stopping() {
                return Err(ModuleError::Stopping(self.module.clone()));
            }
            let woke = wait::parked_only(|| {
                wait::block_on(wait::race(
                    exchange.as_mut(),
                    self.stop.events.changed(seen),
                ))
            });
            if let Either::Left(result) = woke {
                return result.map_err(ModuleError::Port);
            }
        }
    }
}

/// What the module's body and handlers see: the module's ports, its sections and its
/// preemption points (see the module docs).
pub struct ModuleContext {
    shared: Arc<Shared>,
    ports: Arc<HashMap<String, Arc<dyn Any + Send + Sync>>>,
    /// Children not started yet.
    children: Mutex<HashMap<String, Module>>,
    /// The work schedule (taken out while `perform` runs it).
    schedule: Mutex<Option<WorkSchedule<Call>>>,
}

impl ModuleContext {
    /// The module's name.
    pub fn name(&self) -> &str {
        &self.shared.name
    }

    /// Whether the module is stopping (the body should return).
    pub fn stopping(&self) -> bool {
        self.shared.stop.load(Ordering::Acquire)
    }

    fn schedule(&self) -> MutexGuard<'_, Option<WorkSchedule<Call>>> {
        self.schedule.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// `REINSTATE`: every step of the work schedule pending again.
    pub fn reinstate(&self) {
        if let Some(schedule) = self.schedule().as_mut() {
            schedule.reinstate();
        }
    }

    /// `MORE`: the steps of the work schedule `perform` may still run.
    pub fn more(&self) -> usize {
        self.schedule().as_ref().map_or(0, WorkSchedule::more)
    }

    /// `PERFORM`: runs the calls of the most urgent step not yet done, each as the section of
    /// its subprogram (its entry and exit are preemption points) through `call`, which does
    /// the work and returns its code (0: done; anything else fails the step there, and the
    /// other steps go on). Inside a handler that preempted a `perform`, `perform` does
    /// nothing.
    pub fn perform(&self, mut call: impl FnMut(&Call) -> i32) -> Performed {
        let taken = self.schedule().take();
        let Some(mut schedule) = taken else {
            return Performed::Nothing;
        };
        let performed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            schedule.perform(|c| self.in_section(&c.name, || call(c)))
        }));
        // Back in place whatever happened (a call that panicked left its step where it was).
        *self.schedule() = Some(schedule);
        performed.unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    }

    /// The failed steps of the work schedule pending again (an operator refilled a feeder),
    /// resuming at the call that failed; how many.
    pub fn retry_failed(&self) -> usize {
        self.schedule()
            .as_mut()
            .map_or(0, WorkSchedule::retry_failed)
    }

    /// `COSTART`: starts these child modules (declared with [`ModuleBuilder::child`],
    /// loaded and checked with this one), each on its own threads; they stop when this
    /// module stops. A name that is no child not started yet starts nothing and is an error.
    pub fn costart(&self, names: &[&str]) -> Result<(), ModuleError> {
        let mut children = self.children.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(missing) = names.iter().find(|n| !children.contains_key(**n)) {
            return Err(ModuleError::NoChild {
                module: self.shared.name.clone(),
                child: (*missing).to_owned(),
            });
        }
        for name in names {
            if let Some(child) = children.remove(*name) {
                let running = child.start()?;
                self.shared
                    .started
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .push(running);
            }
        }
        Ok(())
    }

    /// A preemption point: runs the handlers whose events wait and that the order lets run
    /// now, most urgent first.
    pub fn point(&self) {
        loop {
            let next = self.shared.sections().next_at_point();
            let Some((handler, event)) = next else { return };
            let innermost = self.shared.sections().innermost().map(str::to_owned);
            {
                let mut log = self.shared.log.lock().unwrap_or_else(|p| p.into_inner());
                if log.len() >= HANDLED_KEPT {
                    log.pop_front();
                }
                log.push_back(match innermost {
                    Some(section) => format!("{handler} in {section}"),
                    None => handler.clone(),
                });
            }
            self.in_section(&handler, || self.run_handler(&handler, event));
        }
    }

    fn run_handler(&self, handler: &str, event: Event) {
        match event {
            Event::Query { payload, answer } => {
                // Taken out while it runs: a handler never runs inside itself.
                let body = self
                    .shared
                    .responses
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .remove(handler);
                let Some(mut body) = body else {
                    let _ = answer.send(Err(format!("no response handler `{handler}`")));
                    return;
                };
                let result =
                    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| body(&payload)))
                        .unwrap_or_else(|_| Err(format!("response handler `{handler}` panicked")));
                self.shared
                    .responses
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .insert(handler.to_owned(), body);
                let _ = answer.send(result);
            }
            Event::Timeout => {
                let body = self
                    .shared
                    .exceptions
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .remove(handler);
                if let Some(mut body) = body {
                    if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| body(self)))
                        .is_err()
                    {
                        tracing::error!(module = %self.shared.name, handler, "exception handler panicked");
                    }
                    self.shared
                        .exceptions
                        .lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .insert(handler.to_owned(), body);
                }
            }
        }
    }

    /// Runs `f` as section `name`: entered (a point), run, left (a point). The section is
    /// left even if `f` panics.
    fn in_section<T>(&self, name: &str, f: impl FnOnce() -> T) -> T {
        /// Leaves the section when dropped (also on a panic).
        struct Leave<'a>(&'a Shared, &'a str);
        impl Drop for Leave<'_> {
            fn drop(&mut self) {
                if let Err(err) = self.0.sections().leave(self.1) {
                    tracing::error!(module = %self.0.name, error = %err, "sections left out of order");
                }
            }
        }
        self.shared.sections().enter(name);
        let leave = Leave(&self.shared, name);
        self.point();
        let out = f();
        self.point();
        drop(leave);
        out
    }

    /// Runs the named subprogram `name` (declared with
    /// [`ModuleBuilder::subprogram`]) as a section: its entry and exit are points.
    pub fn section<T>(&self, name: &str, f: impl FnOnce() -> T) -> T {
        self.in_section(name, f)
    }

    /// Waits for `future`, running the handlers the order allows meanwhile.
    fn at_points<F: std::future::Future>(&self, future: F) -> Result<F::Output, ModuleError> {
        let mut future = pin!(future);
        loop {
            let seen = self.shared.events.generation();
            if self.stopping() {
                return Err(ModuleError::Stopping(self.shared.name.clone()));
            }
            self.point();
            let woke = wait::parked_only(|| {
                wait::block_on(wait::timeout_at(
                    wait::deadline(Instant::now(), LISTEN_SLICE),
                    wait::race(future.as_mut(), self.shared.events.changed(seen)),
                ))
            });
            if let Some(Either::Left(out)) = woke {
                return Ok(out);
            }
        }
    }

    /// `DELAY`: waits `duration`, running the handlers the order allows meanwhile.
    pub fn delay(&self, duration: Duration) -> Result<(), ModuleError> {
        self.at_points(wait::sleep_until(wait::deadline(Instant::now(), duration)))
    }

    fn port<T: Send + Sync + 'static>(&self, port: &str) -> Result<Arc<T>, ModuleError> {
        self.ports
            .get(port)
            .cloned()
            .and_then(|handle| handle.downcast::<T>().ok())
            .ok_or_else(|| ModuleError::NoPort {
                module: self.shared.name.clone(),
                port: port.to_owned(),
                what: format!("as {}", std::any::type_name::<T>()),
            })
    }
    /// Posts `PORT.TIMEOUT` when `result` is a timeout (no answer within the port's timeout,
    /// or, for an owner's message, no user to take it within that time) and the module
    /// handles it.
    fn on_timeout<T>(&self, port: &str, result: Result<T, PortError>) -> Result<T, ModuleError> {
        if let Err(PortError::Timeout { .. } | PortError::NoSuchUser { .. }) = &result {
            let handler = format!("{port}.TIMEOUT");
            if self
                .shared
                .exceptions
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .contains_key(&handler)
            {
                self.shared.post(&handler, Event::Timeout);
                self.point();
            }
        }
        result.map_err(ModuleError::Port)
    }

    /// `SEND`: on a port the module uses (usage `Send`), to the owner, waiting for its
    /// reply; on a port it owns (usage `Send`), to its user that receives (the first
    /// admitted), waiting for that user's answer — within the port's timeout.
    pub fn send<Q, R>(&self, port: &str, value: &Q) -> Result<R, ModuleError>
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        self.to_other_end(port, value, Usage::Send)
    }

    /// `QUERY` on a port: as a user, the owner's response handler answers; on a port the
    /// module owns (usage `Query`), one of its users' response handlers does.
    pub fn query<Q, R>(&self, port: &str, value: &Q) -> Result<R, ModuleError>
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        self.to_other_end(port, value, Usage::Query)
    }

    /// `send` (`usage` Send) or `query` (Query) to the port's other end, as its owner or as
    /// its user, at points, the port's timeout running the exception handler.
    fn to_other_end<Q, R>(&self, port: &str, value: &Q, usage: Usage) -> Result<R, ModuleError>
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        if let Ok(owner) = self.port::<PortOwner<Q, R>>(port) {
            let timeout = owner
                .restrictions()
                .timeout_ms
                .map_or(Duration::MAX, Duration::from_millis);
            let result = if usage == Usage::Query {
                self.at_points(owner.query_future(value, timeout))?
            } else {
                self.at_points(owner.send_any_future(value, timeout))?
            };
            return self.on_timeout(port, result);
        }
        let used = self.port::<UsedPort<Q, R>>(port)?;
        used.user.require(usage)?;
        let timeout = used.timeout.unwrap_or(Duration::MAX);
        let result = self.at_points(used.user.exchange(value, timeout))?;
        self.on_timeout(port, result)
    }

    /// `RECEIVE` on a port the module owns: the next request and the handle to reply with,
    /// waiting at most the port's timeout restriction (or `timeout`, if shorter).
    pub fn receive<Q, R>(
        &self,
        port: &str,
        timeout: Duration,
    ) -> Result<(Q, ReplyHandle<R>), ModuleError>
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        let owner = self.port::<PortOwner<Q, R>>(port)?;
        let timeout = owner
            .restrictions()
            .timeout_ms
            .map_or(timeout, |ms| timeout.min(Duration::from_millis(ms)));
        let result = self.at_points(owner.receive_future(timeout))?;
        self.on_timeout(port, result)
    }
    /// `RECEIVE` on a port the module uses (usage `Receive` or `Response`): takes the next
    /// message its owner sent to this module and answers it with `answer` (the paper's
    /// RECEIVE then REPLY), waiting at most the port's timeout (or `timeout`, if shorter).
    pub fn receive_from_owner<Q, R>(
        &self,
        port: &str,
        timeout: Duration,
        answer: impl FnOnce(&Q) -> R,
    ) -> Result<Q, ModuleError>
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        let used = self.port::<UsedPort<Q, R>>(port)?;
        let timeout = used.timeout.map_or(timeout, |t| t.min(timeout));
        let taken = self.at_points(used.user.take_to_me(timeout))?;
        let (message, value) = self.on_timeout(port, taken)?;
        let payload = used.user.encode_reply(&answer(&value))?;
        let answered = self.at_points(used.user.answer_message(&message, payload, timeout))?;
        answered?;
        Ok(value)
    }
    /// The port `FILTER` of a port the module owns with a filter
    /// ([`ModuleBuilder::owns_filtered`]): how the body talks to that filter.
    pub fn filter<M: Send + Sync + 'static>(
        &self,
        port: &str,
    ) -> Result<Arc<super::FilterPort<M>>, ModuleError> {
        self.port::<super::FilterPort<M>>(&format!("FILTER/{port}"))
    }

    /// The owner end of a port the module owns, for the primitives the context does not
    /// wrap (`sendall`, `callall`, `send_to`, ...): they are not preemption points.
    pub fn owner<Q, R>(&self, port: &str) -> Result<Arc<PortOwner<Q, R>>, ModuleError>
    where
        Q: Serialize + DeserializeOwned + Send + Sync + 'static,
        R: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        self.port::<PortOwner<Q, R>>(port)
    }
}

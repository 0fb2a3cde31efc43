//! Building a checked description through the linking database, then verifying it; and the
//! parts a system adds around its runtime (triggers, state machine actions, port servers).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::thread::JoinHandle;
use std::time::Duration;

use super::decl::{self, PortDecl, Serves, TriggerDecl};
use super::source::{Diagnostics, Location, RawValue, SourceFile};
use super::{LoadOptions, MachineEntry, MachineSlot, System, SystemError};
use crate::fsm::{ActionSet, FsmError, Program, StateMachine, Stimulus};
use crate::habitat::HabitatError;
use crate::{
    Binder, Mat, ModuleError, Problem, RoutineResult, Runtime, RuntimeError, SampleContext,
    SampleModule, Shape,
};
use ndds_client::Participant;
use ndds_client::ports::PortOwner;

/// How long a port server waits for a request before checking whether to stop.
const PORT_POLL: Duration = Duration::from_millis(200);

/// The `[system] name` of the top file (or of the first included file that has one).
fn system_name(files: &[SourceFile]) -> Option<String> {
    files.iter().rev().find_map(|f| {
        let RawValue::Table(t) = &f.top.get("system")?.value else {
            return None;
        };
        match &t.get("name")?.value {
            RawValue::Text(s) if !s.trim().is_empty() => Some(s.clone()),
            _ => None,
        }
    })
}

/// Where things were declared, to report runtime refusals and verify problems there.
#[derive(Default)]
struct Places {
    /// By module name.
    modules: BTreeMap<String, Location>,
    /// By (module, CSMat).
    uses: BTreeMap<(String, String), Location>,
    /// By CSMat: where it was created or first named.
    mats: BTreeMap<String, Location>,
    /// By configuration name.
    configurations: BTreeMap<String, Location>,
}

impl Places {
    fn use_of(&self, module: &str, mat: &str) -> Option<&Location> {
        self.uses
            .get(&(module.to_owned(), mat.to_owned()))
            .or_else(|| self.modules.get(module))
    }

    fn problem(&self, problem: &Problem, fallback: &Location) -> Location {
        let found = match problem {
            Problem::Unbound {
                name,
                referenced_by,
                ..
            } => referenced_by
                .iter()
                .find_map(|m| self.use_of(m, name))
                .or_else(|| self.mats.get(name)),
            Problem::ShapeMismatch { mat, module, .. } => self.use_of(module, mat),
            Problem::MissingProducer { mat, readers, .. } => {
                readers.iter().find_map(|m| self.use_of(m, mat))
            }
            Problem::DoubleWriter { mat, writers, .. } => {
                writers.iter().rev().find_map(|m| self.use_of(m, mat))
            }
            // The module declared last closed the loop.
            Problem::AlgebraicLoop { modules, .. } => modules
                .iter()
                .filter_map(|m| self.modules.get(m))
                .max_by_key(|at| (at.file.as_path(), at.line, at.column)),
            Problem::WrongCategory { configuration, .. } => self.configurations.get(configuration),
        };
        found.unwrap_or(fallback).clone()
    }
}

/// The module error inside `err`: the source of [`RuntimeError::Build`], or the first
/// [`ModuleError`] down its chain of sources.
fn module_error(err: &RuntimeError) -> Option<&ModuleError> {
    if let RuntimeError::Build { source, .. } = err {
        return Some(source);
    }
    let mut cause = std::error::Error::source(err);
    while let Some(e) = cause {
        if let Some(found) = e.downcast_ref::<ModuleError>() {
            return Some(found);
        }
        cause = e.source();
    }
    None
}

/// Where the parameter a component refused ([`ModuleError::Param`]) was written, else
/// `fallback`.
fn param_at<'a>(
    err: &RuntimeError,
    params: &'a BTreeMap<String, Location>,
    fallback: &'a Location,
) -> &'a Location {
    match module_error(err) {
        // `plant.stiffness` is a key of the table `plant`.
        Some(ModuleError::Param { name, .. }) => name
            .split('.')
            .next()
            .and_then(|key| params.get(key))
            .unwrap_or(fallback),
        _ => fallback,
    }
}

/// Whether `err` is a refusal for want of a participant: a network binding, or a module
/// that says it [needs one](ModuleError::NeedsParticipant).
fn needs_participant(err: &RuntimeError) -> bool {
    matches!(
        err,
        RuntimeError::NoParticipant(_) | RuntimeError::Habitat(HabitatError::NoParticipant(_))
    ) || matches!(module_error(err), Some(ModuleError::NeedsParticipant))
}

/// What building refused so far: problems of the description, and (loaded without a
/// participant) what one would let through.
struct Refusals {
    /// Loaded with a participant: a refusal for want of one is a problem like any other.
    with_participant: bool,
    problems: Diagnostics,
    needs_participant: Diagnostics,
}

impl Refusals {
    fn new(participant: Option<&Participant>) -> Self {
        Self {
            with_participant: participant.is_some(),
            problems: Diagnostics::default(),
            needs_participant: Diagnostics::default(),
        }
    }

    /// Reports `err` at `at`, among the problems or among what needs a participant.
    fn refuse(&mut self, at: &Location, err: &RuntimeError) {
        if !self.with_participant && needs_participant(err) {
            self.needs_participant.push(at, err.to_string());
        } else {
            self.problems.push(at, err.to_string());
        }
    }

    fn is_empty(&self) -> bool {
        self.problems.is_empty() && self.needs_participant.is_empty()
    }

    /// The problems if there are any, else what needs a participant, else nothing.
    fn into_result(self) -> Result<(), SystemError> {
        if !self.problems.is_empty() {
            return Err(invalid(self.problems));
        }
        if !self.needs_participant.is_empty() {
            return Err(SystemError::NeedsParticipant(in_file_order(
                self.needs_participant,
            )));
        }
        Ok(())
    }
}

/// Each network binding and port of `d`, loaded without a participant.
fn network_sections(d: &decl::Description) -> Diagnostics {
    let mut needs = Diagnostics::default();
    let advice = "needs a connection to a daemon (load the system with a participant)";
    for s in &d.subscribes {
        needs.push(&s.at, format!("subscribing to `{}` {advice}", s.topic));
    }
    for s in &d.publishes {
        needs.push(&s.at, format!("publishing on `{}` {advice}", s.topic));
    }
    for port in &d.ports {
        needs.push(&port.name.at, format!("port `{}` {advice}", port.name.name));
    }
    needs
}

pub(crate) fn build(
    files: Vec<SourceFile>,
    stem: &str,
    participant: Option<&Participant>,
    options: LoadOptions,
) -> Result<System, SystemError> {
    let name = options
        .name
        .clone()
        .or_else(|| system_name(&files))
        .unwrap_or_else(|| stem.to_owned());
    let runtime = match participant {
        Some(p) if options.check => Runtime::with_participant_unserved(&name, p)?,
        Some(p) => Runtime::with_participant(&name, p)?,
        None => Runtime::new(&name),
    };
    runtime.add_library(options.library.clone());
    build_into(files, runtime, participant, options)
}

pub(crate) fn build_into(
    files: Vec<SourceFile>,
    rt: Runtime,
    participant: Option<&Participant>,
    options: LoadOptions,
) -> Result<System, SystemError> {
    let mut p = Diagnostics::default();
    let known: Vec<String> = rt.component_types().into_iter().map(|(n, _)| n).collect();
    let spec = |name: &str| match rt.component_spec(name) {
        Some(spec) => Ok(Some(spec)),
        None if known.iter().any(|k| k == name) => Ok(None),
        None => Err(known.clone()),
    };
    let d = decl::describe(&files, &spec, &options.overlay, &mut p);
    let fallback = d.start.clone().unwrap_or_else(|| Location {
        file: Arc::new("<system>".into()),
        line: 1,
        column: 1,
    });
    if !p.is_empty() {
        return Err(invalid(p));
    }
    if participant.is_none() {
        let needs = network_sections(&d);
        if !needs.is_empty() {
            return Err(SystemError::NeedsParticipant(in_file_order(needs)));
        }
    }

    let mut places = Places::default();
    let mut found = Refusals::new(participant);

    for h in &d.habitats {
        let mut habitat_options = h.options.clone();
        if options.simulated {
            habitat_options.clock = crate::Clock::Manual;
        }
        if let Err(err) = rt.create_habitat(&h.name.name, habitat_options) {
            found.refuse(&h.name.at, &err);
        }
    }
    for m in &d.mats {
        places.mats.insert(m.name.name.clone(), m.name.at.clone());
        if let Err(err) = rt.create_mat(m.value.clone()) {
            found.refuse(&m.name.at, &err);
        }
    }
    // Groups before modules: a module installed into an inactive group never conflicts with
    // the active one writing the same CSMat.
    // In the order declared: a category's first group is active unless a configuration says
    // otherwise.
    let mut groups: Vec<GroupDecl<'_>> = Vec::new();
    for c in &d.components {
        if let Some((category, group, at)) = &c.group {
            let key = (category.clone(), group.clone());
            match groups.iter_mut().find(|(k, _)| *k == key) {
                Some((_, (modules, _))) => modules.push(&c.name.name),
                None => groups.push((key, (vec![&c.name.name], at.clone()))),
            }
        }
    }
    for ((category, group), (modules, at)) in &groups {
        if let Err(err) = rt.group(category, group, modules) {
            found.refuse(at, &err);
        }
    }
    for conf in &d.configurations {
        places
            .configurations
            .insert(conf.name.name.clone(), conf.name.at.clone());
        let pairs: Vec<(&str, &str)> = conf
            .groups
            .iter()
            .map(|(c, g, _)| (c.as_str(), g.as_str()))
            .collect();
        if let Err(err) = rt.configuration(&conf.name.name, &pairs) {
            found.refuse(&conf.name.at, &err);
        }
        let rates: Vec<(&str, f64)> = conf
            .rates
            .iter()
            .map(|(h, hz, _)| (h.as_str(), *hz))
            .collect();
        if !rates.is_empty()
            && let Err(err) = rt.configuration_rates(&conf.name.name, &rates)
        {
            found.refuse(&conf.name.at, &err);
        }
    }
    for c in &d.components {
        places
            .modules
            .insert(c.name.name.clone(), c.name.at.clone());
        for (mat, at, _) in &c.mats {
            places
                .uses
                .entry((c.name.name.clone(), mat.clone()))
                .or_insert_with(|| at.clone());
            places.mats.entry(mat.clone()).or_insert_with(|| at.clone());
        }
        if let Err(err) =
            rt.install_component(&c.habitat.name, &c.name.name, &c.type_name.name, &c.params)
        {
            found.refuse(param_at(&err, &c.param_at, &c.name.at), &err);
        }
    }
    // Subscriptions after the components: a subscribed CSMat that a component created (a
    // parameter such as `filter.tau`) keeps the component's value until a sample arrives.
    for s in &d.subscribes {
        let module = format!("subscribe:{}", s.topic);
        places.modules.insert(module.clone(), s.at.clone());
        places
            .uses
            .insert((module, s.mat.name.clone()), s.mat.at.clone());
        places
            .mats
            .entry(s.mat.name.clone())
            .or_insert_with(|| s.mat.at.clone());
        // Simulated, a topic this system also publishes is passed on inside the process
        // (a rate transition from the publisher's CSMat): the loop it closes then runs in
        // simulated time, sample for sample, instead of at the network's pace.
        let loopback = options
            .simulated
            .then(|| d.publishes.iter().find(|p| p.topic == s.topic))
            .flatten();
        let bound = match loopback {
            Some(p) => {
                let name = format!("subscribe:{}", s.topic);
                for half in ["in", "out"] {
                    places
                        .modules
                        .insert(format!("{name}.{half}"), s.at.clone());
                }
                rt.rate_transition(
                    &name,
                    (&p.habitat.name, &p.mat.name),
                    (&s.habitat.name, &s.mat.name),
                )
            }
            None => rt.subscribe(&s.habitat.name, &s.mat.name, s.shape, &s.topic, s.qos),
        };
        if let Err(err) = bound {
            found.refuse(&s.at, &err);
        }
    }
    for r in &d.rates {
        for half in ["in", "out"] {
            places
                .modules
                .insert(format!("{}.{half}", r.name.name), r.name.at.clone());
        }
        if let Err(err) = rt.rate_transition(
            &r.name.name,
            (&r.from.0.name, &r.from.1.name),
            (&r.to.0.name, &r.to.1.name),
        ) {
            found.refuse(&r.name.at, &err);
        }
    }
    let mut machines: BTreeMap<String, MachineEntry> = BTreeMap::new();
    for m in &d.machines {
        let slot: MachineSlot = Arc::new(OnceLock::new());
        let pending = PendingMachine {
            program: m.program.clone(),
        };
        // For the names and codes only: the network does not change them.
        let actions = pending.actions(&rt, None);
        let problems = crate::fsm::verify(&m.program, &|action| actions.codes(action));
        for problem in problems {
            found.problems.push(
                &m.at,
                format!(
                    "state machine `{}` ({}): {problem}",
                    m.program.main,
                    m.file.display()
                ),
            );
        }
        machines.insert(
            m.program.main.clone(),
            MachineEntry {
                slot,
                running: std::sync::Mutex::new(None),
                pending,
            },
        );
    }
    for (i, t) in d.triggers.iter().enumerate() {
        let module = format!("trigger{i}:{}", t.stimulus.name);
        places.modules.insert(module.clone(), t.at.clone());
        places
            .uses
            .insert((module.clone(), t.input.name.clone()), t.input.at.clone());
        let Some(entry) = machines.get(&t.machine.name) else {
            continue; // reported by the cross-check
        };
        let slot = Arc::clone(&entry.slot);
        if let Err(err) = rt.install(&t.habitat.name, &module, |b| Ok(Trigger::new(b, t, slot))) {
            found.refuse(&t.at, &err);
        }
    }
    for s in &d.publishes {
        let module = format!("publish:{}", s.topic);
        places.modules.insert(module.clone(), s.at.clone());
        places
            .uses
            .insert((module, s.mat.name.clone()), s.mat.at.clone());
        if let Err(err) = rt.publish(&s.habitat.name, &s.mat.name, &s.topic, s.qos) {
            found.refuse(&s.at, &err);
        }
    }
    if let Some(conf) = &d.configuration
        && found.is_empty()
        && let Err(err) = rt.switch(&conf.name)
    {
        found.refuse(&conf.at, &err);
    }
    // A module missing for want of a participant would show as a missing producer.
    if found.is_empty() {
        let report = rt.verify();
        for problem in &report.problems {
            found
                .problems
                .push(&places.problem(problem, &fallback), problem.to_string());
        }
    }
    found.into_result()?;
    let mut topics: Vec<String> = (d.subscribes.iter().map(|s| s.topic.clone()))
        .chain(d.publishes.iter().map(|p| p.topic.clone()))
        .chain(d.machines.iter().flat_map(|m| {
            [
                format!("fsm/{}/state", m.program.main),
                format!("fsm/{}/events", m.program.main),
            ]
        }))
        .collect();
    topics.sort();
    topics.dedup();
    rt.set_extras(describe_extras(&d, &files));
    Ok(System {
        name: rt.name().to_owned(),
        topics,
        files: files.iter().map(|f| f.path.as_ref().clone()).collect(),
        participant: participant.cloned(),
        description: d.description.clone(),
        display: d.display.iter().map(|n| n.name.clone()).collect(),
        machines,
        ports: d.ports,
        servers: std::sync::Mutex::new(Vec::new()),
        started: std::sync::Mutex::new(false),
        check_only: options.check,
        simulated: std::sync::Mutex::new((0.0, Vec::new())),
        runtime: rt,
    })
}

/// What the description adds to the runtime's own picture of itself, for tools
/// (`Runtime::describe`).
fn describe_extras(d: &super::decl::Description, files: &[SourceFile]) -> crate::describe::Extras {
    use crate::describe::{BindingDescription, MachineDescription};
    let binding = |topic: &str, mat: &str, habitat: &str, direction: &str| BindingDescription {
        topic: topic.to_owned(),
        mat: mat.to_owned(),
        habitat: habitat.to_owned(),
        direction: direction.to_owned(),
    };
    crate::describe::Extras {
        description: d.description.clone().unwrap_or_default(),
        files: files.iter().map(|f| f.path.display().to_string()).collect(),
        components: (d.components.iter())
            .map(|c| (c.name.name.clone(), c.type_name.name.clone()))
            .collect(),
        bindings: (d.subscribes.iter())
            .map(|s| binding(&s.topic, &s.mat.name, &s.habitat.name, "subscribe"))
            .chain(
                (d.publishes.iter())
                    .map(|p| binding(&p.topic, &p.mat.name, &p.habitat.name, "publish")),
            )
            .collect(),
        machines: (d.machines.iter())
            .map(|m| MachineDescription::of(&m.program))
            .collect(),
    }
}

/// `(category, group)`, its modules, where it was first named.
type GroupDecl<'a> = ((String, String), (Vec<&'a str>, Location));

/// The problems, in file order.
fn invalid(p: Diagnostics) -> SystemError {
    SystemError::Invalid(in_file_order(p))
}

/// `p` sorted by place, the first [`MAX_DIAGNOSTICS`](super::source::MAX_DIAGNOSTICS) kept.
fn in_file_order(mut p: Diagnostics) -> Diagnostics {
    p.0.sort_by(|a, b| {
        let (a, b) = (&a.location, &b.location);
        (a.file.as_path(), a.line, a.column).cmp(&(b.file.as_path(), b.line, b.column))
    });
    p.truncate();
    p
}

/// A state machine loaded and verified, started with the system.
pub(crate) struct PendingMachine {
    program: Program,
}

impl PendingMachine {
    /// The actions a description's state machines have: the runtime's (`switch`, `start`,
    /// `stop`, `reset`), `set CSMAT V1 V2 ...` (row-major values; 0 done, 1 refused) and
    /// `snapshot NAME [REASON]` (asks the black-box recorder `ndds record --snapshot S --name
    /// NAME` to write what it keeps; 0 asked, 1 without a network).
    fn actions(&self, rt: &Runtime, participant: Option<&Participant>) -> ActionSet {
        let mut set = ActionSet::runtime(rt);
        let participant = participant.cloned();
        set.add("snapshot", &[0, 1], move |arg| {
            let arg = arg.ok_or("`snapshot` needs the recorder's name")?;
            let (name, reason) = arg.split_once(' ').unwrap_or((arg, "state machine"));
            let Some(participant) = participant.clone() else {
                tracing::warn!("`snapshot {arg}`: the system runs without a network");
                return Ok(1);
            };
            snapshot(participant, name.to_owned(), reason.trim().to_owned());
            Ok(0)
        });
        let rt = rt.clone();
        set.add("set", &[0, 1], move |arg| {
            let arg = arg.ok_or("`set` needs a CSMat name and its values")?;
            let mut words = arg.split_whitespace();
            let name = words.next().ok_or("`set` needs a CSMat name")?;
            let values: Result<Vec<f64>, _> = words.map(str::parse::<f64>).collect();
            let Ok(values) = values else {
                tracing::warn!("`set {arg}`: the values are not numbers");
                return Ok(1);
            };
            // The loader checked that `name` is a CSMat of the system.
            let result = rt.mat(name).write().copy_from_slice(&values);
            Ok(match result {
                Ok(()) => 0,
                Err(err) => {
                    tracing::warn!("`set {arg}`: {err}");
                    1
                }
            })
        });
        set
    }

    pub(crate) fn start(
        &self,
        rt: &Runtime,
        participant: Option<&Participant>,
    ) -> Result<StateMachine, FsmError> {
        let actions = self.actions(rt, participant);
        match participant {
            Some(p) => StateMachine::start_on(self.program.clone(), actions, p),
            None => StateMachine::start(self.program.clone(), actions),
        }
    }
}

/// Asks the black-box recorder `name` for a snapshot, on a thread of its own so the machine
/// never waits for the file to be written: the recorder owns port `snapshot.NAME` (request:
/// the reason; reply: the file written, or why not; docs/recording.md), and the answer is
/// logged.
fn snapshot(participant: Participant, name: String, reason: String) {
    let spawned = std::thread::Builder::new()
        .name("ndds-snapshot".into())
        .spawn(move || {
            let port = format!("snapshot.{name}");
            let answer = ndds_client::ports::PortUser::<String, Result<String, String>>::declare(
                &participant,
                &port,
                "state-machine",
            )
            .and_then(|user| user.send(&reason, std::time::Duration::from_secs(60)));
            match answer {
                Ok(Ok(path)) => tracing::info!(recorder = name, path, "snapshot written"),
                Ok(Err(why)) => tracing::warn!(recorder = name, why, "snapshot not written"),
                Err(err) => tracing::warn!(recorder = name, %err, "snapshot not asked"),
            }
        });
    if let Err(err) = spawned {
        tracing::warn!(%err, "snapshot: no thread to ask the recorder");
    }
}

/// Sends a stimulus to a state machine when a CSMat crosses a threshold: on each sample where
/// the condition holds after it did not (the largest absolute element above `above`, or below
/// `below`). Stimuli sent before the machine runs, or refused by a full queue, are counted in
/// the module's errors.
struct Trigger {
    input: Mat,
    above: Option<f64>,
    below: Option<f64>,
    machine: MachineSlot,
    stimulus: Stimulus,
    was: bool,
}

impl Trigger {
    fn new(b: &mut Binder<'_>, t: &TriggerDecl, machine: MachineSlot) -> Self {
        Self {
            input: b.input(&t.input.name, Shape::Any),
            above: t.above,
            below: t.below,
            machine,
            stimulus: t.stimulus.clone(),
            was: false,
        }
    }
}

impl SampleModule for Trigger {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let norm = self.input.read().matrix().amax();
        let now = self.above.is_none_or(|x| norm > x) && self.below.is_none_or(|x| norm < x);
        let rising = now && !self.was;
        self.was = now;
        if !rising {
            return Ok(());
        }
        match self.machine.get().and_then(std::sync::Weak::upgrade) {
            Some(machine) => machine
                .send(self.stimulus.clone())
                .map_err(|e| ModuleError::Failed(e.to_string())),
            None => Err(ModuleError::Failed(format!(
                "stimulus `{}`: its state machine is not running",
                self.stimulus.name
            ))),
        }
    }

    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        self.was = false;
        Ok(())
    }
}

/// Serves a port declared in a description: requests are strings (configuration names or
/// stimuli), replies `Ok(what happened)` or `Err(why not)`.
pub(crate) struct PortServer {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

/// A port's reply.
pub type PortReply = ndds_client::ports::CommandReply;

impl PortServer {
    pub(crate) fn start(
        system: &System,
        participant: &Participant,
        port: &PortDecl,
    ) -> Result<Self, SystemError> {
        let taken =
            ndds_client::ports::owners_elsewhere(participant, &port.name.name).map_err(|e| {
                SystemError::Port {
                    port: port.name.name.clone(),
                    message: e.to_string(),
                }
            })?;
        if let Some(owner) = taken.first() {
            return Err(SystemError::Port {
                port: port.name.name.clone(),
                message: format!(
                    "already owned by {owner}; a port has one owner: stop that one or rename \
                     this port"
                ),
            });
        }
        let owner: PortOwner<String, PortReply> = PortOwner::declare_with(
            participant,
            &port.name.name,
            system.name(),
            port.restrictions.clone(),
        )
        .map_err(|e| SystemError::Port {
            port: port.name.name.clone(),
            message: e.to_string(),
        })?;
        let stop = Arc::new(AtomicBool::new(false));
        let rt = system.runtime().clone();
        let machine = match &port.serves {
            Serves::Stimuli(m) => system.machines.get(m).map(|entry| Arc::clone(&entry.slot)),
            Serves::Configuration => None,
        };
        let serves = port.serves.clone();
        let flag = Arc::clone(&stop);
        let name = port.name.name.clone();
        let thread = std::thread::Builder::new()
            .name(format!("port {name}"))
            .spawn(move || {
                let mut failing = None;
                while !flag.load(Ordering::Acquire) {
                    let Some((request, reply)) = owner.serve_next(PORT_POLL, &mut failing) else {
                        continue;
                    };
                    let answer = match &serves {
                        Serves::Configuration => rt.switch_explained(request.trim()),
                        Serves::Stimuli(m) => match machine
                            .as_ref()
                            .and_then(|s| s.get())
                            .and_then(std::sync::Weak::upgrade)
                        {
                            Some(sm) => sm
                                .send(Stimulus::parse(&request))
                                .map(|()| format!("sent `{}` to `{m}`", request.trim()))
                                .map_err(|e| e.to_string()),
                            None => Err(format!("state machine `{m}` is not running")),
                        },
                    };
                    if let Err(err) = reply.reply(&answer) {
                        tracing::warn!(port = %name, "reply: {err}");
                    }
                }
            })
            .map_err(|e| SystemError::Port {
                port: port.name.name.clone(),
                message: e.to_string(),
            })?;
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }

    pub(crate) fn stop(mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

//! The state machine itself, without threads or sockets: stimuli in, fired transitions and
//! faults out.
//!
//! Processing one stimulus:
//! 1. A condition stimulus sets its value, a latched one is remembered, a transient one exists
//!    for this step only. Undeclared stimuli, a condition without a value or a value on another
//!    kind are faults and change nothing.
//! 2. Transitions are tried in priority order: the innermost running machine's transitions
//!    from its current state, then its global ones (`from = "*"`), then the global ones of the
//!    machines that called it (innermost first; firing one ends the calls below it), then, if
//!    none matched, the innermost machine's wildcard ones (state, then global). The first
//!    whose condition holds fires.
//! 3. Firing consumes the latched stimuli its condition names, runs its action and takes the
//!    successor of the action's code. A `call` enters a sub-machine at its start state; when a
//!    sub-machine reaches a return state, the caller's transition continues with that state's
//!    code. A code without successor, a failed action, an unknown machine, a call with
//!    [`MAX_CALL_DEPTH`] machines running already, or more than [`MAX_STEPS`] transitions for
//!    one stimulus is a fault: every call is ended and the main machine goes to the program's
//!    error state.
//! 4. Latched stimuli still waiting are tried again in the new state (that is what they wait
//!    for): a transition whose condition names a waiting latched stimulus may fire. A transient
//!    stimulus no transition took vanishes.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::def::{ActionRef, Program, StimulusKind, TransitionDef};
use super::expr::Stimuli;

/// Machines running at once at most (the main one and the machines it called); a call beyond
/// is a fault.
pub const MAX_CALL_DEPTH: usize = 16;
/// Transitions one stimulus may cause at most (a cycle of latched re-tries is a fault).
pub const MAX_STEPS: usize = 64;

/// A stimulus, as queued.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Stimulus {
    /// The stimulus.
    pub name: String,
    /// Its value (conditions only).
    pub value: Option<String>,
}

impl Stimulus {
    /// A transient or latched stimulus.
    pub fn event(name: &str) -> Self {
        Self {
            name: name.to_owned(),
            value: None,
        }
    }

    /// A condition's new value.
    pub fn condition(name: &str, value: &str) -> Self {
        Self {
            name: name.to_owned(),
            value: Some(value.to_owned()),
        }
    }

    /// Parses `NAME` or `NAME=VALUE`.
    pub fn parse(text: &str) -> Self {
        match text.split_once('=') {
            Some((name, value)) => Self::condition(name.trim(), value.trim()),
            None => Self::event(text.trim()),
        }
    }
}

/// Runs the named actions of transitions.
pub trait Actions {
    /// Runs `name` with `argument`; the code selects the next state. An error is a fault (the
    /// machine goes to the error state).
    fn run(&mut self, name: &str, argument: Option<&str>) -> Result<i32, String>;
}

impl<F: FnMut(&str, Option<&str>) -> Result<i32, String>> Actions for F {
    fn run(&mut self, name: &str, argument: Option<&str>) -> Result<i32, String> {
        self(name, argument)
    }
}

/// One transition that fired.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Fired {
    /// The machine it belongs to.
    pub machine: String,
    /// The state it left.
    pub from: String,
    /// The state it entered (for a call: the sub-machine's start state).
    pub to: String,
    /// Its condition.
    pub condition: String,
    /// Its action.
    pub action: String,
    /// The code that chose the successor (none for a call still running).
    pub code: Option<i32>,
}

/// Something that went wrong while processing a stimulus.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, thiserror::Error)]
#[non_exhaustive]
pub enum Fault {
    /// A stimulus the program does not declare.
    #[error("unknown stimulus `{0}`")]
    UnknownStimulus(String),
    /// A condition sent without a value.
    #[error("condition `{0}` needs a value (`{0}=VALUE`)")]
    MissingValue(String),
    /// A transient or latched stimulus sent with a value.
    #[error("stimulus `{0}` is not a condition and takes no value")]
    UnexpectedValue(String),
    /// An action's code has no successor.
    #[error("machine `{machine}`, state `{state}`: code {code} of `{action}` has no successor")]
    NoSuccessor {
        /// The machine.
        machine: String,
        /// The state the transition left.
        state: String,
        /// The code.
        code: i32,
        /// The action.
        action: String,
    },
    /// An action failed.
    #[error("machine `{machine}`: action `{action}` failed: {reason}")]
    ActionFailed {
        /// The machine.
        machine: String,
        /// The action.
        action: String,
        /// Why.
        reason: String,
    },
    /// A call to a machine that does not exist.
    #[error("machine `{machine}` calls unknown machine `{called}`")]
    UnknownMachine {
        /// The caller.
        machine: String,
        /// The callee.
        called: String,
    },
    /// A call with [`MAX_CALL_DEPTH`] machines running already.
    #[error(
        "machine `{machine}`: more than {MAX_CALL_DEPTH} machines running at once (recursion?)"
    )]
    RecursionLimit {
        /// The machine that made the call.
        machine: String,
    },
    /// More than [`MAX_STEPS`] transitions for one stimulus.
    #[error("more than {MAX_STEPS} transitions for one stimulus (a cycle of latched stimuli?)")]
    Runaway,
}

/// What processing one stimulus did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Outcome {
    /// Transitions fired, in order.
    pub fired: Vec<Fired>,
    /// Faults.
    pub faults: Vec<Fault>,
    /// A transient stimulus that no transition took (it is gone).
    pub vanished: bool,
}

#[derive(Clone, Debug, PartialEq, Eq)]
struct Frame {
    machine: String,
    state: String,
    /// Index of the caller's transition (in the machine below) for a called machine.
    caller: Option<usize>,
}

/// A running state program.
#[derive(Clone, Debug)]
pub struct Machine {
    program: Arc<Program>,
    stack: Vec<Frame>,
    latched: BTreeSet<String>,
    conditions: BTreeMap<String, String>,
    last: Option<Fired>,
    transitions: u64,
    faults: u64,
    last_fault: Option<Fault>,
}

/// The memory a condition is evaluated against.
struct View<'a> {
    latched: &'a BTreeSet<String>,
    conditions: &'a BTreeMap<String, String>,
    transient: Option<&'a str>,
}

impl Stimuli for View<'_> {
    fn present(&self, name: &str) -> bool {
        self.transient == Some(name)
            || self.latched.contains(name)
            || self.conditions.contains_key(name)
    }

    fn value(&self, name: &str) -> Option<&str> {
        self.conditions.get(name).map(String::as_str)
    }
}

/// A snapshot of a machine (published on its state topic).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MachineState {
    /// The program's main machine.
    pub machine: String,
    /// The current state of the innermost running machine.
    pub state: String,
    /// `machine:state` of every running machine, main first.
    pub stack: Vec<String>,
    /// The last transition that fired.
    pub last_transition: Option<Fired>,
    /// Latched stimuli waiting for a transition.
    pub latched: Vec<String>,
    /// Conditions and their values.
    pub conditions: Vec<(String, String)>,
    /// Transitions fired so far.
    pub transitions: u64,
    /// Faults so far.
    pub faults: u64,
    /// The last fault, in words.
    pub last_fault: String,
    /// Stimuli refused before reaching the machine (queue full, undeclared, oversized).
    pub dropped: u64,
    /// The stimuli the machine accepts (filled in by [`StateMachine`](super::StateMachine)).
    pub accepts: Vec<super::vocabulary::Accepted>,
}

impl Machine {
    /// The program at the main machine's start state.
    pub fn new(program: Arc<Program>) -> Self {
        let start = program
            .machines
            .get(&program.main)
            .map(|m| m.start.clone())
            .unwrap_or_else(|| program.error_state.clone());
        Self {
            stack: vec![Frame {
                machine: program.main.clone(),
                state: start,
                caller: None,
            }],
            program,
            latched: BTreeSet::new(),
            conditions: BTreeMap::new(),
            last: None,
            transitions: 0,
            faults: 0,
            last_fault: None,
        }
    }

    /// The program.
    pub fn program(&self) -> &Arc<Program> {
        &self.program
    }

    /// The current state of the innermost running machine.
    pub fn state(&self) -> &str {
        self.stack.last().map_or("", |f| f.state.as_str())
    }

    /// `(machine, state)` of every running machine, main first.
    pub fn stack(&self) -> Vec<(String, String)> {
        self.stack
            .iter()
            .map(|f| (f.machine.clone(), f.state.clone()))
            .collect()
    }

    /// The value of a condition.
    pub fn condition(&self, name: &str) -> Option<&str> {
        self.conditions.get(name).map(String::as_str)
    }

    /// Whether a latched stimulus is waiting.
    pub fn is_latched(&self, name: &str) -> bool {
        self.latched.contains(name)
    }

    /// A snapshot.
    pub fn snapshot(&self) -> MachineState {
        MachineState {
            machine: self.program.main.clone(),
            state: self.state().to_owned(),
            stack: self
                .stack
                .iter()
                .map(|f| format!("{}:{}", f.machine, f.state))
                .collect(),
            last_transition: self.last.clone(),
            latched: self.latched.iter().cloned().collect(),
            conditions: self
                .conditions
                .iter()
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect(),
            transitions: self.transitions,
            faults: self.faults,
            last_fault: self
                .last_fault
                .as_ref()
                .map(ToString::to_string)
                .unwrap_or_default(),
            dropped: 0,
            accepts: Vec::new(),
        }
    }

    /// Processes one stimulus (see the module docs).
    pub fn handle(&mut self, stimulus: &Stimulus, actions: &mut dyn Actions) -> Outcome {
        let mut out = Outcome::default();
        let name = stimulus.name.as_str();
        let kind = match self.program.stimuli.get(name) {
            Some(kind) => *kind,
            None => {
                self.fault(&mut out, Fault::UnknownStimulus(name.to_owned()));
                return out;
            }
        };
        let mut transient = None;
        match (kind, &stimulus.value) {
            (StimulusKind::Condition, Some(value)) => {
                self.conditions.insert(name.to_owned(), value.clone());
            }
            (StimulusKind::Condition, None) => {
                self.fault(&mut out, Fault::MissingValue(name.to_owned()));
                return out;
            }
            (_, Some(_)) => {
                self.fault(&mut out, Fault::UnexpectedValue(name.to_owned()));
                return out;
            }
            (StimulusKind::Latched, None) => {
                self.latched.insert(name.to_owned());
            }
            (StimulusKind::Transient, None) => transient = Some(name.to_owned()),
        }
        let mut arriving = Some((name.to_owned(), kind));
        for _ in 0..MAX_STEPS {
            let Some((depth, index, wildcard)) =
                self.select(transient.as_deref(), arriving.is_some())
            else {
                if transient.is_some() {
                    out.vanished = true;
                }
                return out;
            };
            if wildcard && let Some((name, StimulusKind::Latched)) = &arriving {
                self.latched.remove(name);
            }
            // An outer machine's global transition ends the calls below it.
            self.stack.truncate(depth + 1);
            self.fire(index, actions, &mut out);
            transient = None;
            arriving = None;
        }
        self.fail(Fault::Runaway, &mut out);
        out
    }

    /// The transition to fire: the depth of the machine it belongs to (in the call stack), its
    /// index there, and whether it is a wildcard one. The innermost machine's state and global
    /// transitions come first, then the global transitions of the machines that called it
    /// (innermost first: an outer `Abort` still works during a call), then wildcards.
    fn select(&self, transient: Option<&str>, arriving: bool) -> Option<(usize, usize, bool)> {
        let view = View {
            latched: &self.latched,
            conditions: &self.conditions,
            transient,
        };
        // Without an arriving stimulus only waiting latched stimuli may fire a transition.
        let eligible = |t: &TransitionDef| {
            arriving
                || t.when
                    .positive_names()
                    .iter()
                    .any(|n| self.latched.contains(*n))
        };
        let innermost = self.stack.len().checked_sub(1)?;
        let find = |depth: usize, global: bool, wildcard: bool| {
            let frame = &self.stack[depth];
            let machine = self.program.machines.get(&frame.machine)?;
            machine.transitions.iter().position(|t| {
                let applies = match &t.from {
                    Some(from) => !global && *from == frame.state,
                    None => global,
                };
                applies
                    && t.when.has_wildcard() == wildcard
                    && eligible(t)
                    && t.when.eval(&view, wildcard)
            })
        };
        let mut order: Vec<(usize, bool, bool)> =
            vec![(innermost, false, false), (innermost, true, false)];
        order.extend((0..innermost).rev().map(|depth| (depth, true, false)));
        if arriving {
            order.push((innermost, false, true));
            order.push((innermost, true, true));
        }
        order.into_iter().find_map(|(depth, global, wildcard)| {
            find(depth, global, wildcard).map(|index| (depth, index, wildcard))
        })
    }

    fn fire(&mut self, index: usize, actions: &mut dyn Actions, out: &mut Outcome) {
        let program = Arc::clone(&self.program);
        let depth = self.stack.len() - 1;
        let frame = self.stack[depth].clone();
        let Some(t) = program
            .machines
            .get(&frame.machine)
            .and_then(|m| m.transitions.get(index))
        else {
            return;
        };
        for name in t.when.positive_names() {
            if program.stimuli.get(name) == Some(&StimulusKind::Latched) {
                self.latched.remove(name);
            }
        }
        match &t.action {
            ActionRef::Call(sub) => {
                let Some(callee) = program.machines.get(sub) else {
                    let fault = Fault::UnknownMachine {
                        machine: frame.machine.clone(),
                        called: sub.clone(),
                    };
                    return self.fail(fault, out);
                };
                if self.stack.len() >= MAX_CALL_DEPTH {
                    let fault = Fault::RecursionLimit {
                        machine: frame.machine.clone(),
                    };
                    return self.fail(fault, out);
                }
                self.record(
                    Fired {
                        machine: frame.machine.clone(),
                        from: frame.state.clone(),
                        to: format!("{sub}:{}", callee.start),
                        condition: t.when.to_string(),
                        action: t.action.to_string(),
                        code: None,
                    },
                    out,
                );
                self.stack.push(Frame {
                    machine: sub.clone(),
                    state: callee.start.clone(),
                    caller: Some(index),
                });
                self.unwind_returns(actions, out);
            }
            ActionRef::None => self.succeed(index, 0, out, actions),
            ActionRef::Named { name, argument } => match actions.run(name, argument.as_deref()) {
                Ok(code) => self.succeed(index, code, out, actions),
                Err(reason) => {
                    let fault = Fault::ActionFailed {
                        machine: frame.machine.clone(),
                        action: t.action.to_string(),
                        reason,
                    };
                    self.fail(fault, out);
                }
            },
        }
    }

    /// Transition `index` of the innermost machine produced `code`: go to its successor.
    fn succeed(&mut self, index: usize, code: i32, out: &mut Outcome, actions: &mut dyn Actions) {
        let program = Arc::clone(&self.program);
        let Some(frame) = self.stack.last().cloned() else {
            return;
        };
        let Some(t) = program
            .machines
            .get(&frame.machine)
            .and_then(|m| m.transitions.get(index))
        else {
            return;
        };
        let Some(next) = t.next.get(&code) else {
            let fault = Fault::NoSuccessor {
                machine: frame.machine.clone(),
                state: frame.state.clone(),
                code,
                action: t.action.to_string(),
            };
            return self.fail(fault, out);
        };
        self.record(
            Fired {
                machine: frame.machine.clone(),
                from: frame.state.clone(),
                to: next.clone(),
                condition: t.when.to_string(),
                action: t.action.to_string(),
                code: Some(code),
            },
            out,
        );
        if let Some(top) = self.stack.last_mut() {
            top.state = next.clone();
        }
        self.unwind_returns(actions, out);
    }

    /// While a called machine sits in a return state, returns its code to the caller.
    fn unwind_returns(&mut self, actions: &mut dyn Actions, out: &mut Outcome) {
        if self.stack.len() < 2 {
            return;
        }
        let Some(top) = self.stack.last() else { return };
        let code = self
            .program
            .machines
            .get(&top.machine)
            .and_then(|m| m.returns.get(&top.state))
            .copied();
        if let Some(code) = code {
            let frame = self.stack.pop().expect("two frames");
            if let Some(caller) = frame.caller {
                self.succeed(caller, code, out, actions);
            }
        }
    }

    fn fail(&mut self, fault: Fault, out: &mut Outcome) {
        let frame = self.stack.last().cloned();
        self.stack.truncate(1);
        let error = self.program.error_state.clone();
        if let (Some(frame), Some(main)) = (frame, self.stack.first_mut()) {
            self.last = Some(Fired {
                machine: frame.machine,
                from: frame.state,
                to: error.clone(),
                condition: String::new(),
                action: "fault".into(),
                code: None,
            });
            main.state = error;
            self.transitions += 1;
            out.fired.extend(self.last.clone());
        }
        self.fault(out, fault);
    }

    fn fault(&mut self, out: &mut Outcome, fault: Fault) {
        self.faults += 1;
        tracing::warn!(machine = %self.program.main, fault = %fault, "state machine fault");
        self.last_fault = Some(fault.clone());
        out.faults.push(fault);
    }

    fn record(&mut self, fired: Fired, out: &mut Outcome) {
        self.transitions += 1;
        self.last = Some(fired.clone());
        out.fired.push(fired);
    }
}

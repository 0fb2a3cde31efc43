//! State programs: stimuli, machines, states and transitions, built in code or loaded from
//! TOML.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::expr::{Expr, ParseError};

/// The three kinds of stimuli of ControlShell's state machines.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StimulusKind {
    /// No value; exists only while it is processed.
    Transient,
    /// No value; persists until a transition whose condition names it fires.
    Latched,
    /// A string value that persists until changed (`Object = Visible`).
    Condition,
}

/// What a transition does when it fires.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ActionRef {
    /// Nothing: the code is 0.
    None,
    /// A registered action, with an optional argument (`switch endptLQG`).
    Named {
        /// The action's name.
        name: String,
        /// Its argument.
        argument: Option<String>,
    },
    /// Runs sub-machine `.0` until it reaches a return state; that state's code is the code.
    Call(String),
}

impl ActionRef {
    /// Parses `"none"`, `"call SUB"` or `"NAME [ARGUMENT]"`.
    pub fn parse(text: &str) -> ActionRef {
        let text = text.trim();
        let (word, rest) = match text.split_once(char::is_whitespace) {
            Some((w, r)) => (w, Some(r.trim()).filter(|r| !r.is_empty())),
            None => (text, None),
        };
        match (word, rest) {
            ("" | "none", None) => ActionRef::None,
            ("call", Some(sub)) => ActionRef::Call(sub.to_owned()),
            (name, argument) => ActionRef::Named {
                name: name.to_owned(),
                argument: argument.map(str::to_owned),
            },
        }
    }
}

impl std::fmt::Display for ActionRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ActionRef::None => f.write_str("none"),
            ActionRef::Call(sub) => write!(f, "call {sub}"),
            ActionRef::Named {
                name,
                argument: Some(a),
            } => write!(f, "{name} {a}"),
            ActionRef::Named {
                name,
                argument: None,
            } => f.write_str(name),
        }
    }
}

/// One transition.
#[derive(Clone, Debug, PartialEq)]
pub struct TransitionDef {
    /// The state it leaves, or `None` for a global transition (valid from every state).
    pub from: Option<String>,
    /// Its condition.
    pub when: Expr,
    /// What it runs.
    pub action: ActionRef,
    /// Return code → next state.
    pub next: BTreeMap<i32, String>,
}

/// One machine: a named graph of states.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MachineDef {
    /// Its name.
    pub name: String,
    /// The state it starts in.
    pub start: String,
    /// Declared states (the start state and every successor must be among them).
    pub states: Vec<String>,
    /// Return states of a sub-machine, with the code each returns to the caller.
    pub returns: BTreeMap<String, i32>,
    /// Transitions, in priority order: the first matching one fires (state transitions before
    /// global ones, wildcard ones last).
    pub transitions: Vec<TransitionDef>,
}

/// A whole state program: the stimuli, the main machine and its sub-machines.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    /// The machine that runs first (its name also names the program on the network).
    pub main: String,
    /// The state the main machine enters when something goes wrong (a return code without a
    /// successor, a failed action, a recursion too deep).
    pub error_state: String,
    /// Declared stimuli.
    pub stimuli: BTreeMap<String, StimulusKind>,
    /// Machines by name.
    pub machines: BTreeMap<String, MachineDef>,
}

/// A program that cannot be built as described.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DefError {
    /// A condition that does not parse.
    #[error("machine `{machine}`, transition {index} (from {from}): {source}")]
    Condition {
        /// The machine.
        machine: String,
        /// The transition's index in the machine (0-based).
        index: usize,
        /// Its `from`.
        from: String,
        /// The parse error.
        source: ParseError,
    },
    /// A return code that is not an integer.
    #[error("machine `{machine}`, transition {index}: return code `{code}` is not an integer")]
    Code {
        /// The machine.
        machine: String,
        /// The transition's index.
        index: usize,
        /// The key as written.
        code: String,
    },
    /// TOML that does not parse or does not fit the description format.
    #[error("{0}")]
    Toml(String),
    /// Two machines of one name.
    #[error("machine `{0}` is defined twice")]
    DuplicateMachine(String),
}

impl Program {
    /// An empty program whose main machine is `main` (created with start state `start`).
    pub fn new(main: &str, start: &str) -> Self {
        let mut machines = BTreeMap::new();
        machines.insert(
            main.to_owned(),
            MachineDef {
                name: main.to_owned(),
                start: start.to_owned(),
                states: vec![start.to_owned()],
                ..MachineDef::default()
            },
        );
        Self {
            main: main.to_owned(),
            error_state: "Error".to_owned(),
            stimuli: BTreeMap::new(),
            machines,
        }
    }

    /// Declares a stimulus.
    pub fn stimulus(&mut self, name: &str, kind: StimulusKind) -> &mut Self {
        self.stimuli.insert(name.to_owned(), kind);
        self
    }

    /// The machine named `name`, created with start state `start` if it does not exist.
    pub fn machine(&mut self, name: &str, start: &str) -> &mut MachineDef {
        self.machines
            .entry(name.to_owned())
            .or_insert_with(|| MachineDef {
                name: name.to_owned(),
                start: start.to_owned(),
                states: vec![start.to_owned()],
                ..MachineDef::default()
            })
    }

    /// Loads a program from TOML (see the module docs of [`fsm`](super) for the format).
    pub fn from_toml(text: &str) -> Result<Program, DefError> {
        let file: FileProgram = toml::from_str(text).map_err(|e| DefError::Toml(e.to_string()))?;
        let mut program = Program {
            main: file.main,
            error_state: file.error_state.unwrap_or_else(|| "Error".to_owned()),
            stimuli: file.stimuli,
            machines: BTreeMap::new(),
        };
        for machine in file.machine {
            let mut states = machine.states;
            for state in std::iter::once(&machine.start).chain(machine.returns.keys()) {
                if !states.contains(state) {
                    states.push(state.clone());
                }
            }
            let mut def = MachineDef {
                name: machine.name.clone(),
                start: machine.start,
                states,
                returns: machine.returns,
                transitions: Vec::new(),
            };
            for (index, t) in machine.transition.into_iter().enumerate() {
                let from = if t.from == "*" {
                    None
                } else {
                    Some(t.from.clone())
                };
                let when = Expr::parse(&t.when).map_err(|source| DefError::Condition {
                    machine: machine.name.clone(),
                    index,
                    from: t.from.clone(),
                    source,
                })?;
                let mut next = BTreeMap::new();
                for (code, state) in t.next {
                    let code: i32 = code.trim().parse().map_err(|_| DefError::Code {
                        machine: machine.name.clone(),
                        index,
                        code: code.clone(),
                    })?;
                    next.insert(code, state);
                }
                def.transitions.push(TransitionDef {
                    from,
                    when,
                    action: ActionRef::parse(t.action.as_deref().unwrap_or("none")),
                    next,
                });
            }
            if program.machines.insert(machine.name.clone(), def).is_some() {
                return Err(DefError::DuplicateMachine(machine.name));
            }
        }
        Ok(program)
    }
}

impl MachineDef {
    /// Declares states.
    pub fn states(&mut self, states: &[&str]) -> &mut Self {
        for state in states {
            if !self.states.iter().any(|s| s == state) {
                self.states.push((*state).to_owned());
            }
        }
        self
    }

    /// Makes `state` a return state with `code` (for sub-machines).
    pub fn returns(&mut self, state: &str, code: i32) -> &mut Self {
        self.states(&[state]);
        self.returns.insert(state.to_owned(), code);
        self
    }

    /// Adds a transition from `from` (`"*"`: global) on `when`, running `action`
    /// (`"none"`, `"call SUB"`, `"NAME [ARG]"`), with `next` as return code → state.
    pub fn transition(
        &mut self,
        from: &str,
        when: &str,
        action: &str,
        next: &[(i32, &str)],
    ) -> Result<&mut Self, ParseError> {
        let when = Expr::parse(when)?;
        self.transitions.push(TransitionDef {
            from: (from != "*").then(|| from.to_owned()),
            when,
            action: ActionRef::parse(action),
            next: next.iter().map(|(c, s)| (*c, (*s).to_owned())).collect(),
        });
        Ok(self)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileProgram {
    main: String,
    error_state: Option<String>,
    #[serde(default)]
    stimuli: BTreeMap<String, StimulusKind>,
    #[serde(default)]
    machine: Vec<FileMachine>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileMachine {
    name: String,
    start: String,
    #[serde(default)]
    states: Vec<String>,
    #[serde(default)]
    returns: BTreeMap<String, i32>,
    #[serde(default)]
    transition: Vec<FileTransition>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileTransition {
    from: String,
    when: String,
    action: Option<String>,
    #[serde(default)]
    next: BTreeMap<String, String>,
}

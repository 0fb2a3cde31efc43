//! What would go wrong in a state program, found before it runs.

use std::collections::{BTreeSet, VecDeque};
use std::fmt;

use super::def::{ActionRef, Program, StimulusKind};
use super::expr::Expr;

/// One problem found by [`verify`].
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FsmProblem {
    /// The main machine is not defined.
    NoMain(String),
    /// A state that is not declared (as a start, a transition's `from`, a successor or a
    /// return state).
    UnknownState {
        /// The machine.
        machine: String,
        /// The state.
        state: String,
        /// Where it is named.
        context: String,
    },
    /// A condition naming a stimulus that is not declared.
    UnknownStimulus {
        /// The machine.
        machine: String,
        /// The transition (0-based).
        transition: usize,
        /// The stimulus.
        stimulus: String,
    },
    /// `Name = value` on a stimulus that is not a condition.
    NotACondition {
        /// The machine.
        machine: String,
        /// The transition.
        transition: usize,
        /// The stimulus.
        stimulus: String,
    },
    /// A call to a machine that is not defined.
    UnknownMachine {
        /// The machine.
        machine: String,
        /// The transition.
        transition: usize,
        /// The machine called.
        called: String,
    },
    /// A call of a machine that has no return state: the caller never continues.
    NoReturn {
        /// The machine.
        machine: String,
        /// The transition.
        transition: usize,
        /// The machine called.
        called: String,
    },
    /// A named action nobody provides.
    UnknownAction {
        /// The machine.
        machine: String,
        /// The transition.
        transition: usize,
        /// The action.
        action: String,
    },
    /// A code the action can return that has no successor.
    CodeWithoutSuccessor {
        /// The machine.
        machine: String,
        /// The transition.
        transition: usize,
        /// The code.
        code: i32,
    },
    /// A declared state no transition leads to.
    Unreachable {
        /// The machine.
        machine: String,
        /// The state.
        state: String,
    },
}

impl fmt::Display for FsmProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FsmProblem::NoMain(main) => write!(f, "the main machine `{main}` is not defined"),
            FsmProblem::UnknownState {
                machine,
                state,
                context,
            } => write!(
                f,
                "machine `{machine}`: unknown state `{state}` ({context})"
            ),
            FsmProblem::UnknownStimulus {
                machine,
                transition,
                stimulus,
            } => write!(
                f,
                "machine `{machine}`, transition {transition}: unknown stimulus `{stimulus}`"
            ),
            FsmProblem::NotACondition {
                machine,
                transition,
                stimulus,
            } => write!(
                f,
                "machine `{machine}`, transition {transition}: `{stimulus}` is compared to a value but is not a condition"
            ),
            FsmProblem::UnknownMachine {
                machine,
                transition,
                called,
            } => write!(
                f,
                "machine `{machine}`, transition {transition}: calls unknown machine `{called}`"
            ),
            FsmProblem::NoReturn {
                machine,
                transition,
                called,
            } => write!(
                f,
                "machine `{machine}`, transition {transition}: calls `{called}`, which has no return state"
            ),
            FsmProblem::UnknownAction {
                machine,
                transition,
                action,
            } => write!(
                f,
                "machine `{machine}`, transition {transition}: unknown action `{action}`"
            ),
            FsmProblem::CodeWithoutSuccessor {
                machine,
                transition,
                code,
            } => write!(
                f,
                "machine `{machine}`, transition {transition}: return code {code} has no successor"
            ),
            FsmProblem::Unreachable { machine, state } => {
                write!(f, "machine `{machine}`: state `{state}` is unreachable")
            }
        }
    }
}

/// Checks `program`. `action_codes(name)` gives the codes a named action can return, or `None`
/// for an action nobody provides.
pub fn verify(
    program: &Program,
    action_codes: &dyn Fn(&str) -> Option<Vec<i32>>,
) -> Vec<FsmProblem> {
    let mut problems = Vec::new();
    if !program.machines.contains_key(&program.main) {
        problems.push(FsmProblem::NoMain(program.main.clone()));
    }
    for (name, machine) in &program.machines {
        let mut states: BTreeSet<&str> = machine.states.iter().map(String::as_str).collect();
        if *name == program.main {
            states.insert(&program.error_state);
        }
        let mut unknown = |state: &str, context: String| {
            if !states.contains(state) {
                problems.push(FsmProblem::UnknownState {
                    machine: name.clone(),
                    state: state.to_owned(),
                    context,
                });
            }
        };
        unknown(&machine.start, "start state".into());
        for state in machine.returns.keys() {
            unknown(state, "return state".into());
        }
        for (i, t) in machine.transitions.iter().enumerate() {
            if let Some(from) = &t.from {
                unknown(from, format!("`from` of transition {i}"));
            }
            for (code, next) in &t.next {
                unknown(next, format!("successor of code {code} in transition {i}"));
            }
        }
        for (i, t) in machine.transitions.iter().enumerate() {
            stimuli(program, name, i, &t.when, &mut problems);
            let codes = match &t.action {
                ActionRef::None => Some(vec![0]),
                ActionRef::Call(sub) => match program.machines.get(sub) {
                    Some(callee) if callee.returns.is_empty() => {
                        problems.push(FsmProblem::NoReturn {
                            machine: name.clone(),
                            transition: i,
                            called: sub.clone(),
                        });
                        None
                    }
                    Some(callee) => Some(callee.returns.values().copied().collect()),
                    None => {
                        problems.push(FsmProblem::UnknownMachine {
                            machine: name.clone(),
                            transition: i,
                            called: sub.clone(),
                        });
                        None
                    }
                },
                ActionRef::Named { name: action, .. } => {
                    let codes = action_codes(action);
                    if codes.is_none() {
                        problems.push(FsmProblem::UnknownAction {
                            machine: name.clone(),
                            transition: i,
                            action: action.clone(),
                        });
                    }
                    codes
                }
            };
            let mut codes = codes.unwrap_or_default();
            codes.sort_unstable();
            codes.dedup();
            for code in codes {
                if !t.next.contains_key(&code) {
                    problems.push(FsmProblem::CodeWithoutSuccessor {
                        machine: name.clone(),
                        transition: i,
                        code,
                    });
                }
            }
        }
        for state in unreachable(program, name) {
            problems.push(FsmProblem::Unreachable {
                machine: name.clone(),
                state,
            });
        }
    }
    problems
}

fn stimuli(
    program: &Program,
    machine: &str,
    transition: usize,
    expr: &Expr,
    problems: &mut Vec<FsmProblem>,
) {
    let mut compared = Vec::new();
    collect_compared(expr, &mut compared);
    for name in expr.names() {
        match program.stimuli.get(name) {
            None => problems.push(FsmProblem::UnknownStimulus {
                machine: machine.to_owned(),
                transition,
                stimulus: name.to_owned(),
            }),
            Some(kind) if *kind != StimulusKind::Condition && compared.contains(&name) => problems
                .push(FsmProblem::NotACondition {
                    machine: machine.to_owned(),
                    transition,
                    stimulus: name.to_owned(),
                }),
            Some(_) => {}
        }
    }
}

fn collect_compared<'a>(expr: &'a Expr, out: &mut Vec<&'a str>) {
    match expr {
        Expr::Equals(name, _) | Expr::NotEquals(name, _) => out.push(name),
        Expr::Not(inner) => collect_compared(inner, out),
        Expr::And(a, b) | Expr::Or(a, b) => {
            collect_compared(a, out);
            collect_compared(b, out);
        }
        Expr::Wildcard | Expr::Present(_) => {}
    }
}

/// Declared states of `machine` that no path of transitions reaches from its start (the
/// program's error state counts as reachable: faults lead there).
fn unreachable(program: &Program, machine: &str) -> Vec<String> {
    let Some(def) = program.machines.get(machine) else {
        return Vec::new();
    };
    let mut seen: BTreeSet<&str> = BTreeSet::new();
    let mut queue = VecDeque::from([def.start.as_str()]);
    if machine == program.main {
        queue.push_back(&program.error_state);
    }
    while let Some(state) = queue.pop_front() {
        if !seen.insert(state) {
            continue;
        }
        for t in &def.transitions {
            if t.from.as_deref().is_none_or(|from| from == state) {
                queue.extend(t.next.values().map(String::as_str));
            }
        }
    }
    def.states
        .iter()
        .filter(|s| !seen.contains(s.as_str()))
        .cloned()
        .collect()
}

//! [`Vocabulary`]: the stimuli a program accepts, so that a misspelt stimulus is refused with
//! its reason before it reaches the machine (where it would be a fault sending the machine to
//! its error state, or a transient that silently vanishes).
//!
//! | sent                         | accepted when                                              |
//! |------------------------------|------------------------------------------------------------|
//! | `NAME`                       | `NAME` is declared transient or latched                    |
//! | `NAME=VALUE`                 | `NAME` is a declared condition, and `VALUE` is not a near miss of a value the transitions compare it with |
//!
//! A condition may take any value: a value no transition names makes every `NAME = X` false,
//! which is how "none of them" is said. Only a near miss of a tested value is refused, as the
//! typo it almost certainly is: the same but for case (`visible` for `Visible`), or, for
//! values of 4 characters or more, one edit away (`Visibel`, `Hiden`). `Off` where only `On` is
//! tested, or `2` where only `1` is, are values of their own.

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use super::def::{Program, StimulusKind};
use super::engine::Stimulus;
use super::expr::Expr;

/// One stimulus a machine accepts, as published in its state (and listed by `ndds fsm show`).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Accepted {
    /// Its name.
    pub name: String,
    /// `transient`, `latched` or `condition`.
    pub kind: String,
    /// For a condition, the values its transitions compare it with (any other value is
    /// accepted too, except near misses of these).
    pub values: Vec<String>,
}

impl std::fmt::Display for Accepted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.kind.as_str(), self.values.as_slice()) {
            ("condition", []) => write!(f, "{}=VALUE", self.name),
            ("condition", values) => write!(f, "{}={}", self.name, values.join("|")),
            _ => f.write_str(&self.name),
        }
    }
}

/// Why a stimulus is refused, in the machine's words.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Refusal {
    /// The program declares no such stimulus.
    #[error("machine `{machine}` has no stimulus `{stimulus}`{suggestion}; it accepts: {}", list(.accepts))]
    Undeclared {
        /// The main machine.
        machine: String,
        /// The stimulus sent.
        stimulus: String,
        /// ` (did you mean `X`?)` or empty.
        suggestion: String,
        /// What it accepts.
        accepts: Vec<Accepted>,
    },
    /// A value sent with a transient or latched stimulus.
    #[error(
        "machine `{machine}`: `{stimulus}` is a {kind} stimulus and takes no value (send `{stimulus}`)"
    )]
    UnexpectedValue {
        /// The main machine.
        machine: String,
        /// The stimulus.
        stimulus: String,
        /// `transient` or `latched`.
        kind: String,
    },
    /// A condition sent without a value.
    #[error("machine `{machine}`: condition `{}` needs a value: {accepted}", .accepted.name)]
    MissingValue {
        /// The main machine.
        machine: String,
        /// The condition.
        accepted: Accepted,
    },
    /// A condition value that is a near miss of one its transitions name.
    #[error("machine `{machine}`: `{}={value}` is not a value its transitions test (did you mean `{}={suggestion}`?); they test: {accepted}", .accepted.name, .accepted.name)]
    NearMiss {
        /// The main machine.
        machine: String,
        /// The value sent.
        value: String,
        /// The value it resembles.
        suggestion: String,
        /// The condition.
        accepted: Accepted,
    },
}

fn list(accepts: &[Accepted]) -> String {
    if accepts.is_empty() {
        return "nothing (the program declares no stimuli)".to_owned();
    }
    accepts
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// What a program accepts.
#[derive(Clone, Debug, Default)]
pub struct Vocabulary {
    machine: String,
    entries: BTreeMap<String, Accepted>,
}

impl Vocabulary {
    /// The stimuli `program` declares, with the values its transitions compare conditions with.
    pub fn of(program: &Program) -> Self {
        let mut values: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
        for machine in program.machines.values() {
            for transition in &machine.transitions {
                compared_values(&transition.when, &mut values);
            }
        }
        let entries = program
            .stimuli
            .iter()
            .map(|(name, kind)| {
                let kind_name = match kind {
                    StimulusKind::Transient => "transient",
                    StimulusKind::Latched => "latched",
                    StimulusKind::Condition => "condition",
                };
                let values = match kind {
                    StimulusKind::Condition => values
                        .get(name.as_str())
                        .map(|v| v.iter().map(|s| (*s).to_owned()).collect())
                        .unwrap_or_default(),
                    _ => Vec::new(),
                };
                let accepted = Accepted {
                    name: name.clone(),
                    kind: kind_name.to_owned(),
                    values,
                };
                (name.clone(), accepted)
            })
            .collect();
        Self {
            machine: program.main.clone(),
            entries,
        }
    }

    /// Every accepted stimulus, by name.
    pub fn accepted(&self) -> Vec<Accepted> {
        self.entries.values().cloned().collect()
    }

    /// Whether the machine takes `stimulus`, and if not, why.
    pub fn check(&self, stimulus: &Stimulus) -> Result<(), Box<Refusal>> {
        self.refusal(stimulus).map_or(Ok(()), |r| Err(Box::new(r)))
    }

    fn refusal(&self, stimulus: &Stimulus) -> Option<Refusal> {
        let machine = self.machine.clone();
        let Some(accepted) = self.entries.get(&stimulus.name) else {
            let names: Vec<&str> = self.entries.keys().map(String::as_str).collect();
            return Some(Refusal::Undeclared {
                machine,
                stimulus: stimulus.name.clone(),
                suggestion: crate::system::decl::suggest(&stimulus.name, &names),
                accepts: self.accepted(),
            });
        };
        match (accepted.kind.as_str(), &stimulus.value) {
            ("condition", None) => Some(Refusal::MissingValue {
                machine,
                accepted: accepted.clone(),
            }),
            ("condition", Some(value)) => {
                near_miss(value, &accepted.values).map(|near| Refusal::NearMiss {
                    machine,
                    value: value.clone(),
                    suggestion: near.to_owned(),
                    accepted: accepted.clone(),
                })
            }
            (kind, Some(_)) => Some(Refusal::UnexpectedValue {
                machine,
                stimulus: stimulus.name.clone(),
                kind: kind.to_owned(),
            }),
            (_, None) => None,
        }
    }
}

/// The tested value `value` is a typo of, if any: the same but for case, or (for values of at
/// least 4 characters) one edit away, a swap of two neighbours counting as one (`Visibel`,
/// `Hiden`). Short values and values two edits away are words of their own (`Off` for `On`,
/// `2` for `1`).
fn near_miss<'a>(value: &str, tested: &'a [String]) -> Option<&'a str> {
    if tested.iter().any(|t| t == value) {
        return None;
    }
    tested
        .iter()
        .find(|t| {
            t.to_lowercase() == value.to_lowercase()
                || (value.chars().count() >= 4 && strsim::osa_distance(value, t) == 1)
        })
        .map(String::as_str)
}

fn compared_values<'a>(expr: &'a Expr, values: &mut BTreeMap<&'a str, BTreeSet<&'a str>>) {
    match expr {
        Expr::Wildcard | Expr::Present(_) => {}
        Expr::Equals(name, value) | Expr::NotEquals(name, value) => {
            values.entry(name).or_default().insert(value);
        }
        Expr::Not(inner) => compared_values(inner, values),
        Expr::And(a, b) | Expr::Or(a, b) => {
            compared_values(a, values);
            compared_values(b, values);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn program() -> Program {
        let mut p = Program::new("arm", "Joint");
        p.stimulus("Coarse", StimulusKind::Transient)
            .stimulus("Precise", StimulusKind::Latched)
            .stimulus("Object", StimulusKind::Condition)
            .stimulus("Mode", StimulusKind::Condition)
            .stimulus("Power", StimulusKind::Condition)
            .stimulus("Gear", StimulusKind::Condition);
        let m = p.machine("arm", "Joint");
        m.states(&["Endpoint"]);
        m.transition(
            "Joint",
            "Object = Visible and Precise",
            "none",
            &[(0, "Endpoint")],
        )
        .expect("parses");
        m.transition("Endpoint", "Object != Hidden", "none", &[(0, "Joint")])
            .expect("parses");
        m.transition("Joint", "Power = On or Gear = 1", "none", &[(0, "Joint")])
            .expect("parses");
        p
    }

    fn check(text: &str) -> Result<(), Box<Refusal>> {
        Vocabulary::of(&program()).check(&Stimulus::parse(text))
    }

    #[test]
    fn declared_stimuli_are_accepted() {
        for ok in [
            "Coarse",
            "Precise",
            "Object=Visible",
            "Object=Hidden",
            "Object=Gone",
            "Object=Visual",
            "Mode=anything",
            "Power=Off",
            "Gear=2",
        ] {
            assert_eq!(check(ok), Ok(()), "{ok}");
        }
    }

    #[test]
    fn a_misspelt_stimulus_is_refused_with_a_suggestion_and_the_list() {
        let err = check("Corse").expect_err("undeclared");
        assert!(matches!(*err, Refusal::Undeclared { .. }), "{err:?}");
        assert_eq!(
            err.to_string(),
            "machine `arm` has no stimulus `Corse` (did you mean `Coarse`?); it accepts: \
             Coarse, Gear=1, Mode=VALUE, Object=Hidden|Visible, Power=On, Precise"
        );
    }

    #[test]
    fn values_where_none_belong_and_missing_values_are_refused() {
        let err = check("Coarse=1").expect_err("no value");
        assert_eq!(
            err.to_string(),
            "machine `arm`: `Coarse` is a transient stimulus and takes no value (send `Coarse`)"
        );
        let err = check("Object").expect_err("needs a value");
        assert_eq!(
            err.to_string(),
            "machine `arm`: condition `Object` needs a value: Object=Hidden|Visible"
        );
    }

    #[test]
    fn a_near_miss_of_a_tested_value_is_refused() {
        for typo in [
            "Object=Visibel",
            "Object=visible",
            "Object=Hiden",
            "Object=HIDDEN",
            "Power=on",
        ] {
            let err = check(typo).expect_err(typo);
            assert!(matches!(*err, Refusal::NearMiss { .. }), "{typo}: {err:?}");
        }
        assert_eq!(
            check("Object=Visibel").expect_err("typo").to_string(),
            "machine `arm`: `Object=Visibel` is not a value its transitions test (did you mean \
             `Object=Visible`?); they test: Object=Hidden|Visible"
        );
    }
}

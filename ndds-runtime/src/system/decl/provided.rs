//! The unknown-CSMat rule of a description, in one place: a CSMat the description reads
//! (a component input, a publication, a rate transition's source, a trigger's input, a
//! displayed CSMat, a `set` action's target) must be provided by a `[[mat]]`, a component
//! output, a `[[subscribe]]` or a rate transition, or be a parameter CSMat
//! `<component>.<parameter>`.
//!
//! The loader owns this report for everything written in a file: it says where the name was
//! written, suggests the closest provided one, and comes with every other problem of the
//! file, before anything is built. [`Runtime::verify`](crate::Runtime::verify) (its
//! `Problem::Unbound`) runs only on a description this check let through, so it never reports
//! the same name again; the loader relies on it for the one thing only a built runtime knows:
//! which parameter CSMats a component really creates.

use std::collections::BTreeSet;

use super::machine::MachineDecl;
use super::{Description, list, suggest};
use crate::ParamKind;
use crate::fsm::ActionRef;
use crate::system::source::{Diagnostics, Location};

/// What provides each CSMat name of a description.
pub(super) struct Provided<'a> {
    /// Declared by a `[[mat]]`, a `[[subscribe]]`, a rate transition or a component output.
    names: BTreeSet<&'a str>,
    /// The provided names, sorted, for messages.
    known: Vec<&'a str>,
    components: BTreeSet<&'a str>,
}

impl<'a> Provided<'a> {
    pub fn of(d: &'a Description) -> Self {
        let mut names: BTreeSet<&str> = BTreeSet::new();
        names.extend(d.mats.iter().map(|m| m.name.name.as_str()));
        names.extend(d.subscribes.iter().map(|s| s.mat.name.as_str()));
        names.extend(d.rates.iter().map(|r| r.to.1.name.as_str()));
        let outputs = d.components.iter().flat_map(|c| &c.mats);
        names.extend(
            outputs
                .filter(|(_, _, kind)| *kind == ParamKind::Output)
                .map(|(mat, _, _)| mat.as_str()),
        );
        Self {
            known: names.iter().copied().collect(),
            names,
            components: d.components.iter().map(|c| c.name.name.as_str()).collect(),
        }
    }

    /// Whether the description provides `name`. A `<component>.<parameter>` name is taken
    /// on trust: which ones exist is the component's to say, and verify() reports a name that
    /// none creates.
    pub fn provides(&self, name: &str) -> bool {
        self.names.contains(name) || self.is_parameter(name)
    }

    fn is_parameter(&self, name: &str) -> bool {
        name.rsplit_once('.')
            .is_some_and(|(component, _)| self.components.contains(component))
    }

    /// Reports every CSMat the description reads that nothing provides.
    pub fn check_reads(&self, d: &Description, p: &mut Diagnostics) {
        let inputs = d.components.iter().flat_map(|c| &c.mats);
        for (mat, at, _) in inputs.filter(|(_, _, kind)| *kind == ParamKind::Input) {
            self.check(mat, at, p);
        }
        let named = (d.publishes.iter().map(|s| &s.mat))
            .chain(d.rates.iter().map(|r| &r.from.1))
            .chain(d.triggers.iter().map(|t| &t.input))
            .chain(&d.display);
        for n in named {
            self.check(&n.name, &n.at, p);
        }
    }

    fn check(&self, name: &str, at: &Location, p: &mut Diagnostics) {
        if self.provides(name) {
            return;
        }
        p.expected(
            at,
            format!(
                "unknown CSMat `{name}`: no [[mat]], component output, [[subscribe]] or rate \
                 transition provides it"
            ),
            format!("one of {}{}", list(&self.known), suggest(name, &self.known)),
        );
    }

    /// Reports `set CSMAT V1 V2 ...` actions whose CSMat is not the system's or whose values
    /// are not numbers.
    pub fn check_set_actions(&self, d: &Description, p: &mut Diagnostics) {
        for m in &d.machines {
            for (machine, def) in &m.program.machines {
                for argument in def
                    .transitions
                    .iter()
                    .filter_map(|t| set_argument(&t.action))
                {
                    self.check_set(m, machine, argument, p);
                }
            }
        }
    }

    fn check_set(&self, m: &MachineDecl, machine: &str, argument: &str, p: &mut Diagnostics) {
        let mut words = argument.split_whitespace();
        let mat = words.next().unwrap_or("");
        let numbers_ok =
            words.clone().count() > 0 && words.all(|w| w.parse::<f64>().is_ok_and(f64::is_finite));
        if self.provides(mat) && numbers_ok {
            return;
        }
        p.expected(
            &m.at,
            format!(
                "state machine `{machine}` ({}): action `set {argument}`",
                m.file.display()
            ),
            format!(
                "`set CSMAT V1 V2 ...` with a CSMat of this system{} and its values",
                suggest(mat, &self.known)
            ),
        );
    }
}

/// The argument of a `set` action (empty when it has none).
fn set_argument(action: &ActionRef) -> Option<&str> {
    match action {
        ActionRef::Named { name, argument } if name == "set" => {
            Some(argument.as_deref().unwrap_or(""))
        }
        _ => None,
    }
}

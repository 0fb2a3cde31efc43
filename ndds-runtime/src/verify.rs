//! Verification: every problem that would make live execution wrong, found before it starts.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

use super::database::{Database, ObjectKind};
use super::module::{Shape, Use};
use super::sort::{SortError, SortNode, sort};

/// One problem found by [`Runtime::verify`](super::Runtime::verify).
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Problem {
    /// Referenced but never created.
    Unbound {
        /// What kind of object.
        kind: ObjectKind,
        /// Its name.
        name: String,
        /// Who refers to it (module, group or configuration names; `application` for code).
        referenced_by: Vec<String>,
    },
    /// A module expects another shape than the CSMat has.
    ShapeMismatch {
        /// The CSMat.
        mat: String,
        /// The module.
        module: String,
        /// What the module declared.
        expected: Shape,
        /// What the CSMat is.
        actual: (usize, usize),
    },
    /// Active modules read a CSMat that no active module writes and the application did not
    /// create.
    MissingProducer {
        /// The CSMat.
        mat: String,
        /// The active modules reading it.
        readers: Vec<String>,
        /// Modules that write it but are not active.
        inactive_writers: Vec<String>,
        /// The configuration checked (`None`: the active set now).
        configuration: Option<String>,
    },
    /// Several active modules write one CSMat.
    DoubleWriter {
        /// The CSMat.
        mat: String,
        /// Its writers.
        writers: Vec<String>,
        /// The configuration checked (`None`: the active set now).
        configuration: Option<String>,
    },
    /// A cycle through direct-feedthrough inputs in one habitat.
    AlgebraicLoop {
        /// The habitat.
        habitat: String,
        /// The modules in the loop, each writing the next one's input.
        modules: Vec<String>,
        /// The CSMats along it.
        mats: Vec<String>,
        /// The configuration checked (`None`: the active set now).
        configuration: Option<String>,
    },
    /// A configuration selects a group that belongs to another category.
    WrongCategory {
        /// The configuration.
        configuration: String,
        /// The group.
        group: String,
        /// The category the configuration names.
        category: String,
        /// The group's own category.
        actual: String,
    },
}

fn scope(configuration: &Option<String>) -> String {
    match configuration {
        Some(name) => format!(" (in configuration `{name}`)"),
        None => String::new(),
    }
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::Unbound {
                kind,
                name,
                referenced_by,
            } => write!(
                f,
                "unbound {kind} `{name}`: referenced by {} but never created",
                referenced_by.join(", ")
            ),
            Problem::ShapeMismatch {
                mat,
                module,
                expected,
                actual,
            } => write!(
                f,
                "shape mismatch: module `{module}` expects CSMat `{mat}` to be {expected}, it is {}x{}",
                actual.0, actual.1
            ),
            Problem::MissingProducer {
                mat,
                readers,
                inactive_writers,
                configuration,
            } => {
                write!(
                    f,
                    "missing producer{}: CSMat `{mat}` is read by {} but no active module writes it",
                    scope(configuration),
                    readers.join(", ")
                )?;
                if !inactive_writers.is_empty() {
                    write!(f, " (inactive writers: {})", inactive_writers.join(", "))?;
                }
                Ok(())
            }
            Problem::DoubleWriter {
                mat,
                writers,
                configuration,
            } => write!(
                f,
                "double writer{}: CSMat `{mat}` is written by {}",
                scope(configuration),
                writers.join(" and ")
            ),
            Problem::AlgebraicLoop {
                habitat,
                modules,
                mats,
                configuration,
            } => write!(
                f,
                "algebraic loop{} in habitat `{habitat}`: {}",
                scope(configuration),
                SortError::AlgebraicLoop {
                    modules: modules.clone(),
                    mats: mats.clone()
                }
                .to_string()
                .trim_start_matches("algebraic loop through direct-feedthrough inputs: ")
            ),
            Problem::WrongCategory {
                configuration,
                group,
                category,
                actual,
            } => write!(
                f,
                "configuration `{configuration}` selects group `{group}` for category `{category}`, but the group belongs to `{actual}`"
            ),
        }
    }
}

/// Everything [`Runtime::verify`](super::Runtime::verify) found; empty means the system may run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VerifyReport {
    /// The problems, in a stable order.
    pub problems: Vec<Problem>,
}

impl VerifyReport {
    /// No problem found.
    pub fn is_ok(&self) -> bool {
        self.problems.is_empty()
    }
}

impl fmt::Display for VerifyReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.problems.is_empty() {
            return f.write_str("no problems");
        }
        for (i, problem) in self.problems.iter().enumerate() {
            if i > 0 {
                f.write_str("\n")?;
            }
            write!(f, "  - {problem}")?;
        }
        Ok(())
    }
}

/// Checks the whole database.
pub(crate) fn verify(db: &Database) -> VerifyReport {
    let mut problems = Vec::new();
    unbound(db, &mut problems);
    shapes(db, &mut problems);
    let now = db.active_groups();
    active_set(db, &now, None, &mut problems);
    for (name, selections) in &db.configurations {
        if db.current.as_deref() == Some(name) {
            continue;
        }
        let mut active = now.clone();
        for (category, group) in selections {
            active.insert(category.clone(), Some(group.clone()));
        }
        active_set(db, &active, Some(name), &mut problems);
    }
    VerifyReport { problems }
}

fn unbound(db: &Database, problems: &mut Vec<Problem>) {
    unbound_mats(db, problems);
    for (name, habitat) in &db.habitats {
        if !habitat.is_created() {
            let mut referenced_by: Vec<String> = db
                .modules
                .iter()
                .filter(|(_, m)| &m.habitat == name)
                .map(|(m, _)| m.clone())
                .collect();
            if referenced_by.is_empty() {
                referenced_by.push("application".into());
            }
            problems.push(Problem::Unbound {
                kind: ObjectKind::Habitat,
                name: name.clone(),
                referenced_by,
            });
        }
    }
    let mut missing_modules: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    for (group, entry) in &db.groups {
        for module in &entry.modules {
            if !db.modules.contains_key(module) {
                missing_modules
                    .entry(module)
                    .or_default()
                    .push(group.clone());
            }
        }
    }
    for (module, groups) in missing_modules {
        problems.push(Problem::Unbound {
            kind: ObjectKind::Module,
            name: module.to_owned(),
            referenced_by: groups,
        });
    }
    let mut missing_groups: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    for (configuration, selections) in &db.configurations {
        for (category, group) in selections {
            match db.groups.get(group) {
                None => missing_groups
                    .entry(group)
                    .or_default()
                    .push(configuration.clone()),
                Some(entry) if &entry.category != category => {
                    problems.push(Problem::WrongCategory {
                        configuration: configuration.clone(),
                        group: group.clone(),
                        category: category.clone(),
                        actual: entry.category.clone(),
                    })
                }
                Some(_) => {}
            }
        }
    }
    for (group, configurations) in missing_groups {
        problems.push(Problem::Unbound {
            kind: ObjectKind::Group,
            name: group.to_owned(),
            referenced_by: configurations,
        });
    }
}

/// The unknown-CSMat rule of the runtime: a CSMat referenced (by a module or the application)
/// but never created. It is the only check for a runtime built in Rust. A description file's
/// names are checked by the loader first, where they were written (`system::decl::provided`),
/// and a description reaches this only when that check found nothing: what is left here is
/// what only the built runtime knows, a `<component>.<parameter>` CSMat its component did not
/// create. One mistake, one message: a CSMat waiting for the shape of another that is itself
/// unbound ([`Binder::output_same_as`](crate::Binder::output_same_as)) is not reported; it is
/// created as soon as that one is.
fn unbound_mats(db: &Database, problems: &mut Vec<Problem>) {
    for (name, entry) in &db.mats {
        if entry.mat.is_bound() || waits_for_unbound(db, name) {
            continue;
        }
        let mut referenced_by: Vec<String> = db.referrers_of_mat(name).into_iter().collect();
        if entry.looked_up {
            referenced_by.push("application".into());
        }
        if !referenced_by.is_empty() {
            problems.push(Problem::Unbound {
                kind: ObjectKind::Mat,
                name: name.clone(),
                referenced_by,
            });
        }
    }
}

/// Whether `name` waits for the shape of an unbound CSMat that is reported itself: the chain
/// of unbound CSMats each waits for ends at one that waits for none (a cycle of them ends
/// nowhere, and each is reported).
fn waits_for_unbound(db: &Database, name: &str) -> bool {
    let unbound = |mat: &str| db.mats.get(mat).is_none_or(|e| !e.mat.is_bound());
    let leader_of = |mat: &str| {
        db.follows
            .iter()
            .find(|(follower, leader)| follower == mat && unbound(leader))
            .map(|(_, leader)| leader.as_str())
    };
    let mut seen = BTreeSet::from([name]);
    let mut current = name;
    while let Some(leader) = leader_of(current) {
        if !seen.insert(leader) {
            return false;
        }
        current = leader;
    }
    current != name
}

fn shapes(db: &Database, problems: &mut Vec<Problem>) {
    for (module, entry) in &db.modules {
        let ports = entry
            .interface
            .inputs
            .iter()
            .map(|(p, _)| p)
            .chain(&entry.interface.outputs);
        for port in ports {
            if let Shape::Exact(rows, cols) = port.shape
                && port.mat.is_bound()
            {
                let actual = port.mat.shape();
                if actual != (rows, cols) {
                    problems.push(Problem::ShapeMismatch {
                        mat: port.mat.name().to_owned(),
                        module: module.clone(),
                        expected: port.shape,
                        actual,
                    });
                }
            }
        }
    }
}

/// Double writers, missing producers and algebraic loops of one active set.
fn active_set(
    db: &Database,
    active: &BTreeMap<String, Option<String>>,
    configuration: Option<&String>,
    problems: &mut Vec<Problem>,
) {
    let configuration = configuration.cloned();
    let is_active = |module: &str| db.is_active_with(module, active);
    let mut writers: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    let mut inactive_writers: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    let mut readers: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    for (name, entry) in &db.modules {
        let on = is_active(name);
        for mat in entry.interface.output_names() {
            let map = if on {
                &mut writers
            } else {
                &mut inactive_writers
            };
            map.entry(mat).or_default().push(name.clone());
        }
        if on {
            for (port, usage) in &entry.interface.inputs {
                if *usage != Use::Parameter {
                    readers
                        .entry(port.mat.name())
                        .or_default()
                        .push(name.clone());
                }
            }
        }
    }
    for (mat, list) in &writers {
        if list.len() > 1 {
            problems.push(Problem::DoubleWriter {
                mat: (*mat).to_owned(),
                writers: list.clone(),
                configuration: configuration.clone(),
            });
        }
    }
    for (mat, list) in readers {
        let by_application = db.mats.get(mat).is_some_and(|e| e.by_application);
        let unbound = db.mats.get(mat).is_none_or(|e| !e.mat.is_bound());
        if writers.contains_key(mat) || by_application || unbound {
            continue; // unbound ones are reported as such
        }
        let mut list: Vec<String> = list
            .into_iter()
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        list.retain(|reader| !writers.get(mat).is_some_and(|w| w.contains(reader)));
        problems.push(Problem::MissingProducer {
            mat: mat.to_owned(),
            readers: list,
            inactive_writers: inactive_writers.get(mat).cloned().unwrap_or_default(),
            configuration: configuration.clone(),
        });
    }
    let mut by_habitat: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (name, entry) in &db.modules {
        if is_active(name) {
            by_habitat.entry(&entry.habitat).or_default().push(name);
        }
    }
    for (habitat, modules) in by_habitat {
        // Double writers are reported above; only the first writer of a CSMat orders the
        // list here, so a loop elsewhere in the same set is still found.
        let mut claimed: BTreeSet<&str> = BTreeSet::new();
        let nodes: Vec<SortNode<'_>> = modules
            .iter()
            .map(|&m| SortNode {
                module: m,
                reads: db.modules[m].interface.feedthrough_names().collect(),
                writes: db.modules[m]
                    .interface
                    .output_names()
                    .filter(|mat| claimed.insert(mat))
                    .collect(),
            })
            .collect();
        if let Err(SortError::AlgebraicLoop { modules, mats }) = sort(&nodes) {
            problems.push(Problem::AlgebraicLoop {
                habitat: habitat.to_owned(),
                modules,
                mats,
                configuration: configuration.clone(),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Problem;
    use crate::{Clock, HabitatOptions, ObjectKind, RoutineResult, Runtime, SampleContext};
    use crate::{SampleModule, Shape};

    struct Idle;

    impl SampleModule for Idle {
        fn execute(&mut self, _: &SampleContext) -> RoutineResult {
            Ok(())
        }
    }

    /// A runtime whose module `name` in habitat `habitat` writes `output` shaped like `input`.
    fn copy(rt: &Runtime, habitat: &str, name: &str, input: &str, output: &str) {
        if !rt.habitat(habitat).is_created() {
            let options = HabitatOptions::rate(10.0).clock(Clock::Manual);
            rt.create_habitat(habitat, options).unwrap();
        }
        rt.install(habitat, name, |b| {
            let input = b.input(input, Shape::Any);
            b.output_same_as(output, &input);
            Ok(Idle)
        })
        .unwrap();
    }

    fn unbound(name: &str, by: &str) -> Problem {
        Problem::Unbound {
            kind: ObjectKind::Mat,
            name: name.into(),
            referenced_by: vec![by.into()],
        }
    }

    #[test]
    fn csmats_waiting_for_an_unbound_one_are_not_reported_too() {
        let rt = Runtime::new("waiting");
        copy(&rt, "h", "a", "x", "y");
        copy(&rt, "h", "b", "y", "z");
        assert_eq!(rt.verify().problems, [unbound("x", "a")]);
    }

    #[test]
    fn csmats_waiting_for_each_other_are_all_reported() {
        let rt = Runtime::new("circle");
        copy(&rt, "h1", "a", "x", "y");
        copy(&rt, "h2", "b", "y", "x");
        let report = rt.verify();
        let reported: Vec<&str> = (report.problems.iter())
            .filter_map(|p| match p {
                Problem::Unbound { name, .. } => Some(name.as_str()),
                _ => None,
            })
            .collect();
        assert_eq!(reported, ["x", "y"]);
    }
}

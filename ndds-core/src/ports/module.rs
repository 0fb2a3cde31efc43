//! Module specifications and their load-time check (Shin, 1985, section 5): what a module
//! declares — its tasks, the ports it owns and uses with their usages, its response and
//! exception handlers, its named subprograms, its `order` and the child modules it starts —
//! checked before it runs, with every problem reported at once.
//!
//! [`ModuleSpec::check`] checks one module against itself and the handler bodies it was
//! given ("each declared response handler must have a corresponding handler in the module
//! body, otherwise a load error will result"); [`check_system`] checks modules against each
//! other, the global usage the paper defers to load time: every port used has one owner,
//! the ends' usages complement each other, their message formats agree, and every child a
//! module starts is a module of the system.
//!
//! Handler names are the paper's: `PORT.NAME` for a response handler (`ASK_CHILD1.STATUS`,
//! `SHARE_FEEDER1.CRIT_SECTION`) and `PORT.TIMEOUT` for the exception handler of a port's
//! timeout.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

use super::order::Order;
use super::usage::Usage;

/// One end of a port, as a module declares it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PortDecl {
    /// The port.
    pub port: String,
    /// This end's usages (empty, for an owner: any).
    pub usages: Vec<Usage>,
    /// Whether its operations time out (a `TIMEOUT=` restriction): only then may a
    /// `PORT.TIMEOUT` handler be declared.
    pub timeout: bool,
    /// Fingerprints of the request and reply types, when known.
    pub formats: Option<(u64, u64)>,
}

/// What a module declares.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModuleSpec {
    /// The module's name (its background code's section name).
    pub name: String,
    /// Tasks created with the module, besides its body.
    pub tasks: Vec<String>,
    /// Ports it owns.
    pub owns: Vec<PortDecl>,
    /// Ports it uses.
    pub uses: Vec<PortDecl>,
    /// Response handlers it declares (`PORT.NAME`).
    pub responses: Vec<String>,
    /// Exception handlers it declares (`PORT.TIMEOUT`).
    pub exceptions: Vec<String>,
    /// Named subprograms (sections of its own it enters and leaves).
    pub subprograms: Vec<String>,
    /// Its order, if it has one.
    pub order: Option<Order>,
    /// The modules it starts (`costart`).
    pub children: Vec<String>,
}

/// A problem found before a module runs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LoadProblem {
    /// A declared response or exception handler without a body, or a body for a handler the
    /// module did not declare.
    MissingHandler {
        /// The handler.
        handler: String,
        /// `declared without a body` or `given a body but not declared`.
        what: &'static str,
    },
    /// A handler, order entry or usage that names a port the module neither owns nor uses.
    UnknownPort {
        /// Where the name was found.
        place: String,
        /// The port.
        port: String,
    },
    /// A handler on a port whose usages do not call for it.
    HandlerWithoutUsage {
        /// The handler.
        handler: String,
        /// Why not, in words.
        why: String,
    },
    /// A used port with usage `Response` and no response handler for it.
    NoResponseHandler {
        /// The port.
        port: String,
    },
    /// An order entry that names no section of the module.
    UnknownSection {
        /// The entry.
        section: String,
    },
    /// A usage an end cannot declare (an owner's usage on a user's end, or the other way).
    WrongEnd {
        /// The port.
        port: String,
        /// The usage.
        usage: Usage,
        /// `owner` or `user`: the end that declared it.
        end: &'static str,
    },
    /// A name declared twice.
    Duplicate {
        /// What kind of name.
        kind: &'static str,
        /// The name.
        name: String,
    },
    /// A port used by a module and owned by none in the system.
    NoOwner {
        /// The using module.
        module: String,
        /// The port.
        port: String,
    },
    /// A port owned by two modules.
    TwoOwners {
        /// The port.
        port: String,
        /// The owning modules.
        owners: (String, String),
    },
    /// A user's usage that complements none of the owner's.
    IncompatibleUsage {
        /// The port.
        port: String,
        /// The using module.
        user: String,
        /// The usage.
        usage: Usage,
        /// The owner's usages.
        owner: Vec<Usage>,
    },
    /// The two ends' message formats differ.
    IncompatibleFormat {
        /// The port.
        port: String,
        /// The using module.
        user: String,
        /// The owner's request and reply fingerprints.
        owner_formats: (u64, u64),
        /// The user's.
        user_formats: (u64, u64),
    },
    /// The work schedule does not read, or calls what the module does not declare.
    Schedule {
        /// What is wrong.
        what: String,
    },
    /// A problem of a child module, found when its parent loaded.
    InChild {
        /// The child.
        module: String,
        /// The problem.
        problem: Box<LoadProblem>,
    },
    /// A child that is not a module of the system.
    UnknownChild {
        /// The parent.
        parent: String,
        /// The child named.
        child: String,
    },
    /// A module whose specification was read from a description file, and whose code does
    /// not agree with it: something declared there and not given in code (a port's types, a
    /// handler's or a task's body, a child), or declared in code and not there.
    Specification {
        /// Where: `FILE:LINE:COLUMN` of the declaration, or the file.
        at: String,
        /// What is wrong, and what to do.
        what: String,
    },
}

impl fmt::Display for LoadProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LoadProblem::MissingHandler { handler, what } => {
                write!(f, "handler `{handler}` {what}")
            }
            LoadProblem::UnknownPort { place, port } => {
                write!(
                    f,
                    "{place} names port `{port}`, which the module neither owns nor uses"
                )
            }
            LoadProblem::HandlerWithoutUsage { handler, why } => {
                write!(f, "handler `{handler}`: {why}")
            }
            LoadProblem::NoResponseHandler { port } => write!(
                f,
                "port `{port}` is used with usage Response but no response handler `{port}.NAME` is declared"
            ),
            LoadProblem::UnknownSection { section } => write!(
                f,
                "the order names `{section}`, which is not the module, a subprogram, or a declared handler"
            ),
            LoadProblem::WrongEnd { port, usage, end } => {
                write!(
                    f,
                    "port `{port}`: {usage:?} is not a usage of a port's {end}"
                )
            }
            LoadProblem::Duplicate { kind, name } => write!(f, "{kind} `{name}` is declared twice"),
            LoadProblem::NoOwner { module, port } => {
                write!(
                    f,
                    "module `{module}` uses port `{port}`, which no module of the system owns"
                )
            }
            LoadProblem::TwoOwners { port, owners } => write!(
                f,
                "port `{port}` is owned by both `{}` and `{}`",
                owners.0, owners.1
            ),
            LoadProblem::IncompatibleUsage {
                port,
                user,
                usage,
                owner,
            } => write!(
                f,
                "port `{port}`: `{user}` uses it with {usage:?}, which complements none of the owner's usages {owner:?}"
            ),
            LoadProblem::IncompatibleFormat {
                port,
                user,
                owner_formats,
                user_formats,
            } => write!(
                f,
                "port `{port}`: `{user}` uses message formats {:016x}/{:016x} but the owner's are {:016x}/{:016x}",
                user_formats.0, user_formats.1, owner_formats.0, owner_formats.1
            ),
            LoadProblem::InChild { module, problem } => write!(f, "in `{module}`: {problem}"),
            LoadProblem::Schedule { what } => write!(f, "work schedule: {what}"),
            LoadProblem::Specification { at, what } => write!(f, "{at}: {what}"),
            LoadProblem::UnknownChild { parent, child } => {
                write!(
                    f,
                    "module `{parent}` starts `{child}`, which is not a module of the system"
                )
            }
        }
    }
}

/// A module that cannot run, with every problem found.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("module `{module}` cannot be loaded: {}", problems.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))]
pub struct LoadError {
    /// The module (or `system`).
    pub module: String,
    /// Every problem found.
    pub problems: Vec<LoadProblem>,
}

impl ModuleSpec {
    /// The port a handler name (`PORT.NAME`) is on.
    fn handler_port(handler: &str) -> &str {
        handler.rsplit_once('.').map_or(handler, |(port, _)| port)
    }

    fn end(&self, port: &str) -> Option<(&PortDecl, bool)> {
        self.owns
            .iter()
            .find(|d| d.port == port)
            .map(|d| (d, true))
            .or_else(|| {
                self.uses
                    .iter()
                    .find(|d| d.port == port)
                    .map(|d| (d, false))
            })
    }

    /// Checks the module against itself and against `bodies`, the handlers it was given
    /// code for; every problem found.
    pub fn check<'a>(&self, bodies: impl IntoIterator<Item = &'a str>) -> Vec<LoadProblem> {
        let mut problems = Vec::new();
        let bodies: BTreeSet<&str> = bodies.into_iter().collect();
        let declared: BTreeSet<&str> = self
            .responses
            .iter()
            .chain(&self.exceptions)
            .map(String::as_str)
            .collect();
        // Names declared twice.
        let mut seen = BTreeSet::new();
        for (kind, name) in self
            .owns
            .iter()
            .chain(&self.uses)
            .map(|d| ("port", &d.port))
            .chain(self.responses.iter().map(|h| ("handler", h)))
            .chain(self.exceptions.iter().map(|h| ("handler", h)))
            .chain(self.subprograms.iter().map(|s| ("subprogram", s)))
            .chain(self.tasks.iter().map(|t| ("task", t)))
            .chain(self.children.iter().map(|c| ("child", c)))
        {
            if !seen.insert((kind, name.as_str())) {
                problems.push(LoadProblem::Duplicate {
                    kind,
                    name: name.clone(),
                });
            }
        }
        // Usages at the wrong end.
        for decl in &self.owns {
            for &usage in &decl.usages {
                if usage.user_complement().is_none() {
                    problems.push(LoadProblem::WrongEnd {
                        port: decl.port.clone(),
                        usage,
                        end: "owner",
                    });
                }
            }
        }
        for decl in &self.uses {
            for &usage in &decl.usages {
                if !usage.of_user() {
                    problems.push(LoadProblem::WrongEnd {
                        port: decl.port.clone(),
                        usage,
                        end: "user",
                    });
                }
            }
        }
        // Every declared handler has a body, every body was declared.
        for handler in &declared {
            if !bodies.contains(handler) {
                problems.push(LoadProblem::MissingHandler {
                    handler: (*handler).to_owned(),
                    what: "is declared without a body",
                });
            }
        }
        for body in &bodies {
            if !declared.contains(body) {
                problems.push(LoadProblem::MissingHandler {
                    handler: (*body).to_owned(),
                    what: "is given a body but not declared",
                });
            }
        }
        // Response handlers sit on ports whose usage answers queries.
        for handler in &self.responses {
            let port = Self::handler_port(handler);
            match self.end(port) {
                None => problems.push(LoadProblem::UnknownPort {
                    place: format!("response handler `{handler}`"),
                    port: port.to_owned(),
                }),
                Some((decl, owned)) => {
                    let answers = if owned {
                        decl.usages.is_empty() || decl.usages.contains(&Usage::Response)
                    } else {
                        decl.usages.contains(&Usage::Response)
                    };
                    if !answers {
                        problems.push(LoadProblem::HandlerWithoutUsage {
                            handler: handler.clone(),
                            why: format!(
                                "the module {} port `{port}` without usage Response (it declared {:?})",
                                if owned { "owns" } else { "uses" },
                                decl.usages
                            ),
                        });
                    }
                }
            }
        }
        // One response handler per port, and a port whose queries a handler answers is not
        // also read by the body (both would take the same messages).
        let mut answered = BTreeSet::new();
        for handler in &self.responses {
            let port = Self::handler_port(handler);
            if !answered.insert(port) {
                problems.push(LoadProblem::HandlerWithoutUsage {
                    handler: handler.clone(),
                    why: format!("port `{port}` has a response handler already (one per port)"),
                });
            }
            if let Some((decl, owned)) = self.end(port) {
                // Only where the handler answers at all (else its usage is the problem).
                let read_too = if owned {
                    decl.usages.is_empty()
                        || (decl.usages.contains(&Usage::Receive)
                            && decl.usages.contains(&Usage::Response))
                } else {
                    decl.usages.contains(&Usage::Receive) && decl.usages.contains(&Usage::Response)
                };
                if read_too {
                    problems.push(LoadProblem::HandlerWithoutUsage {
                        handler: handler.clone(),
                        why: format!(
                            "the body could take the same messages from port `{port}` (it declared {:?}): declare usage Response without Receive",
                            decl.usages
                        ),
                    });
                }
            }
        }
        for decl in &self.uses {
            let prefix = format!("{}.", decl.port);
            if decl.usages.contains(&Usage::Response)
                && !self.responses.iter().any(|h| h.starts_with(&prefix))
            {
                problems.push(LoadProblem::NoResponseHandler {
                    port: decl.port.clone(),
                });
            }
        }
        // Exception handlers are for ports with a timeout.
        for handler in &self.exceptions {
            let (port, kind) = handler.rsplit_once('.').unwrap_or((handler, ""));
            if kind != "TIMEOUT" {
                problems.push(LoadProblem::HandlerWithoutUsage {
                    handler: handler.clone(),
                    why: "an exception handler is named `PORT.TIMEOUT`".to_owned(),
                });
                continue;
            }
            match self.end(port) {
                None => problems.push(LoadProblem::UnknownPort {
                    place: format!("exception handler `{handler}`"),
                    port: port.to_owned(),
                }),
                Some((decl, _)) if !decl.timeout => {
                    problems.push(LoadProblem::HandlerWithoutUsage {
                        handler: handler.clone(),
                        why: format!("port `{port}` has no timeout restriction"),
                    });
                }
                Some(_) => {}
            }
        }
        // The order names sections of this module only.
        if let Some(order) = &self.order {
            for name in order.names() {
                let known = *name == self.name
                    || self.subprograms.contains(name)
                    || self.tasks.contains(name)
                    || declared.contains(name.as_str());
                if !known {
                    problems.push(LoadProblem::UnknownSection {
                        section: name.clone(),
                    });
                }
            }
        }
        problems
    }
}

/// Checks the modules of one system against each other (see the module docs); every
/// problem found. Each module's own [`ModuleSpec::check`] is separate.
pub fn check_system(modules: &[ModuleSpec]) -> Vec<LoadProblem> {
    let mut problems = Vec::new();
    let mut owners: BTreeMap<&str, (&ModuleSpec, &PortDecl)> = BTreeMap::new();
    for module in modules {
        for decl in &module.owns {
            if let Some((other, _)) = owners.get(decl.port.as_str()) {
                problems.push(LoadProblem::TwoOwners {
                    port: decl.port.clone(),
                    owners: (other.name.clone(), module.name.clone()),
                });
                continue;
            }
            owners.insert(&decl.port, (module, decl));
        }
    }
    let names: BTreeSet<&str> = modules.iter().map(|m| m.name.as_str()).collect();
    for module in modules {
        for decl in &module.uses {
            let Some((_, owner)) = owners.get(decl.port.as_str()) else {
                problems.push(LoadProblem::NoOwner {
                    module: module.name.clone(),
                    port: decl.port.clone(),
                });
                continue;
            };
            if !owner.usages.is_empty() {
                for &usage in &decl.usages {
                    if !owner
                        .usages
                        .iter()
                        .any(|o| o.user_complement() == Some(usage))
                    {
                        problems.push(LoadProblem::IncompatibleUsage {
                            port: decl.port.clone(),
                            user: module.name.clone(),
                            usage,
                            owner: owner.usages.clone(),
                        });
                    }
                }
            }
            if let (Some(theirs), Some(mine)) = (owner.formats, decl.formats)
                && theirs != mine
            {
                problems.push(LoadProblem::IncompatibleFormat {
                    port: decl.port.clone(),
                    user: module.name.clone(),
                    owner_formats: theirs,
                    user_formats: mine,
                });
            }
        }
        for child in &module.children {
            if !names.contains(child.as_str()) {
                problems.push(LoadProblem::UnknownChild {
                    parent: module.name.clone(),
                    child: child.clone(),
                });
            }
        }
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decl(port: &str, usages: &[Usage], timeout: bool) -> PortDecl {
        PortDecl {
            port: port.to_owned(),
            usages: usages.to_vec(),
            timeout,
            formats: None,
        }
    }

    /// CHIP_IT as the appendix declares it.
    fn chip_it() -> ModuleSpec {
        ModuleSpec {
            name: "CHIP_IT".into(),
            tasks: vec!["FREEZE_CARD".into()],
            owns: vec![
                decl("READY_TO_CHIP", &[Usage::Receive], true),
                decl("SHARE_FEEDER", &[Usage::Query], true),
            ],
            uses: vec![
                decl("SHARE_FEEDER1", &[Usage::Response], false),
                decl("FREQUENCY", &[Usage::Send], false),
            ],
            responses: vec!["SHARE_FEEDER1.CRIT_SECTION".into()],
            exceptions: vec![
                "READY_TO_CHIP.TIMEOUT".into(),
                "SHARE_FEEDER.TIMEOUT".into(),
            ],
            subprograms: vec!["GRASP".into(), "INSERT".into()],
            order: Some(
                Order::parse(
                    "ORDER(READY_TO_CHIP.TIMEOUT, SHARE_FEEDER.TIMEOUT, CHIP_IT, GRASP, \
                     SHARE_FEEDER1.CRIT_SECTION, INSERT)",
                )
                .unwrap(),
            ),
            children: vec![],
        }
    }

    const CHIP_IT_BODIES: [&str; 3] = [
        "SHARE_FEEDER1.CRIT_SECTION",
        "READY_TO_CHIP.TIMEOUT",
        "SHARE_FEEDER.TIMEOUT",
    ];

    #[test]
    fn the_appendixs_chip_it_loads() {
        assert_eq!(chip_it().check(CHIP_IT_BODIES), []);
    }

    #[test]
    fn every_problem_of_a_module_is_reported_at_once() {
        let mut m = chip_it();
        m.exceptions.push("FREQUENCY.TIMEOUT".into()); // FREQUENCY has no timeout
        m.responses.push("NOWHERE.STATUS".into()); // an unknown port
        m.uses.push(decl("ASK_CHILD2", &[Usage::Response], false)); // no handler for it
        m.owns.push(decl("LOUD", &[Usage::ReceiveAll], false)); // a user's usage
        m.order = Some(Order::parse("ORDER(CHIP_IT, GRAPS, INSERT)").unwrap()); // a typo
        let problems = m.check([
            "SHARE_FEEDER1.CRIT_SECTION",
            "READY_TO_CHIP.TIMEOUT",
            "EXTRA.TIMEOUT",
        ]);
        let text: Vec<String> = problems.iter().map(ToString::to_string).collect();
        let expected = [
            "port `LOUD`: ReceiveAll is not a usage of a port's owner",
            "handler `FREQUENCY.TIMEOUT` is declared without a body",
            "handler `NOWHERE.STATUS` is declared without a body",
            "handler `SHARE_FEEDER.TIMEOUT` is declared without a body",
            "handler `EXTRA.TIMEOUT` is given a body but not declared",
            "response handler `NOWHERE.STATUS` names port `NOWHERE`, which the module neither owns nor uses",
            "port `ASK_CHILD2` is used with usage Response but no response handler `ASK_CHILD2.NAME` is declared",
            "handler `FREQUENCY.TIMEOUT`: port `FREQUENCY` has no timeout restriction",
            "the order names `GRAPS`, which is not the module, a subprogram, or a declared handler",
        ];
        assert_eq!(text, expected);
        let err = LoadError {
            module: m.name.clone(),
            problems,
        };
        assert!(
            err.to_string()
                .starts_with("module `CHIP_IT` cannot be loaded: port `LOUD`")
        );
    }

    #[test]
    fn a_response_handler_needs_a_port_that_answers_queries() {
        let mut m = chip_it();
        m.uses[0].usages = vec![Usage::Receive];
        let problems = m.check(CHIP_IT_BODIES);
        assert_eq!(
            problems,
            [LoadProblem::HandlerWithoutUsage {
                handler: "SHARE_FEEDER1.CRIT_SECTION".into(),
                why: "the module uses port `SHARE_FEEDER1` without usage Response (it declared [Receive])"
                    .into(),
            }]
        );
        // A port whose queries the handler answers and that the body also receives from.
        m.uses[0].usages = vec![Usage::Receive, Usage::Response];
        m.responses.push("SHARE_FEEDER1.OTHER".into());
        let text: Vec<String> = m
            .check(CHIP_IT_BODIES.into_iter().chain(["SHARE_FEEDER1.OTHER"]))
            .iter()
            .map(ToString::to_string)
            .collect();
        assert_eq!(
            text,
            [
                "handler `SHARE_FEEDER1.CRIT_SECTION`: the body could take the same messages from port `SHARE_FEEDER1` (it declared [Receive, Response]): declare usage Response without Receive",
                "handler `SHARE_FEEDER1.OTHER`: port `SHARE_FEEDER1` has a response handler already (one per port)",
                "handler `SHARE_FEEDER1.OTHER`: the body could take the same messages from port `SHARE_FEEDER1` (it declared [Receive, Response]): declare usage Response without Receive",
            ]
        );
        m.responses.pop();
        m.uses[0].usages = vec![Usage::Receive];
        m.tasks.push("FREEZE_CARD".into());
        assert_eq!(
            m.check(CHIP_IT_BODIES).first(),
            Some(&LoadProblem::Duplicate {
                kind: "task",
                name: "FREEZE_CARD".into()
            })
        );
    }

    #[test]
    fn a_system_checks_owners_usages_formats_and_children() {
        let gate = ModuleSpec {
            name: "GATE".into(),
            owns: vec![PortDecl {
                formats: Some((1, 2)),
                ..decl("FREQUENCY", &[Usage::Receive], false)
            }],
            children: vec!["LOAD_IT".into(), "NOBODY".into()],
            ..ModuleSpec::default()
        };
        let load_it = ModuleSpec {
            name: "LOAD_IT".into(),
            uses: vec![
                PortDecl {
                    formats: Some((1, 3)),
                    ..decl("FREQUENCY", &[Usage::Send, Usage::Query], false)
                },
                decl("ORPHAN", &[Usage::Send], false),
            ],
            ..ModuleSpec::default()
        };
        let rival = ModuleSpec {
            name: "RIVAL".into(),
            owns: vec![decl("FREQUENCY", &[], false)],
            ..ModuleSpec::default()
        };
        let problems = check_system(&[gate, load_it, rival]);
        let text: Vec<String> = problems.iter().map(ToString::to_string).collect();
        assert_eq!(
            text,
            [
                "port `FREQUENCY` is owned by both `GATE` and `RIVAL`",
                "module `GATE` starts `NOBODY`, which is not a module of the system",
                "port `FREQUENCY`: `LOAD_IT` uses it with Query, which complements none of the owner's usages [Receive]",
                "port `FREQUENCY`: `LOAD_IT` uses message formats 0000000000000001/0000000000000003 but the owner's are 0000000000000001/0000000000000002",
                "module `LOAD_IT` uses port `ORPHAN`, which no module of the system owns",
            ]
        );
    }
}

//! Module specifications written in a description file (Shin's module specification, apart
//! from the module's code): a TOML file of `[[module]]` tables naming each module's tasks,
//! the ports it owns and uses with their restrictions, its response and exception handlers,
//! its subprograms, its `order`, its work schedule and its children. The code then only
//! *binds* what the file declares — a port's message types, a handler's or a task's body, a
//! child — and [`ModuleBuilder::load`] reports every disagreement between the two, with where
//! the declaration was written (see docs/ports.md, "Module specifications in a file").
//!
//! Reading the files takes the crate's `module-files` feature (off by default, so that a
//! program that only publishes compiles no TOML); `ndds modules --check` has it.
//!
//! ```toml
//! [[module]]
//! name = "CHIP_IT"
//! subprograms = ["GRASP", "INSERT"]
//! responses = ["SHARE_FEEDER1.CRIT_SECTION"]
//! exceptions = ["SHARE_FEEDER2.TIMEOUT"]
//! order = "ORDER(SHARE_FEEDER2.TIMEOUT, CHIP_IT, GRASP, SHARE_FEEDER1.CRIT_SECTION, INSERT)"
//! schedule = """
//! 1) GRASP(1), INSERT(10.5, 20, 3)
//! """
//!
//! [[module.owns]]
//! port = "SHARE_FEEDER1"
//! usages = ["response"]
//! users = ["CHIP_IT2"]
//!
//! [[module.uses]]
//! port = "SHARE_FEEDER2"
//! usages = ["query"]
//! timeout = 3.0
//! ```

#![cfg_attr(not(feature = "module-files"), allow(dead_code))]

use std::time::Duration;

use ndds_core::ports::Usage;

use super::wire::Restrictions;

/// A module file that cannot be used: every problem found, each with where it was written.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}", problems.join("\n"))]
pub struct ModuleFileError {
    /// One line per problem: `FILE:LINE:COLUMN: what is wrong`.
    pub problems: Vec<String>,
}

/// The modules of one description file (see the module docs).
#[derive(Clone, Debug)]
pub struct ModuleFile {
    path: String,
    modules: Vec<FileModule>,
}

/// One `[[module]]`, read and checked for form.
#[derive(Clone, Debug, Default)]
pub(crate) struct FileModule {
    pub(crate) name: String,
    /// Where the module's table starts (`FILE:LINE:COLUMN`).
    pub(crate) at: String,
    pub(crate) tasks: Vec<(String, String)>,
    pub(crate) subprograms: Vec<String>,
    pub(crate) responses: Vec<String>,
    pub(crate) exceptions: Vec<String>,
    pub(crate) order: Option<String>,
    /// Where the order is written (`FILE:LINE:COLUMN`).
    pub(crate) order_at: Option<String>,
    pub(crate) schedule: Option<String>,
    pub(crate) children: Vec<(String, String)>,
    pub(crate) ports: Vec<FilePort>,
}

/// A port the file declares for a module.
#[derive(Clone, Debug)]
pub(crate) struct FilePort {
    pub(crate) port: String,
    pub(crate) at: String,
    pub(crate) end: FileEnd,
}

/// Which end of the port, with what that end declares.
#[derive(Clone, Debug)]
pub(crate) enum FileEnd {
    Owner(Restrictions),
    User {
        usages: Vec<Usage>,
        timeout: Option<Duration>,
    },
}

impl ModuleFile {
    /// The file's name, as messages give it.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The names of the modules it declares, in file order.
    pub fn names(&self) -> Vec<&str> {
        self.modules.iter().map(|m| m.name.as_str()).collect()
    }

    /// Module `name`, whose code is bound with a [`ModuleBuilder`](super::ModuleBuilder).
    pub(crate) fn module(&self, name: &str) -> Result<&FileModule, ModuleFileError> {
        self.modules
            .iter()
            .find(|m| m.name == name)
            .ok_or_else(|| ModuleFileError {
                problems: vec![format!(
                    "{}: no module `{name}`; it declares {}",
                    self.path,
                    self.names()
                        .iter()
                        .map(|n| format!("`{n}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )],
            })
    }

    /// The specifications the file declares, checked against each other as one system
    /// (without code: message formats are not known, and handler bodies are not asked for).
    /// What `ndds modules check FILE` prints.
    pub fn check(&self) -> Vec<String> {
        let specs: Vec<ndds_core::ports::ModuleSpec> =
            self.modules.iter().map(FileModule::spec).collect();
        let mut problems = Vec::new();
        for (module, spec) in self.modules.iter().zip(&specs) {
            let declared: Vec<&str> = spec
                .responses
                .iter()
                .chain(&spec.exceptions)
                .map(String::as_str)
                .collect();
            for problem in spec.check(declared) {
                // An order's problem is shown where the order is written.
                let at = match (&problem, &module.order_at) {
                    (ndds_core::ports::LoadProblem::UnknownSection { .. }, Some(at)) => at,
                    _ => &module.at,
                };
                problems.push(format!("{}: module `{}`: {problem}", at, module.name));
            }
            if let Some(text) = &module.schedule
                && let Err(err) = ndds_core::ports::WorkSchedule::parse(text)
            {
                problems.push(format!(
                    "{}: module `{}`: work schedule: {err}",
                    module.at, module.name
                ));
            }
        }
        for problem in ndds_core::ports::check_system(&specs) {
            problems.push(format!("{}: {problem}", self.path));
        }
        problems
    }
}

impl FileModule {
    /// The specification as far as the file gives it (ports without formats).
    pub(crate) fn spec(&self) -> ndds_core::ports::ModuleSpec {
        let mut spec = ndds_core::ports::ModuleSpec {
            name: self.name.clone(),
            tasks: self.tasks.iter().map(|(t, _)| t.clone()).collect(),
            responses: self.responses.clone(),
            exceptions: self.exceptions.clone(),
            subprograms: self.subprograms.clone(),
            order: None,
            children: self.children.iter().map(|(c, _)| c.clone()).collect(),
            ..ndds_core::ports::ModuleSpec::default()
        };
        if let Some(order) = self
            .order
            .as_deref()
            .and_then(|o| ndds_core::ports::Order::parse(o).ok())
        {
            spec.order = Some(order);
        }
        for port in &self.ports {
            let decl = |usages: &[Usage], timeout: bool| ndds_core::ports::PortDecl {
                port: port.port.clone(),
                usages: usages.to_vec(),
                timeout,
                formats: None,
            };
            match &port.end {
                FileEnd::Owner(r) => spec.owns.push(decl(&r.usages, r.timeout_ms.is_some())),
                FileEnd::User { usages, timeout } => {
                    spec.uses.push(decl(usages, timeout.is_some()))
                }
            }
        }
        spec
    }
}

/// Reading module files (the `module-files` feature).
#[cfg(feature = "module-files")]
mod reader {
    use std::collections::BTreeSet;
    use std::ops::Range;
    use std::path::{Path, PathBuf};
    use std::time::Duration;

    use ndds_core::ports::Usage;
    use serde::Deserialize;
    use toml::Spanned;

    use super::{FileEnd, FileModule, FilePort, ModuleFile, ModuleFileError};
    use crate::ports::wire::{Filter, ProcessClass, Restrictions};

    /// Largest module file read, in bytes.
    const MAX_FILE: u64 = 1 << 20;

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Doc {
        #[serde(default)]
        module: Vec<Spanned<ModuleDoc>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct ModuleDoc {
        name: Spanned<String>,
        #[serde(default)]
        tasks: Vec<Spanned<String>>,
        #[serde(default)]
        subprograms: Vec<Spanned<String>>,
        #[serde(default)]
        responses: Vec<Spanned<String>>,
        #[serde(default)]
        exceptions: Vec<Spanned<String>>,
        order: Option<Spanned<String>>,
        schedule: Option<Spanned<String>>,
        schedule_file: Option<Spanned<String>>,
        #[serde(default)]
        children: Vec<Spanned<String>>,
        #[serde(default)]
        owns: Vec<Spanned<PortDoc>>,
        #[serde(default)]
        uses: Vec<Spanned<PortDoc>>,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct PortDoc {
        port: Spanned<String>,
        #[serde(default)]
        usages: Vec<Spanned<String>>,
        #[serde(default)]
        users: Vec<String>,
        max_users: Option<u32>,
        timeout: Option<Spanned<f64>>,
        priority: Option<i32>,
        class: Option<Spanned<String>>,
        spin_us: Option<Spanned<u32>>,
        buffer: Option<Spanned<u32>>,
    }

    /// Turns byte offsets into `FILE:LINE:COLUMN` and collects problems.
    struct Places<'a> {
        path: &'a str,
        text: &'a str,
        problems: Vec<String>,
    }

    impl Places<'_> {
        fn at(&self, span: Range<usize>) -> String {
            let before = &self.text[..span.start.min(self.text.len())];
            let line = before.matches('\n').count() + 1;
            let column = before
                .rsplit_once('\n')
                .map_or(before, |(_, last)| last)
                .chars()
                .count()
                + 1;
            format!("{}:{line}:{column}", self.path)
        }

        fn problem(&mut self, span: Range<usize>, what: impl std::fmt::Display) {
            let at = self.at(span);
            self.problems.push(format!("{at}: {what}"));
        }
    }

    impl ModuleFile {
        /// Reads and checks `path` (at most 1 MiB). A schedule file it names is read relative to
        /// it.
        pub fn read(path: impl AsRef<Path>) -> Result<Self, ModuleFileError> {
            let path = path.as_ref();
            let shown = path.display().to_string();
            let fail = |what: String| ModuleFileError {
                problems: vec![format!("{shown}: {what}")],
            };
            let meta = std::fs::metadata(path).map_err(|e| fail(e.to_string()))?;
            if !meta.is_file() {
                return Err(fail("not a regular file".to_owned()));
            }
            if meta.len() > MAX_FILE {
                return Err(fail(format!(
                    "{} bytes: larger than the {MAX_FILE} a module file may have",
                    meta.len()
                )));
            }
            let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
            Self::parse_at(&shown, &text, path.parent().map(Path::to_path_buf))
        }

        /// Reads `text` as a module file named `name` in messages (schedule files are then read
        /// relative to the current directory).
        pub fn parse(name: &str, text: &str) -> Result<Self, ModuleFileError> {
            Self::parse_at(name, text, None)
        }

        fn parse_at(name: &str, text: &str, dir: Option<PathBuf>) -> Result<Self, ModuleFileError> {
            let mut places = Places {
                path: name,
                text,
                problems: Vec::new(),
            };
            let doc: Doc = match toml::from_str(text) {
                Ok(doc) => doc,
                Err(err) => {
                    let what = err.message().to_owned();
                    match err.span() {
                        Some(span) => places.problem(span, what),
                        None => places.problems.push(format!("{name}: {what}")),
                    }
                    return Err(ModuleFileError {
                        problems: places.problems,
                    });
                }
            };
            let mut modules: Vec<FileModule> = Vec::new();
            if doc.module.is_empty() {
                places
                    .problems
                    .push(format!("{name}: no [[module]] table: nothing to load"));
            }
            for module in doc.module {
                let span = module.span();
                let read = read_module(module.into_inner(), span, &mut places, dir.as_deref());
                if let Some(first) = modules.iter().find(|m| m.name == read.name) {
                    let what = format!(
                        "module `{}` is declared twice (first at {})",
                        read.name, first.at
                    );
                    places.problems.push(format!("{}: {what}", read.at));
                    continue;
                }
                modules.push(read);
            }
            if places.problems.is_empty() {
                Ok(ModuleFile {
                    path: name.to_owned(),
                    modules,
                })
            } else {
                Err(ModuleFileError {
                    problems: places.problems,
                })
            }
        }
    }

    fn read_module(
        doc: ModuleDoc,
        span: Range<usize>,
        places: &mut Places<'_>,
        dir: Option<&Path>,
    ) -> FileModule {
        let at = places.at(span);
        let names = |list: Vec<Spanned<String>>, kind: &str, places: &mut Places<'_>| {
            let mut seen = BTreeSet::new();
            let mut out = Vec::new();
            for name in list {
                let span = name.span();
                let name = name.into_inner();
                if !good_name(&name) {
                    places.problem(
                        span.clone(),
                        format!(
                            "{kind} `{name}`: names are letters, digits, `_`, `-` and `.`, not empty"
                        ),
                    );
                } else if !seen.insert(name.clone()) {
                    places.problem(span.clone(), format!("{kind} `{name}` is declared twice"));
                } else {
                    out.push((name, places.at(span)));
                }
            }
            out
        };
        let name_span = doc.name.span();
        let name = doc.name.into_inner();
        if !good_name(&name) {
            places.problem(
                name_span,
                format!(
                    "module name `{name}`: names are letters, digits, `_`, `-` and `.`, not empty"
                ),
            );
        }
        let mut module = FileModule {
            name,
            at,
            tasks: names(doc.tasks, "task", places),
            subprograms: strip(names(doc.subprograms, "subprogram", places)),
            responses: strip(names(doc.responses, "response handler", places)),
            exceptions: strip(names(doc.exceptions, "exception handler", places)),
            children: names(doc.children, "child", places),
            ..FileModule::default()
        };
        for handler in &module.responses {
            if !handler.contains('.') {
                let at = module.at.clone();
                places.problems.push(format!(
                    "{at}: response handler `{handler}` should be named `PORT.NAME`"
                ));
            }
        }
        for handler in &module.exceptions {
            if !handler.ends_with(".TIMEOUT") {
                let at = module.at.clone();
                places.problems.push(format!(
                    "{at}: exception handler `{handler}` should be named `PORT.TIMEOUT`"
                ));
            }
        }
        if let Some(order) = doc.order {
            let span = order.span();
            let text = order.into_inner();
            match ndds_core::ports::Order::parse(&text) {
                Ok(_) => {
                    module.order = Some(text);
                    module.order_at = Some(places.at(span));
                }
                Err(err) => places.problem(span, format!("the order does not read: {err}")),
            }
        }
        match (doc.schedule, doc.schedule_file) {
            (Some(_), Some(file)) => places.problem(
                file.span(),
                "`schedule` and `schedule_file` both given: keep one",
            ),
            (Some(text), None) => {
                let span = text.span();
                let text = text.into_inner();
                match ndds_core::ports::WorkSchedule::parse(&text) {
                    Ok(_) => module.schedule = Some(text),
                    Err(err) => {
                        places.problem(span, format!("the work schedule does not read: {err}"))
                    }
                }
            }
            (None, Some(file)) => {
                let span = file.span();
                let relative = PathBuf::from(file.into_inner());
                let path = match dir {
                    Some(dir) if relative.is_relative() => dir.join(&relative),
                    _ => relative,
                };
                match std::fs::read_to_string(&path) {
                    Ok(text) => match ndds_core::ports::WorkSchedule::parse(&text) {
                        Ok(_) => module.schedule = Some(text),
                        Err(err) => places.problem(
                            span,
                            format!("the work schedule {} does not read: {err}", path.display()),
                        ),
                    },
                    Err(err) => places.problem(span, format!("{}: {err}", path.display())),
                }
            }
            (None, None) => {}
        }
        let mut seen = BTreeSet::new();
        for (port, owner) in doc
            .owns
            .into_iter()
            .map(|p| (p, true))
            .chain(doc.uses.into_iter().map(|p| (p, false)))
        {
            let span = port.span();
            if let Some(read) = read_port(port.into_inner(), span.clone(), owner, places) {
                if !seen.insert(read.port.clone()) {
                    places.problem(
                        span,
                        format!("port `{}` is declared twice in this module", read.port),
                    );
                    continue;
                }
                module.ports.push(read);
            }
        }
        module
    }

    fn strip(named: Vec<(String, String)>) -> Vec<String> {
        named.into_iter().map(|(name, _)| name).collect()
    }

    fn read_port(
        doc: PortDoc,
        span: Range<usize>,
        owner: bool,
        places: &mut Places<'_>,
    ) -> Option<FilePort> {
        let before = places.problems.len();
        let port_span = doc.port.span();
        let port = doc.port.into_inner();
        if !good_name(&port) {
            places.problem(
                port_span,
                format!("port `{port}`: names are letters, digits, `_`, `-` and `.`, not empty"),
            );
        }
        let mut usages = Vec::new();
        for usage in doc.usages {
            let span = usage.span();
            match parse_usage(usage.get_ref()) {
                Some(u) if owner && u == Usage::ReceiveAll => places.problem(
                    span,
                    "`receive_all` is a user's usage; an owner sends to all with `sendall` or `callall`",
                ),
                Some(u) if !owner && !u.of_user() => places.problem(
                    span,
                    format!("`{}` is an owner's usage, not a user's", usage.get_ref()),
                ),
                Some(u) if usages.contains(&u) => {
                    places.problem(span, format!("usage `{}` is given twice", usage.get_ref()))
                }
                Some(u) => usages.push(u),
                None => places.problem(
                    span,
                    format!(
                        "unknown usage `{}`; expected one of send, receive, query, response, sendall, callall, receive_all",
                        usage.get_ref()
                    ),
                ),
            }
        }
        let timeout = match doc.timeout {
            Some(t) if !(t.get_ref().is_finite() && (0.001..=86_400.0).contains(t.get_ref())) => {
                places.problem(t.span(), "a timeout is in seconds, from 0.001 to 86400");
                None
            }
            Some(t) => Some(Duration::from_secs_f64(*t.get_ref())),
            None => None,
        };
        let owner_only = [
            ("users", !doc.users.is_empty()),
            ("max_users", doc.max_users.is_some()),
            ("priority", doc.priority.is_some()),
            ("class", doc.class.is_some()),
            ("spin_us", doc.spin_us.is_some()),
            ("buffer", doc.buffer.is_some()),
        ];
        if !owner {
            for (key, given) in owner_only {
                if given {
                    places.problem(
                        span.clone(),
                        format!("`{key}` is a restriction of the port's owner: give it under [[module.owns]]"),
                    );
                }
            }
        }
        let class = match (doc.class, doc.spin_us) {
            (None, None) => ProcessClass::Loose,
            (None, Some(spin)) => {
                places.problem(spin.span(), "`spin_us` goes with class = \"tight\"");
                ProcessClass::Loose
            }
            (Some(class), spin) => match class.get_ref().as_str() {
                "loose" => {
                    if let Some(spin) = spin {
                        places.problem(spin.span(), "`spin_us` goes with class = \"tight\"");
                    }
                    ProcessClass::Loose
                }
                "tight" => ProcessClass::Tight {
                    spin_us: spin.map_or(ProcessClass::DEFAULT_SPIN_US, |s| *s.get_ref()),
                },
                other => {
                    places.problem(
                        class.span(),
                        format!("unknown class `{other}`; expected \"loose\" or \"tight\""),
                    );
                    ProcessClass::Loose
                }
            },
        };
        let filter = match doc.buffer {
            Some(b) if *b.get_ref() == 0 => {
                places.problem(b.span(), "a buffer holds at least 1 request");
                None
            }
            Some(b) if usages.iter().any(|u| *u != Usage::Receive) => {
                places.problem(
                    b.span(),
                    "a buffer answers its senders itself: its port's usages are [\"receive\"] (or none)",
                );
                None
            }
            Some(b) => Some(Filter::BoundedBuffer {
                capacity: *b.get_ref(),
            }),
            None => None,
        };
        if places.problems.len() > before {
            return None;
        }
        let at = places.at(span);
        let end = if owner {
            FileEnd::Owner(Restrictions {
                usages,
                users: doc.users,
                max_users: doc.max_users,
                timeout_ms: timeout
                    .map(|t| u64::try_from(t.as_millis()).unwrap_or(u64::MAX).max(1)),
                priority: doc.priority,
                filter,
                class,
            })
        } else {
            FileEnd::User { usages, timeout }
        };
        Some(FilePort { port, at, end })
    }

    /// A usage as the file writes it (the paper's upper case works too).
    fn parse_usage(text: &str) -> Option<Usage> {
        Some(match text.to_ascii_lowercase().as_str() {
            "send" => Usage::Send,
            "receive" => Usage::Receive,
            "query" => Usage::Query,
            "response" => Usage::Response,
            "sendall" | "send_all" => Usage::SendAll,
            "callall" | "call_all" => Usage::CallAll,
            "receive_all" | "receiveall" => Usage::ReceiveAll,
            _ => return None,
        })
    }

    fn good_name(name: &str) -> bool {
        !name.is_empty()
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
    }
}

#[cfg(all(test, feature = "module-files"))]
mod tests {
    use super::*;
    use crate::ports::wire::ProcessClass;

    const CHIP_IT: &str = r#"
[[module]]
name = "CHIP_IT"
subprograms = ["GRASP", "INSERT"]
responses = ["SHARE_FEEDER1.CRIT_SECTION"]
exceptions = ["SHARE_FEEDER2.TIMEOUT"]
order = "ORDER(SHARE_FEEDER2.TIMEOUT, CHIP_IT, GRASP, SHARE_FEEDER1.CRIT_SECTION, INSERT)"
schedule = """
1) GRASP(1), INSERT(10.5, 20, 3)
"""

[[module.owns]]
port = "SHARE_FEEDER1"
usages = ["response"]
users = ["CHIP_IT2"]
max_users = 1
priority = 3
class = "tight"
spin_us = 40

[[module.uses]]
port = "SHARE_FEEDER2"
usages = ["QUERY"]
timeout = 3.0
"#;

    #[test]
    fn a_whole_module_reads_with_its_restrictions() {
        let file = ModuleFile::parse("chip.toml", CHIP_IT).unwrap();
        assert_eq!(file.names(), ["CHIP_IT"]);
        let module = file.module("CHIP_IT").unwrap();
        assert_eq!(module.at, "chip.toml:2:1");
        assert_eq!(module.subprograms, ["GRASP", "INSERT"]);
        assert!(module.schedule.as_deref().unwrap().contains("GRASP(1)"));
        let owned = &module.ports[0];
        let FileEnd::Owner(r) = &owned.end else {
            panic!("owned: {owned:?}")
        };
        assert_eq!(r.usages, [Usage::Response]);
        assert_eq!(r.users, ["CHIP_IT2"]);
        assert_eq!((r.max_users, r.priority), (Some(1), Some(3)));
        assert_eq!(r.class, ProcessClass::Tight { spin_us: 40 });
        let FileEnd::User { usages, timeout } = &module.ports[1].end else {
            panic!("used: {:?}", module.ports[1])
        };
        assert_eq!(usages, &[Usage::Query]);
        assert_eq!(*timeout, Some(Duration::from_secs(3)));
        assert_eq!(module.ports[1].at, "chip.toml:21:1");
        // Alone, the port it uses has no owner: `check` says so, naming the file.
        let problems = file.check();
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(problems[0].starts_with("chip.toml: "), "{problems:?}");
        assert!(problems[0].contains("SHARE_FEEDER2"), "{problems:?}");
    }

    #[test]
    fn every_problem_is_reported_at_once_where_it_was_written() {
        let text = r#"
[[module]]
name = "A"
order = "ORDER(A,"
responses = ["NOPORT"]

[[module.owns]]
port = "P"
usages = ["recieve", "receive_all"]
buffer = 0

[[module.uses]]
port = "Q"
max_users = 2
timeout = -1.0

[[module.owns]]
port = "B"
usages = ["query"]
buffer = 4

[[module]]
name = "A"
"#;
        let err = ModuleFile::parse("bad.toml", text).unwrap_err();
        let all = err.problems.join("\n");
        for expected in [
            "bad.toml:4:9: the order does not read",
            "bad.toml:2:1: response handler `NOPORT` should be named `PORT.NAME`",
            "bad.toml:9:11: unknown usage `recieve`",
            "bad.toml:9:22: `receive_all` is a user's usage",
            "bad.toml:10:10: a buffer holds at least 1 request",
            "`max_users` is a restriction of the port's owner",
            "bad.toml:15:11: a timeout is in seconds",
            "bad.toml:20:10: a buffer answers its senders itself",
            "bad.toml:22:1: module `A` is declared twice (first at bad.toml:2:1)",
        ] {
            assert!(all.contains(expected), "missing {expected:?} in:\n{all}");
        }
        assert_eq!(err.problems.len(), 9, "{all}");
    }

    #[test]
    fn a_modules_order_naming_no_section_is_reported_where_the_order_is() {
        let text = "[[module]]\nname = \"M\"\nsubprograms = [\"A\"]\norder = \"ORDER(M, B)\"\n";
        let problems = ModuleFile::parse("o.toml", text).unwrap().check();
        assert_eq!(
            problems,
            [
                "o.toml:4:9: module `M`: the order names `B`, which is not the module, a subprogram, or a declared handler"
            ]
        );
    }

    #[test]
    fn syntax_errors_and_unknown_keys_say_where() {
        let err = ModuleFile::parse("s.toml", "[[module]]\nname = \"A\"\nowns = [\n").unwrap_err();
        assert!(err.problems[0].starts_with("s.toml:"), "{err}");
        let err =
            ModuleFile::parse("k.toml", "[[module]]\nname = \"A\"\nordre = \"A\"\n").unwrap_err();
        assert!(err.problems[0].starts_with("k.toml:3:1:"), "{err}");
        assert!(err.problems[0].contains("ordre"), "{err}");
        let err = ModuleFile::parse("e.toml", "").unwrap_err();
        assert!(err.problems[0].contains("no [[module]]"), "{err}");
        assert!(
            ModuleFile::parse("n.toml", CHIP_IT)
                .unwrap()
                .module("CHIP")
                .unwrap_err()
                .to_string()
                .contains("it declares `CHIP_IT`")
        );
    }
}

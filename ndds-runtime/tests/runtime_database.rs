//! The runtime's linking database (ControlShell paper, sections 4, 5 and 7): reference before
//! creation, verification of every kind of problem before live execution, the errors refused
//! at install time, and configuration switches that change nothing when refused.
//!
//! Every habitat here is clocked by hand (`Clock::Manual`) and nothing touches the network.

use std::sync::{Arc, Mutex};

use ndds_runtime::{
    Binder, Clock, CsMat, HabitatError, HabitatOptions, Mat, ModuleError, ObjectKind, Params,
    Problem, RoutineResult, Runtime, RuntimeError, SampleContext, SampleModule, Shape, SortError,
};

type Log = Arc<Mutex<Vec<String>>>;
type TestResult = Result<(), Box<dyn std::error::Error>>;
/// `(module, feedthrough inputs, state inputs, outputs)`.
type Interface = (
    &'static str,
    &'static [&'static str],
    &'static [&'static str],
    &'static [&'static str],
);

fn manual() -> HabitatOptions {
    HabitatOptions::rate(100.0).clock(Clock::Manual)
}

fn new_log() -> Log {
    Arc::new(Mutex::new(Vec::new()))
}

fn calls(log: &Log) -> Vec<String> {
    log.lock().unwrap().clone()
}

/// A 1 × 1 module: each output becomes 1 + the sum of its inputs; every routine is logged as
/// `"<module>.<routine>"`.
struct Node {
    name: String,
    log: Log,
    inputs: Vec<Mat>,
    outputs: Vec<Mat>,
}

impl Node {
    /// Feedthrough inputs `reads`, state inputs `state`, outputs `writes`.
    fn build(
        b: &mut Binder<'_>,
        log: &Log,
        reads: &[&str],
        state: &[&str],
        writes: &[&str],
    ) -> Result<Self, ModuleError> {
        let mut inputs = Vec::new();
        for mat in reads {
            inputs.push(b.input(mat, (1, 1)));
        }
        for mat in state {
            inputs.push(b.state_input(mat, (1, 1)));
        }
        let mut outputs = Vec::new();
        for mat in writes {
            outputs.push(b.output(mat, (1, 1)));
        }
        Ok(Self {
            name: b.module_name().to_owned(),
            log: Arc::clone(log),
            inputs,
            outputs,
        })
    }

    fn note(&self, routine: &str) {
        self.log
            .lock()
            .unwrap()
            .push(format!("{}.{routine}", self.name));
    }
}

impl SampleModule for Node {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        self.note("execute");
        let sum: f64 = self.inputs.iter().map(|m| m.value(0, 0)).sum();
        for out in &self.outputs {
            out.write().fill(sum + 1.0);
        }
        Ok(())
    }
    fn state_update(&mut self, _: &SampleContext) -> RoutineResult {
        self.note("state_update");
        Ok(())
    }
    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        self.note("enable");
        Ok(())
    }
    fn disable(&mut self, _: &SampleContext) -> RoutineResult {
        self.note("disable");
        Ok(())
    }
    fn startup(&mut self, _: &SampleContext) -> RoutineResult {
        self.note("startup");
        Ok(())
    }
    fn shutdown(&mut self, _: &SampleContext) -> RoutineResult {
        self.note("shutdown");
        Ok(())
    }
    fn terminate(&mut self) {
        self.note("terminate");
    }
}

/// Copies a matrix of any shape declared `shape`.
struct Copy {
    input: Mat,
    output: Mat,
}

impl SampleModule for Copy {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let value = self.input.read().clone();
        self.output.write().copy_from(&value)?;
        Ok(())
    }
}

fn sorted(mut v: Vec<String>) -> Vec<String> {
    v.sort();
    v
}

// ----- reference before creation -----

#[test]
fn a_mat_referenced_before_creation_is_bound_in_place_when_created() -> TestResult {
    let rt = Runtime::new("ref-mat");
    let x = rt.mat("x");
    assert_eq!(x.name(), "x");
    assert!(!x.is_bound(), "a placeholder is unbound");
    assert_eq!(x.shape(), (0, 0), "a placeholder is 0x0");

    rt.create_habitat("h", manual())?;
    let mut held = None;
    rt.install("h", "copy", |b| {
        let input = b.input("x", (2, 2));
        held = Some(input.clone());
        let output = b.output("y", (2, 2));
        Ok(Copy { input, output })
    })?;
    let held = held.expect("the builder ran");
    assert!(held.same(&x), "the module holds the database's handle");
    assert!(
        rt.mat("x").same(&x),
        "looking it up again gives the same handle"
    );

    let report = rt.verify();
    assert_eq!(
        report.problems,
        [Problem::Unbound {
            kind: ObjectKind::Mat,
            name: "x".into(),
            referenced_by: vec!["copy".into(), "application".into()],
        }],
        "{report}"
    );
    assert!(matches!(
        rt.habitat("h").start(),
        Err(HabitatError::Verify { .. })
    ));

    let created = rt.create_mat(CsMat::from_row_slice("x", 2, 2, &[1.0, 2.0, 3.0, 4.0])?)?;
    assert!(created.same(&x), "create_mat binds the placeholder");
    assert!(x.is_bound());
    assert_eq!(x.shape(), (2, 2));
    assert_eq!(held.value(1, 0), 3.0, "the module sees the values");
    assert!(rt.verify().is_ok(), "{}", rt.verify());

    let h = rt.habitat("h");
    h.start()?;
    h.step()?;
    let y = rt.mat("y");
    assert_eq!(y.snapshot().matrix(), x.snapshot().matrix());
    x.write().set(1, 1, 40.0)?;
    h.step()?;
    assert_eq!(y.value(1, 1), 40.0, "later values flow through too");
    Ok(())
}

#[test]
fn a_habitat_referenced_before_creation_runs_once_created() -> TestResult {
    let rt = Runtime::new("ref-habitat");
    let log = new_log();
    let early = rt.habitat("h");
    assert!(!early.is_created());
    rt.create_mat(CsMat::from_row_slice("x", 1, 1, &[2.0])?)?;
    rt.install("h", "m", |b| Node::build(b, &log, &["x"], &[], &["y"]))?;
    assert_eq!(early.modules(), ["m"], "installed into the placeholder");

    match early.start() {
        Err(HabitatError::NotCreated(name)) => assert_eq!(name, "h"),
        other => panic!("expected NotCreated, got {other:?}"),
    }
    assert!(matches!(early.step(), Err(HabitatError::NotCreated(_))));
    let report = rt.verify();
    assert_eq!(
        report.problems,
        [Problem::Unbound {
            kind: ObjectKind::Habitat,
            name: "h".into(),
            referenced_by: vec!["m".into()],
        }],
        "{report}"
    );
    assert!(report.to_string().contains("habitat `h`"), "{report}");
    assert!(calls(&log).is_empty(), "nothing ran: {:?}", calls(&log));

    let created = rt.create_habitat("h", manual())?;
    assert!(early.is_created(), "the early handle is the same habitat");
    assert_eq!(created.modules(), ["m"]);
    assert!(rt.verify().is_ok(), "{}", rt.verify());
    early.start()?;
    early.step()?;
    assert_eq!(rt.mat("y").value(0, 0), 3.0);
    assert_eq!(
        calls(&log),
        ["m.startup", "m.enable", "m.execute", "m.state_update"]
    );
    Ok(())
}

// ----- verify: every kind of problem -----

#[test]
fn verify_reports_unbound_mats_habitats_modules_and_groups() -> TestResult {
    let rt = Runtime::new("unbound");
    let log = new_log();
    // A module in a habitat that is never created, reading a CSMat nobody creates.
    rt.install("ghost-habitat", "reader", |b| {
        Node::build(b, &log, &["nowhere"], &[], &["out"])
    })?;
    // A group naming a module never installed, and a configuration naming a group never made.
    rt.group("controllers", "pd", &["reader", "pd-filter"])?;
    rt.configuration("fast", &[("controllers", "lqg")])?;

    let report = rt.verify();
    let expected = [
        Problem::Unbound {
            kind: ObjectKind::Mat,
            name: "nowhere".into(),
            referenced_by: vec!["reader".into()],
        },
        Problem::Unbound {
            kind: ObjectKind::Habitat,
            name: "ghost-habitat".into(),
            referenced_by: vec!["reader".into()],
        },
        Problem::Unbound {
            kind: ObjectKind::Module,
            name: "pd-filter".into(),
            referenced_by: vec!["pd".into()],
        },
        Problem::Unbound {
            kind: ObjectKind::Group,
            name: "lqg".into(),
            referenced_by: vec!["fast".into()],
        },
    ];
    for problem in &expected {
        assert!(
            report.problems.contains(problem),
            "missing {problem:?} in\n{report}"
        );
    }
    assert_eq!(report.problems.len(), expected.len(), "{report}");
    let text = report.to_string();
    for needle in [
        "CSMat `nowhere`",
        "habitat `ghost-habitat`",
        "module `pd-filter`",
        "module group `lqg`",
        "referenced by pd",
        "referenced by fast",
    ] {
        assert!(text.contains(needle), "`{needle}` not in\n{text}");
    }

    // Creating each object clears its problem.
    rt.create_mat(CsMat::zeros("nowhere", 1, 1))?;
    rt.create_habitat("ghost-habitat", manual())?;
    rt.install("ghost-habitat", "pd-filter", |b| {
        Node::build(b, &log, &[], &[], &["filtered"])
    })?;
    rt.group("controllers", "lqg", &[])?;
    assert!(rt.verify().is_ok(), "{}", rt.verify());
    Ok(())
}

#[test]
fn verify_reports_shape_mismatches_whichever_comes_first() -> TestResult {
    let rt = Runtime::new("shapes");
    rt.create_habitat("h", manual())?;
    // Declared before creation...
    rt.install("h", "early", |b| {
        let input = b.input("x", (2, 1));
        Ok(Copy {
            output: b.output("x2", (2, 1)),
            input,
        })
    })?;
    rt.create_mat(CsMat::zeros("x", 3, 1))?;
    // ... and after.
    rt.install("h", "late", |b| {
        let input = b.input("x", (1, 3));
        Ok(Copy {
            output: b.output("x3", (1, 3)),
            input,
        })
    })?;
    let report = rt.verify();
    assert_eq!(
        report.problems,
        [
            Problem::ShapeMismatch {
                mat: "x".into(),
                module: "early".into(),
                expected: Shape::Exact(2, 1),
                actual: (3, 1),
            },
            Problem::ShapeMismatch {
                mat: "x".into(),
                module: "late".into(),
                expected: Shape::Exact(1, 3),
                actual: (3, 1),
            },
        ],
        "{report}"
    );
    let text = report.to_string();
    assert!(
        text.contains("module `early` expects CSMat `x` to be 2x1, it is 3x1"),
        "{text}"
    );
    assert!(text.contains("module `late`"), "{text}");
    Ok(())
}

#[test]
fn verify_reports_a_reader_whose_only_writer_is_inactive() -> TestResult {
    let rt = Runtime::new("producer");
    let log = new_log();
    rt.create_habitat("h", manual())?;
    // The first group of a category is its active one.
    rt.group("source", "idle", &[])?;
    rt.group("source", "live", &["writer"])?;
    rt.configuration("running", &[("source", "live")])?;
    rt.install("h", "writer", |b| Node::build(b, &log, &[], &[], &["u"]))?;
    rt.install("h", "reader", |b| Node::build(b, &log, &["u"], &[], &["v"]))?;
    assert_eq!(rt.habitat("h").order(), ["reader"]);

    let report = rt.verify();
    assert_eq!(
        report.problems,
        [Problem::MissingProducer {
            mat: "u".into(),
            readers: vec!["reader".into()],
            inactive_writers: vec!["writer".into()],
            configuration: None,
        }],
        "{report}"
    );
    let text = report.to_string();
    assert!(text.contains("CSMat `u` is read by reader"), "{text}");
    assert!(text.contains("inactive writers: writer"), "{text}");
    assert!(matches!(
        rt.habitat("h").start(),
        Err(HabitatError::Verify { .. })
    ));

    // In the configuration where the writer is active there is no problem.
    rt.switch("running")?;
    assert!(rt.verify().is_ok(), "{}", rt.verify());
    assert_eq!(rt.habitat("h").order(), ["writer", "reader"]);
    Ok(())
}

#[test]
fn verify_reports_two_active_writers_in_two_habitats() -> TestResult {
    let rt = Runtime::new("writers");
    let log = new_log();
    rt.create_habitat("fast", manual())?;
    rt.create_habitat("slow", manual())?;
    rt.install("fast", "w1", |b| Node::build(b, &log, &[], &[], &["u"]))?;
    // A second active writer in another habitat is refused at install ...
    match rt.install("slow", "w2", |b| Node::build(b, &log, &[], &[], &["u"])) {
        Err(RuntimeError::DoubleWriter { mat, first, second }) => {
            assert_eq!(
                (mat.as_str(), first.as_str(), second.as_str()),
                ("u", "w1", "w2")
            );
        }
        other => panic!("expected a double writer, got {other:?}"),
    }
    assert!(rt.habitat("slow").modules().is_empty());
    // ... so it can only come with a configuration, which verify checks too.
    rt.group("extra", "off", &[])?;
    rt.group("extra", "on", &["w2"])?;
    rt.configuration("both", &[("extra", "on")])?;
    rt.install("slow", "w2", |b| Node::build(b, &log, &[], &[], &["u"]))?;
    let report = rt.verify();
    assert_eq!(
        report.problems,
        [Problem::DoubleWriter {
            mat: "u".into(),
            writers: vec!["w1".into(), "w2".into()],
            configuration: Some("both".into()),
        }],
        "{report}"
    );
    let text = report.to_string();
    assert!(
        text.contains("double writer (in configuration `both`): CSMat `u` is written by w1 and w2"),
        "{text}"
    );
    for habitat in ["fast", "slow"] {
        assert!(matches!(
            rt.habitat(habitat).start(),
            Err(HabitatError::Verify { .. })
        ));
    }
    assert!(calls(&log).iter().all(|c| !c.ends_with(".startup")));
    assert!(matches!(
        rt.switch("both"),
        Err(RuntimeError::DoubleWriter { .. })
    ));
    Ok(())
}

#[test]
fn verify_reports_an_algebraic_loop_that_only_a_configuration_would_close() -> TestResult {
    let rt = Runtime::new("loop");
    let log = new_log();
    rt.create_habitat("h", manual())?;
    rt.group("mode", "open", &[])?;
    rt.group("mode", "closed", &["a", "b"])?;
    rt.configuration("loop", &[("mode", "closed")])?;
    // Both inactive when installed, so the list sorts; together they feed each other.
    rt.install("h", "a", |b| {
        Node::build(b, &log, &["b_out"], &[], &["a_out"])
    })?;
    rt.install("h", "b", |b| {
        Node::build(b, &log, &["a_out"], &[], &["b_out"])
    })?;
    assert!(rt.habitat("h").order().is_empty());

    let report = rt.verify();
    assert_eq!(report.problems.len(), 1, "{report}");
    let Problem::AlgebraicLoop {
        habitat,
        modules,
        mats,
        configuration,
    } = &report.problems[0]
    else {
        panic!("expected an algebraic loop, got\n{report}");
    };
    assert_eq!(habitat, "h");
    assert_eq!(configuration.as_deref(), Some("loop"));
    assert_eq!(sorted(modules.clone()), ["a", "b"]);
    // mats[i] is written by modules[i] and read by the next one.
    for (i, mat) in mats.iter().enumerate() {
        assert_eq!(mat, &format!("{}_out", modules[i]), "{modules:?} {mats:?}");
    }
    let text = report.to_string();
    assert!(
        text.contains("algebraic loop (in configuration `loop`) in habitat `h`"),
        "{text}"
    );
    assert!(
        text.contains("`a`") && text.contains("`b`") && text.contains("a_out"),
        "{text}"
    );

    // Switching to it is refused, and nothing changes.
    match rt.switch("loop") {
        Err(RuntimeError::Sort {
            habitat,
            source: SortError::AlgebraicLoop { modules, .. },
        }) => {
            assert_eq!(habitat, "h");
            assert_eq!(sorted(modules), ["a", "b"]);
        }
        other => panic!("expected a sort error, got {other:?}"),
    }
    assert_eq!(rt.active_groups()["mode"], "open");
    assert!(rt.habitat("h").order().is_empty());
    Ok(())
}

#[test]
fn verify_reports_a_configuration_selecting_a_group_of_another_category() -> TestResult {
    let rt = Runtime::new("category");
    rt.group("sensors", "joint", &[])?;
    rt.group("sensors", "endpoint", &[])?;
    rt.group("controllers", "pd", &[])?;
    rt.group("controllers", "lqg", &[])?;
    rt.configuration("JointPD", &[("sensors", "joint"), ("controllers", "pd")])?;
    rt.configuration("mixed-up", &[("controllers", "endpoint")])?;
    let report = rt.verify();
    assert_eq!(
        report.problems,
        [Problem::WrongCategory {
            configuration: "mixed-up".into(),
            group: "endpoint".into(),
            category: "controllers".into(),
            actual: "sensors".into(),
        }],
        "{report}"
    );
    let text = report.to_string();
    assert!(
        text.contains(
            "configuration `mixed-up` selects group `endpoint` for category `controllers`, but the group belongs to `sensors`"
        ),
        "{text}"
    );
    match rt.switch("mixed-up") {
        Err(RuntimeError::WrongCategory {
            group,
            category,
            actual,
        }) => {
            assert_eq!(
                (group.as_str(), category.as_str(), actual.as_str()),
                ("endpoint", "controllers", "sensors")
            );
        }
        other => panic!("expected WrongCategory, got {other:?}"),
    }
    rt.switch("JointPD")?;
    assert_eq!(rt.current_configuration().as_deref(), Some("JointPD"));
    Ok(())
}

#[test]
fn start_refuses_a_system_that_does_not_verify_and_runs_nothing() -> TestResult {
    let rt = Runtime::new("refuse");
    let log = new_log();
    let h = rt.create_habitat("h", manual())?;
    rt.install("h", "m", |b| Node::build(b, &log, &["x"], &[], &["y"]))?;
    let err = h.start().expect_err("x is unbound");
    let HabitatError::Verify { habitat, report } = &err else {
        panic!("expected a verify error, got {err:?}");
    };
    assert_eq!(habitat, "h");
    assert_eq!(report, &rt.verify(), "the error carries the report");
    assert!(
        report.problems.iter().any(|p| matches!(
            p,
            Problem::Unbound { kind: ObjectKind::Mat, name, .. } if name == "x"
        )),
        "{report}"
    );
    assert!(err.to_string().contains("CSMat `x`"), "{err}");
    assert!(!h.is_running());
    assert!(calls(&log).is_empty(), "no routine ran: {:?}", calls(&log));
    assert!(matches!(h.step(), Err(HabitatError::NotRunning(_))));
    assert!(matches!(rt.start_all(), Err(RuntimeError::Habitat(_))));
    assert!(calls(&log).is_empty(), "no routine ran: {:?}", calls(&log));

    rt.create_mat(CsMat::from_row_slice("x", 1, 1, &[5.0])?)?;
    h.start()?;
    assert!(h.is_running());
    h.step()?;
    assert_eq!(rt.mat("y").value(0, 0), 6.0);
    assert_eq!(
        calls(&log),
        ["m.startup", "m.enable", "m.execute", "m.state_update"]
    );
    Ok(())
}

// ----- install-time errors -----

#[test]
fn a_second_writer_in_one_habitat_is_refused_at_install() -> TestResult {
    let rt = Runtime::new("double");
    let log = new_log();
    rt.create_habitat("h", manual())?;
    rt.install("h", "first", |b| Node::build(b, &log, &[], &[], &["u"]))?;
    let err = rt
        .install("h", "second", |b| Node::build(b, &log, &[], &[], &["u"]))
        .expect_err("two writers of u");
    match &err {
        RuntimeError::Sort {
            habitat,
            source: SortError::DoubleWriter { mat, first, second },
        } => {
            assert_eq!(habitat, "h");
            assert_eq!(
                (mat.as_str(), first.as_str(), second.as_str()),
                ("u", "first", "second")
            );
        }
        other => panic!("expected a double writer, got {other:?}"),
    }
    let text = err.to_string();
    assert!(
        text.contains("`first`") && text.contains("`second`") && text.contains("`u`"),
        "{text}"
    );
    assert_eq!(rt.modules(), ["first"]);
    assert_eq!(rt.habitat("h").modules(), ["first"]);
    assert_eq!(
        calls(&log),
        ["second.terminate"],
        "the refused module is unloaded"
    );
    assert!(rt.verify().is_ok(), "{}", rt.verify());
    Ok(())
}

#[test]
fn an_algebraic_loop_is_refused_at_install() -> TestResult {
    let rt = Runtime::new("loop-install");
    let log = new_log();
    rt.create_habitat("h", manual())?;
    rt.install("h", "a", |b| {
        Node::build(b, &log, &["b_out"], &[], &["a_out"])
    })?;
    let err = rt
        .install("h", "b", |b| {
            Node::build(b, &log, &["a_out"], &[], &["b_out"])
        })
        .expect_err("a and b feed each other");
    match &err {
        RuntimeError::Sort {
            habitat,
            source: SortError::AlgebraicLoop { modules, mats },
        } => {
            assert_eq!(habitat, "h");
            assert_eq!(sorted(modules.clone()), ["a", "b"]);
            assert_eq!(sorted(mats.clone()), ["a_out", "b_out"]);
        }
        other => panic!("expected an algebraic loop, got {other:?}"),
    }
    let text = err.to_string();
    assert!(
        text.contains("habitat `h`") && text.contains("`a`") && text.contains("`b`"),
        "{text}"
    );
    assert_eq!(rt.modules(), ["a"]);
    assert_eq!(rt.habitat("h").order(), ["a"]);
    Ok(())
}

#[test]
fn a_loop_closed_through_a_state_input_is_sorted_writers_first() -> TestResult {
    let rt = Runtime::new("state-loop");
    let log = new_log();
    rt.create_habitat("h", manual())?;
    // Feedthrough: plant <- u <- ctrl; logger <- y, u. Closed by ctrl reading y in
    // state_update only. Installed in the worst order.
    let interfaces: [Interface; 4] = [
        ("logger", &["y", "u", "ref"], &[], &["logged"]),
        ("plant", &["u"], &[], &["y"]),
        ("ctrl", &["ref"], &["y"], &["u"]),
        ("reference", &[], &[], &["ref"]),
    ];
    for (name, reads, state, writes) in interfaces {
        rt.install("h", name, |b| Node::build(b, &log, reads, state, writes))?;
    }
    assert!(rt.verify().is_ok(), "{}", rt.verify());
    let order = rt.habitat("h").order();
    assert_eq!(order, ["reference", "ctrl", "plant", "logger"]);
    for (reader, reads, _, _) in interfaces {
        let at = order.iter().position(|m| m == reader).unwrap();
        for mat in reads {
            let (writer, ..) = interfaces
                .iter()
                .find(|(_, _, _, writes)| writes.contains(mat))
                .unwrap();
            let w = order.iter().position(|m| m == writer).unwrap();
            assert!(w < at, "{writer} (writes {mat}) must run before {reader}");
        }
    }
    let h = rt.habitat("h");
    h.start()?;
    h.step()?;
    // reference: ref = 1; ctrl: u = ref + y(old 0) + 1 = 2; plant: y = 3; logger: 3+2+1+1.
    assert_eq!(rt.mat("u").value(0, 0), 2.0);
    assert_eq!(rt.mat("y").value(0, 0), 3.0);
    assert_eq!(rt.mat("logged").value(0, 0), 7.0);
    Ok(())
}

#[test]
fn duplicate_names_are_refused() -> TestResult {
    let rt = Runtime::new("duplicates");
    let log = new_log();
    rt.create_habitat("h1", manual())?;
    rt.create_habitat("h2", manual())?;
    rt.install("h1", "m", |b| Node::build(b, &log, &[], &[], &["u"]))?;

    let mut built = false;
    let err = rt
        .install("h2", "m", |b| {
            built = true;
            Node::build(b, &log, &[], &[], &["v"])
        })
        .expect_err("a second module m");
    assert!(
        matches!(&err, RuntimeError::Duplicate { kind: ObjectKind::Module, name } if name == "m"),
        "{err:?}"
    );
    assert!(
        err.to_string().contains("module `m` already exists"),
        "{err}"
    );
    assert!(!built, "the duplicate is not even built");
    assert_eq!(rt.habitat("h1").modules(), ["m"]);
    assert!(rt.habitat("h2").modules().is_empty());

    let err = rt.create_habitat("h1", manual()).expect_err("h1 twice");
    assert!(
        matches!(&err, RuntimeError::Duplicate { kind: ObjectKind::Habitat, name } if name == "h1"),
        "{err:?}"
    );

    rt.group("cat", "g", &["m"])?;
    let err = rt.group("other-cat", "g", &[]).expect_err("group g twice");
    assert!(
        matches!(&err, RuntimeError::Duplicate { kind: ObjectKind::Group, name } if name == "g"),
        "{err:?}"
    );

    rt.configuration("c", &[("cat", "g")])?;
    let err = rt
        .configuration("c", &[])
        .expect_err("configuration c twice");
    assert!(
        matches!(&err, RuntimeError::Duplicate { kind: ObjectKind::Configuration, name } if name == "c"),
        "{err:?}"
    );

    rt.create_mat(CsMat::zeros("x", 1, 1))?;
    let err = rt.create_mat(CsMat::zeros("x", 1, 1)).expect_err("x twice");
    assert!(
        matches!(&err, RuntimeError::Duplicate { kind: ObjectKind::Mat, name } if name == "x"),
        "{err:?}"
    );
    assert!(rt.verify().is_ok(), "{}", rt.verify());
    Ok(())
}

#[test]
fn an_unknown_component_type_lists_the_registered_ones() -> TestResult {
    let rt = Runtime::new("registry");
    assert!(
        rt.component_types().is_empty(),
        "a runtime starts without a library"
    );
    ndds_components::register(&rt);
    rt.create_habitat("h", manual())?;
    rt.register_component("my_filter", "test component", |b, _params| {
        Node::build(b, &new_log(), &[], &[], &["f"])
    });
    let err = rt
        .install_component("h", "m", "no_such_type", &Params::new())
        .expect_err("not registered");
    let RuntimeError::UnknownType { name, known } = &err else {
        panic!("expected UnknownType, got {err:?}");
    };
    assert_eq!(name, "no_such_type");
    let known: Vec<&str> = known.split(", ").collect();
    for registered in ["gain", "lowpass", "pd", "my_filter"] {
        assert!(known.contains(&registered), "{known:?}");
    }
    let registered: Vec<String> = rt.component_types().into_iter().map(|(n, _)| n).collect();
    assert_eq!(
        sorted(known.iter().map(|s| (*s).to_owned()).collect()),
        sorted(registered)
    );
    let text = err.to_string();
    assert!(
        text.contains("`no_such_type`") && text.contains("my_filter"),
        "{text}"
    );
    assert!(rt.modules().is_empty());

    rt.install_component("h", "m", "my_filter", &Params::new())?;
    assert_eq!(rt.modules(), ["m"]);
    Ok(())
}

#[test]
fn creating_a_mat_with_another_shape_than_its_writer_declared_is_refused() -> TestResult {
    let rt = Runtime::new("conflict");
    rt.create_habitat("h", manual())?;
    rt.install("h", "w", |b| {
        let input = b.param_or("w.gain", CsMat::zeros("w.gain", 2, 1));
        let output = b.output("y", (2, 1));
        Ok(Copy { input, output })
    })?;
    let y = rt.mat("y");
    assert_eq!(y.shape(), (2, 1), "an output declaration creates it");
    let err = rt
        .create_mat(CsMat::zeros("y", 3, 1))
        .expect_err("y is 2x1");
    match &err {
        RuntimeError::ShapeConflict {
            name,
            rows,
            cols,
            new_rows,
            new_cols,
        } => assert_eq!(
            (name.as_str(), *rows, *cols, *new_rows, *new_cols),
            ("y", 2, 1, 3, 1)
        ),
        other => panic!("expected ShapeConflict, got {other:?}"),
    }
    assert!(err.to_string().contains("`y` is already 2x1"), "{err}");
    assert_eq!(y.shape(), (2, 1), "unchanged");
    // The right shape gives it its initial value.
    rt.create_mat(CsMat::from_row_slice("y", 2, 1, &[7.0, 8.0])?)?;
    assert_eq!((y.value(0, 0), y.value(1, 0)), (7.0, 8.0));
    Ok(())
}

#[test]
fn a_module_whose_constructor_fails_is_not_installed() -> TestResult {
    let rt = Runtime::new("build");
    let h = rt.create_habitat("h", manual())?;
    let err = rt
        .install("h", "broken", |b| {
            let _input = b.input("broken.in", (1, 1));
            let _output = b.output("broken.out", (2, 2));
            Err::<Copy, _>(ModuleError::Failed("no hardware".into()))
        })
        .expect_err("the constructor fails");
    match &err {
        RuntimeError::Build { module, source } => {
            assert_eq!(module, "broken");
            assert!(matches!(source, ModuleError::Failed(why) if why == "no hardware"));
        }
        other => panic!("expected Build, got {other:?}"),
    }
    assert!(
        err.to_string().contains("`broken`") && err.to_string().contains("no hardware"),
        "{err}"
    );
    assert!(rt.modules().is_empty());
    assert!(h.modules().is_empty());
    assert!(h.order().is_empty());
    assert!(
        rt.verify().is_ok(),
        "no dangling reference: {}",
        rt.verify()
    );
    // The name is free again.
    rt.install("h", "broken", |b| {
        Node::build(b, &new_log(), &[], &[], &["fixed"])
    })?;
    assert_eq!(rt.modules(), ["broken"]);
    Ok(())
}

/// A failed install must leave the database as it was: the CSMats the failed constructor
/// declared are not created, so the application can still create them with any shape.
#[test]
fn a_failed_build_leaves_no_csmat_behind() -> TestResult {
    let rt = Runtime::new("build-trace");
    rt.create_habitat("h", manual())?;
    let _ = rt
        .install("h", "broken", |b| {
            let _output = b.output("phantom", (2, 2));
            Err::<Copy, _>(ModuleError::Failed("no hardware".into()))
        })
        .expect_err("the constructor fails");
    let phantom = rt.create_mat(CsMat::zeros("phantom", 3, 3));
    assert!(
        phantom.is_ok(),
        "`phantom` was declared only by a module that was never installed, yet: {phantom:?}"
    );
    Ok(())
}

/// The same when the sort refuses the module after it was built: its outputs are not created.
#[test]
fn a_module_refused_by_the_sort_leaves_no_csmat_behind() -> TestResult {
    let rt = Runtime::new("sort-trace");
    let log = new_log();
    rt.create_habitat("h", manual())?;
    rt.install("h", "a", |b| {
        Node::build(b, &log, &["b_out"], &[], &["a_out"])
    })?;
    let _ = rt
        .install("h", "b", |b| {
            Node::build(b, &log, &["a_out"], &[], &["b_out"])
        })
        .expect_err("loop");
    // b_out was declared only by the refused `b`: `a` reads a CSMat nobody created.
    let report = rt.verify();
    assert_eq!(
        report.problems,
        [Problem::Unbound {
            kind: ObjectKind::Mat,
            name: "b_out".into(),
            referenced_by: vec!["a".into()],
        }],
        "{report}"
    );
    Ok(())
}

// ----- switching -----

#[test]
fn switching_to_an_unknown_configuration_is_refused() -> TestResult {
    let rt = Runtime::new("unknown");
    rt.group("cat", "g", &[])?;
    let err = rt.switch("nope").expect_err("no such configuration");
    assert!(
        matches!(&err, RuntimeError::Unknown { kind: ObjectKind::Configuration, name } if name == "nope"),
        "{err:?}"
    );
    assert!(err.to_string().contains("configuration `nope`"), "{err}");
    // A configuration naming a group that does not exist cannot be switched to either.
    rt.configuration("dangling", &[("cat", "missing")])?;
    assert!(matches!(
        rt.switch("dangling"),
        Err(RuntimeError::Unknown {
            kind: ObjectKind::Group,
            ..
        })
    ));
    assert_eq!(rt.active_groups()["cat"], "g");
    assert_eq!(rt.current_configuration(), None);
    Ok(())
}

#[test]
fn a_switch_that_would_make_a_double_writer_changes_nothing() -> TestResult {
    let rt = Runtime::new("switch");
    let log = new_log();
    let h = rt.create_habitat("h", manual())?;
    let other = rt.create_habitat("other", manual())?;
    rt.group("ctl", "a", &["w1"])?;
    rt.group("ctl", "b", &["w3"])?;
    rt.group("extra", "off", &[])?;
    rt.group("extra", "on", &["w2"])?;
    rt.group("remote", "quiet", &[])?;
    rt.group("remote", "loud", &["w4"])?;
    rt.install("h", "w1", |b| Node::build(b, &log, &[], &[], &["u"]))?;
    rt.install("h", "w3", |b| Node::build(b, &log, &[], &[], &["u"]))?;
    rt.install("h", "w2", |b| Node::build(b, &log, &[], &[], &["u"]))?;
    rt.install("other", "w4", |b| Node::build(b, &log, &[], &[], &["u"]))?;
    rt.install("h", "reader", |b| Node::build(b, &log, &["u"], &[], &["r"]))?;
    h.start()?;
    other.start()?;
    h.step()?;
    assert_eq!(h.order(), ["w1", "reader"]);

    // Defined while running (a habitat would not start with them: verify checks every
    // configuration).
    rt.configuration("both", &[("ctl", "b"), ("extra", "on")])?;
    rt.configuration("across", &[("ctl", "b"), ("remote", "loud")])?;
    rt.configuration("swap", &[("ctl", "b")])?;
    let groups = rt.active_groups();
    let before = calls(&log);

    match rt.switch("both") {
        Err(RuntimeError::Sort {
            habitat,
            source: SortError::DoubleWriter { mat, first, second },
        }) => {
            assert_eq!(habitat, "h");
            assert_eq!(mat, "u");
            assert_eq!(sorted(vec![first, second]), ["w2", "w3"]);
        }
        other => panic!("expected a double writer in h, got {other:?}"),
    }
    match rt.switch("across") {
        Err(RuntimeError::DoubleWriter { mat, first, second }) => {
            assert_eq!(mat, "u");
            assert_eq!(sorted(vec![first, second]), ["w3", "w4"]);
        }
        other => panic!("expected a double writer across habitats, got {other:?}"),
    }
    assert_eq!(rt.active_groups(), groups, "active groups unchanged");
    assert_eq!(h.order(), ["w1", "reader"], "order unchanged");
    assert!(other.order().is_empty());
    assert_eq!(calls(&log), before, "no enable or disable");
    assert_eq!(rt.current_configuration(), None);
    h.step()?;

    // A valid switch enables the entering module (prepared while the old set samples), then
    // disables the leaving one after its last sample.
    let mark = calls(&log).len();
    rt.switch("swap")?;
    assert_eq!(calls(&log)[mark..], ["w3.enable", "w1.disable"]);
    assert_eq!(h.order(), ["w3", "reader"]);
    assert_eq!(rt.current_configuration().as_deref(), Some("swap"));
    Ok(())
}

#[test]
fn verify_reports_a_loop_beside_a_double_writer_in_the_same_set() -> TestResult {
    let rt = Runtime::new("both");
    let log = new_log();
    rt.create_habitat("h", manual())?;
    rt.group("mode", "off", &[])?;
    rt.group("mode", "bad", &["a", "b", "w1", "w2"])?;
    rt.configuration("bad", &[("mode", "bad")])?;
    rt.install("h", "a", |b| {
        Node::build(b, &log, &["b_out"], &[], &["a_out"])
    })?;
    rt.install("h", "b", |b| {
        Node::build(b, &log, &["a_out"], &[], &["b_out"])
    })?;
    rt.install("h", "w1", |b| Node::build(b, &log, &[], &[], &["twice"]))?;
    rt.install("h", "w2", |b| Node::build(b, &log, &[], &[], &["twice"]))?;
    let report = rt.verify();
    let double = report.problems.iter().any(|p| {
        matches!(p, Problem::DoubleWriter { mat, writers, .. }
            if mat == "twice" && writers == &["w1".to_owned(), "w2".to_owned()])
    });
    let cycle = report.problems.iter().any(|p| {
        matches!(p, Problem::AlgebraicLoop { modules, .. }
            if sorted(modules.clone()) == ["a", "b"])
    });
    assert!(double && cycle, "both problems reported:\n{report}");
    Ok(())
}

#[test]
fn a_habitat_with_an_unusable_rate_is_not_created() -> TestResult {
    let rt = Runtime::new("rates");
    for hz in [0.0, -5.0, f64::NAN, f64::INFINITY, 2e6] {
        match rt.create_habitat("h", HabitatOptions::rate(hz)) {
            Err(RuntimeError::Habitat(HabitatError::InvalidRate { habitat, .. })) => {
                assert_eq!(habitat, "h")
            }
            other => panic!("{hz} Hz: expected InvalidRate, got {other:?}"),
        }
        assert!(!rt.habitat("h").is_created());
    }
    let mut options = HabitatOptions::rate(100.0);
    options.period = std::time::Duration::ZERO;
    assert!(rt.create_habitat("h", options).is_err());
    rt.create_habitat("h", HabitatOptions::rate(0.5))?;
    Ok(())
}

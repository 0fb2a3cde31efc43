//! Modules (Shin's module layer) over real ports, through a real daemon: checked before they
//! run with every problem at once, handlers run under the module's order at preemption
//! points, timeouts run exception handlers.

mod common;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ndds_client::ports::{
    ModuleBuilder, ModuleError, PortError, PortOwner, PortUser, Restrictions, Usage,
};

const WAIT: Duration = Duration::from_secs(10);

fn participant(dir: &std::path::Path, name: &str) -> ndds_client::Participant {
    common::participant(&common::unique_config(dir, name))
}

/// A log of what happened, shared by the module's sections and the test.
#[derive(Clone, Default)]
struct Log(Arc<Mutex<Vec<String>>>);

impl Log {
    fn push(&self, what: impl Into<String>) {
        self.0.lock().unwrap().push(what.into());
    }
    fn take(&self) -> Vec<String> {
        self.0.lock().unwrap().clone()
    }
}

#[test]
fn chip_its_order_answers_the_critical_section_query_only_while_insert_runs() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "chip-it");
    // CHIP_IT2's end: it owns SHARE_FEEDER1 and queries CHIP_IT through it.
    let chip_it2 = PortOwner::<u32, i32>::declare_with(
        &p,
        "SHARE_FEEDER1",
        "CHIP_IT2",
        Restrictions {
            usages: vec![Usage::Query],
            users: vec!["CHIP_IT".into()],
            ..Restrictions::default()
        },
    )
    .unwrap();
    let log = Log::default();
    let (answers, sections) = (log.clone(), log.clone());
    let module = ModuleBuilder::new(&p, "CHIP_IT")
        .uses::<u32, i32>("SHARE_FEEDER1", &[Usage::Response], None)
        .response("SHARE_FEEDER1.CRIT_SECTION", move |_: u32| {
            answers.push("answered");
            1
        })
        .subprogram("GRASP")
        .subprogram("INSERT")
        .order("ORDER(CHIP_IT, GRASP, SHARE_FEEDER1.CRIT_SECTION, INSERT)")
        .body(move |ctx| {
            for _ in 0..4 {
                for section in ["GRASP", "INSERT"] {
                    let stopped = ctx.section(section, || {
                        sections.push(format!("{section} begins"));
                        let stopped = ctx.delay(Duration::from_millis(150)).is_err();
                        sections.push(format!("{section} ends"));
                        stopped
                    });
                    if stopped {
                        return;
                    }
                }
                // The background code between steps: not to be preempted either.
                if ctx.delay(Duration::from_millis(150)).is_err() {
                    return;
                }
            }
        })
        .load()
        .unwrap();
    let running = module.start().unwrap();
    assert!(common::eventually(WAIT, || !chip_it2
        .present_users()
        .is_empty()));
    // Queries arrive at any time; each is answered only when INSERT runs.
    for _ in 0..3 {
        assert_eq!(chip_it2.query(&1, WAIT).unwrap(), 1);
    }
    let handled = running.handled();
    assert_eq!(handled.len(), 3, "{handled:?}");
    assert!(
        handled
            .iter()
            .all(|h| h == "SHARE_FEEDER1.CRIT_SECTION in INSERT"),
        "{handled:?}"
    );
    // And in the log, each answer falls within INSERT: at its entry (a preemption point,
    // before its first statement) or while it runs — never in GRASP or the background code.
    let events = log.take();
    let mut last = "";
    for event in &events {
        if event == "answered" {
            assert!(
                matches!(last, "GRASP ends" | "INSERT begins"),
                "answered after `{last}`: {events:?}"
            );
        } else {
            last = event;
        }
    }
    running.stop();
}

#[test]
fn a_timeout_runs_the_ports_exception_handler_under_the_order() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "gate");
    // RELEASE owns LET_1_GO but is hung: it never replies.
    let _release = PortOwner::<u32, i32>::declare(&p, "LET_1_GO", "RELEASE").unwrap();
    let log = Log::default();
    let (exceptions, body_log) = (log.clone(), log.clone());
    let module = ModuleBuilder::new(&p, "GATE")
        .uses::<u32, i32>("LET_1_GO", &[Usage::Send], Some(Duration::from_millis(300)))
        .exception("LET_1_GO.TIMEOUT", move |ctx| {
            exceptions.push(format!("{} handles the timeout", ctx.name()));
        })
        .order("ORDER(LET_1_GO.TIMEOUT, GATE)")
        .body(move |ctx| {
            let started = Instant::now();
            let result = ctx.send::<u32, i32>("LET_1_GO", &1);
            let timed_out = matches!(result, Err(ModuleError::Port(PortError::Timeout { .. })));
            body_log.push(format!(
                "send returned (timed out: {timed_out}, after at least 300 ms: {})",
                started.elapsed() >= Duration::from_millis(300)
            ));
        })
        .load()
        .unwrap();
    let running = module.start().unwrap();
    assert!(common::eventually(WAIT, || log.take().len() == 2));
    assert_eq!(
        log.take(),
        [
            "GATE handles the timeout",
            "send returned (timed out: true, after at least 300 ms: true)"
        ]
    );
    assert_eq!(running.handled(), ["LET_1_GO.TIMEOUT in GATE"]);
    running.stop();
}

#[test]
fn a_module_that_does_not_hold_together_is_refused_with_every_problem() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "load");
    let err = ModuleBuilder::new(&p, "LOAD_CARD")
        // Usage Response without a response handler for the port.
        .uses::<u32, i32>("ASK_CHILD1", &[Usage::Response], None)
        // A handler whose types are not the port's.
        .uses::<u32, i32>("CARD_IN_PLACE", &[Usage::Response], None)
        .response("CARD_IN_PLACE.DONE", |s: String| s)
        // An exception handler for a port without a timeout.
        .owns::<(), ()>("PALLET_IN_PLACE", Restrictions::default())
        .exception("PALLET_IN_PLACE.TIMEOUT", |_| {})
        .order("ORDER(PALLET_IN_PLACE.TIMEOUT, ASK_CHILD1.STATUS, LOAD_CARD)")
        .load()
        .err()
        .unwrap();
    let ModuleError::Load(load) = &err else {
        panic!("{err}")
    };
    let text: Vec<String> = load.problems.iter().map(ToString::to_string).collect();
    assert_eq!(
        text,
        [
            "port `ASK_CHILD1` is used with usage Response but no response handler `ASK_CHILD1.NAME` is declared",
            "handler `PALLET_IN_PLACE.TIMEOUT`: port `PALLET_IN_PLACE` has no timeout restriction",
            "the order names `ASK_CHILD1.STATUS`, which is not the module, a subprogram, or a declared handler",
            &format!(
                "port `CARD_IN_PLACE`: `LOAD_CARD (handler `CARD_IN_PLACE.DONE`)` uses message formats {} but the owner's are {}",
                fingerprints::<String, String>(),
                fingerprints::<u32, i32>()
            ),
        ],
        "{err}"
    );
    // Nothing was declared: the module's ports are not on the network.
    std::thread::sleep(Duration::from_millis(200));
    let graph = p.graph().unwrap();
    assert!(
        !graph
            .endpoints
            .iter()
            .any(|e| e.info.topic.starts_with("port/PALLET_IN_PLACE/")),
        "a refused module declared a port"
    );
}

fn fingerprints<
    Q: serde::Serialize + serde::de::DeserializeOwned,
    R: serde::Serialize + serde::de::DeserializeOwned,
>() -> String {
    format!(
        "{:016x}/{:016x}",
        ndds_client::TypeDescription::of::<Q>().fingerprint(),
        ndds_client::TypeDescription::of::<R>().fingerprint()
    )
}

#[test]
fn a_users_query_is_answered_by_the_owning_modules_response_handler() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "status");
    let module = ModuleBuilder::new(&p, "LOAD_IT")
        .owns::<u32, u32>(
            "STATUS",
            Restrictions {
                usages: vec![Usage::Response],
                ..Restrictions::default()
            },
        )
        .response("STATUS.NUM_LOADED", |n: u32| n + 40)
        .load()
        .unwrap();
    let running = module.start().unwrap();
    let asker =
        PortUser::<u32, u32>::declare_with(&p, "STATUS", "operator", &[Usage::Query]).unwrap();
    assert_eq!(asker.query(&2, WAIT).unwrap(), 42);
    assert_eq!(running.handled(), ["STATUS.NUM_LOADED"]);
    running.stop();
}

/// LOAD_IT and its children, as in the appendix: LOAD_IT starts LOAD_CARD and SCREW_IN_CARD
/// with `costart` and queries LOAD_CARD's status through ASK_CHILD1.
fn load_it(p: &ndds_client::Participant, loaded: u32) -> ModuleBuilder {
    let load_card = ModuleBuilder::new(p, "LOAD_CARD")
        .uses::<(), u32>("ASK_CHILD1", &[Usage::Response], None)
        .response("ASK_CHILD1.STATUS", move |()| loaded)
        .task("FREEZE_PALLET", |task| {
            while !task.stopping() {
                std::thread::sleep(Duration::from_millis(20));
            }
        });
    let screw_in_card = ModuleBuilder::new(p, "SCREW_IN_CARD");
    ModuleBuilder::new(p, "LOAD_IT")
        .owns::<(), u32>(
            "ASK_CHILD1",
            Restrictions {
                usages: vec![Usage::Query],
                users: vec!["LOAD_CARD".into()],
                timeout_ms: Some(2_000),
                ..Restrictions::default()
            },
        )
        .child(load_card)
        .child(screw_in_card)
}

#[test]
fn costart_starts_the_children_and_the_parent_queries_them() {
    use ndds_client::ports::{ModuleInfo, PortWire};
    use ndds_client::{ConsumerQos, Reliability};

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "costart");
    let statuses = Log::default();
    let seen = statuses.clone();
    let module = load_it(&p, 17)
        .body(move |ctx| {
            // A child that is not one is refused, and starts nothing.
            let err = ctx.costart(&["LOAD_CARD", "GATE"]).unwrap_err();
            seen.push(err.to_string());
            ctx.costart(&["LOAD_CARD", "SCREW_IN_CARD"]).unwrap();
            let status: u32 = ctx.query("ASK_CHILD1", &()).unwrap();
            seen.push(format!("LOAD_CARD has loaded {status}"));
        })
        .load()
        .unwrap();
    let running = module.start().unwrap();
    assert!(common::eventually(WAIT, || statuses.take().len() == 2));
    assert_eq!(
        statuses.take(),
        [
            "module `LOAD_IT` has no child `GATE` to start (not declared with `child`, or started already)",
            "LOAD_CARD has loaded 17",
        ]
    );
    // Each module declares itself, with its parent: the tree.
    let reliable = ConsumerQos {
        reliability: Reliability::Reliable { depth: 4 },
        ..ConsumerQos::default()
    };
    let declaration = |name: &str| {
        p.consumer_with_type::<ModuleInfo>(
            &format!("module/{name}"),
            ModuleInfo::description(),
            reliable,
        )
        .unwrap()
        .recv_timeout(WAIT)
        .unwrap()
        .value
    };
    let parent = declaration("LOAD_IT");
    assert_eq!(
        (parent.parent, parent.children, parent.owns),
        (
            None,
            vec!["LOAD_CARD".to_owned(), "SCREW_IN_CARD".to_owned()],
            vec!["ASK_CHILD1".to_owned()]
        )
    );
    let child = declaration("LOAD_CARD");
    assert_eq!(
        (child.parent.as_deref(), child.tasks, child.uses),
        (
            Some("LOAD_IT"),
            vec!["FREEZE_PALLET".to_owned()],
            vec!["ASK_CHILD1".to_owned()]
        )
    );
    assert_eq!(child.pid, std::process::id());
    // Stopping the parent stops its children (and their tasks).
    running.stop();
    let graph_has = |topic: &str| {
        p.graph().unwrap().endpoints.iter().any(|e| {
            e.info.topic == topic && e.info.kind() == ndds_core::wire::EndpointKind::Producer
        })
    };
    assert!(common::eventually(WAIT, || !graph_has("module/LOAD_CARD")
        && !graph_has("module/LOAD_IT")));
}

#[test]
fn a_childs_problems_are_reported_with_the_parents() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "costart-load");
    let broken_child = ModuleBuilder::new(&p, "SCREW_IN_CARD").uses::<(), u32>(
        "ASK_CHILD2",
        &[Usage::Response],
        None,
    );
    let err = load_it(&p, 0).child(broken_child).load().err().unwrap();
    let text = err.to_string();
    assert!(
        text.contains("in `SCREW_IN_CARD`: port `ASK_CHILD2` is used with usage Response but no response handler"),
        "{text}"
    );
    // Two children of one name (load_it has one already).
    assert!(
        text.contains("child `SCREW_IN_CARD` is declared twice"),
        "{text}"
    );
}

#[test]
fn a_work_schedule_from_a_file_runs_its_steps_and_goes_on_past_an_empty_feeder() {
    use ndds_client::ports::Performed;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "schedule");
    let file = dir.path().join("chip_it.schedule");
    std::fs::write(
        &file,
        "-- CHIP_IT's card: every chip the same priority\n\
         1) GRASP(1), INSERT(10, 20, 3)\n\
         1) GRASP(4), INSERT(12, 20, 3)\n\
         1) GRASP(12), INSERT(14, 20, 3)\n",
    )
    .unwrap();
    let log = Log::default();
    let calls = log.clone();
    let module = ModuleBuilder::new(&p, "CHIP_IT")
        .subprogram("GRASP")
        .subprogram("INSERT")
        .schedule_file(&file)
        .body(move |ctx| {
            let mut feeder4 = 0; // empty until the operator refills it
            let run = |ctx: &ndds_client::ports::ModuleContext, feeder4: u32| {
                while ctx.more() > 0 {
                    let performed = ctx.perform(|call| {
                        let args: Vec<String> = call.args.iter().map(ToString::to_string).collect();
                        calls.push(format!("{}({})", call.name, args.join(",")));
                        let empty = call.name == "GRASP" && args == ["4"] && feeder4 == 0;
                        i32::from(empty)
                    });
                    if let Performed::Failed { code, .. } = performed {
                        calls.push(format!("feeder empty ({code}): operator told"));
                    }
                }
            };
            ctx.reinstate();
            run(ctx, feeder4);
            feeder4 = 10;
            calls.push(format!("refilled: {} step(s) again", ctx.retry_failed()));
            run(ctx, feeder4);
        })
        .load()
        .unwrap();
    let running = module.start().unwrap();
    assert!(common::eventually(WAIT, || log.take().len() == 9));
    assert_eq!(
        log.take(),
        [
            "GRASP(1)",
            "INSERT(10,20,3)",
            "GRASP(4)",
            "feeder empty (1): operator told",
            "GRASP(12)",
            "INSERT(14,20,3)",
            "refilled: 1 step(s) again",
            // The failed step resumes at the call that failed.
            "GRASP(4)",
            "INSERT(12,20,3)",
        ]
    );
    running.stop();
    // A schedule that calls what the module does not declare is refused at load, and so is
    // one that does not read, naming its file.
    let load = |text: &str| {
        std::fs::write(&file, text).unwrap();
        ModuleBuilder::new(&p, "CHIP_IT2")
            .subprogram("GRASP")
            .subprogram("INSERT")
            .schedule_file(&file)
            .load()
            .err()
            .unwrap()
            .to_string()
    };
    let err = load("1) GRASP(1), INSRET(10, 20, 3)\n");
    assert!(
        err.contains(
            "work schedule: line 1 calls `INSRET`, which is not a subprogram of the module"
        ),
        "{err}"
    );
    let err = load("1) GRASP(1\n");
    assert!(
        err.contains(&format!("work schedule: {}: line 1", file.display())),
        "{err}"
    );
}

#[test]
fn without_an_order_handlers_interrupt_the_body_and_a_panic_leaves_the_sections_right() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "no-order");
    let module = ModuleBuilder::new(&p, "CELL")
        .owns::<u32, u32>(
            "STATUS",
            Restrictions {
                usages: vec![Usage::Response],
                ..Restrictions::default()
            },
        )
        .response("STATUS.NOW", |n: u32| n * 2)
        .subprogram("WORK")
        .body(|ctx| {
            // A subprogram that panics: its section is left all the same.
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                ctx.section("WORK", || panic!("a tool broke"))
            }));
            // The body runs on (a long motion); queries are answered meanwhile.
            let _ = ctx.delay(Duration::from_secs(30));
        })
        .load()
        .unwrap();
    let running = module.start().unwrap();
    let asker =
        PortUser::<u32, u32>::declare_with(&p, "STATUS", "operator", &[Usage::Query]).unwrap();
    assert_eq!(asker.query(&21, WAIT).unwrap(), 42);
    // It ran inside the body's section (not inside a WORK left open by the panic).
    assert_eq!(running.handled(), ["STATUS.NOW in CELL"]);
    running.stop();
}

/// LOAD_IT's tree as a specification file: the code only binds what it declares.
const LOAD_IT_FILE: &str = r#"
[[module]]
name = "LOAD_IT"
children = ["LOAD_CARD", "SCREW_IN_CARD"]

[[module.owns]]
port = "ASK_CHILD1"
usages = ["query"]
users = ["LOAD_CARD"]
timeout = 2.0

[[module]]
name = "LOAD_CARD"
tasks = ["FREEZE_PALLET"]
responses = ["ASK_CHILD1.STATUS"]

[[module.uses]]
port = "ASK_CHILD1"
usages = ["response"]

[[module]]
name = "SCREW_IN_CARD"
subprograms = ["SCREW"]
schedule_file = "screw.schedule"
"#;

#[test]
fn a_module_tree_from_a_specification_file_binds_its_code_and_runs() {
    use ndds_client::ports::ModuleFile;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "file-tree");
    std::fs::write(dir.path().join("load_it.toml"), LOAD_IT_FILE).unwrap();
    std::fs::write(
        dir.path().join("screw.schedule"),
        "1) SCREW(1)\n2) SCREW(2)\n",
    )
    .unwrap();
    let file = ModuleFile::read(dir.path().join("load_it.toml")).unwrap();
    assert!(
        file.check().is_empty(),
        "the tree holds together: {:?}",
        file.check()
    );
    let statuses = Log::default();
    let (seen, screwed) = (statuses.clone(), statuses.clone());
    let load_card = ModuleBuilder::from_file(&p, &file, "LOAD_CARD")
        .unwrap()
        .port::<(), u32>("ASK_CHILD1")
        .response("ASK_CHILD1.STATUS", |()| 23u32)
        .task("FREEZE_PALLET", |task| {
            while !task.stopping() {
                std::thread::sleep(Duration::from_millis(20));
            }
        });
    let screw_in_card = ModuleBuilder::from_file(&p, &file, "SCREW_IN_CARD")
        .unwrap()
        .body(move |ctx| {
            while ctx.more() > 0 {
                ctx.perform(|call| {
                    screwed.push(format!("{}({})", call.name, call.args[0]));
                    0
                });
            }
        });
    let module = ModuleBuilder::from_file(&p, &file, "LOAD_IT")
        .unwrap()
        .port::<(), u32>("ASK_CHILD1")
        .child(load_card)
        .child(screw_in_card)
        .body(move |ctx| {
            // The file's restrictions are the port's.
            let owner = ctx.owner::<(), u32>("ASK_CHILD1").unwrap();
            let r = owner.restrictions();
            seen.push(format!("{:?} {:?} {:?}", r.usages, r.users, r.timeout_ms));
            ctx.costart(&["LOAD_CARD", "SCREW_IN_CARD"]).unwrap();
            let status: u32 = ctx.query("ASK_CHILD1", &()).unwrap();
            seen.push(format!("LOAD_CARD has loaded {status}"));
        })
        .load()
        .unwrap();
    let running = module.start().unwrap();
    assert!(common::eventually(WAIT, || statuses.take().len() == 4));
    let mut got = statuses.take();
    got.sort();
    assert_eq!(
        got,
        [
            "LOAD_CARD has loaded 23",
            "SCREW(1)",
            "SCREW(2)",
            "[Query] [\"LOAD_CARD\"] Some(2000)"
        ]
    );
    running.stop();
}

#[test]
fn code_that_disagrees_with_its_specification_file_is_refused_naming_where() {
    use ndds_client::ports::ModuleFile;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "file-mismatch");
    // A schedule file that is not there is reported where the file names it.
    let err = ModuleFile::parse("load_it.toml", LOAD_IT_FILE).unwrap_err();
    assert_eq!(err.problems.len(), 1, "{err}");
    assert!(
        err.problems[0].starts_with("load_it.toml:24:17: screw.schedule: "),
        "{err}"
    );
    let file = ModuleFile::parse(
        "load_it.toml",
        &LOAD_IT_FILE.replace(
            "schedule_file = \"screw.schedule\"",
            "schedule = \"1) SCREW(1)\"",
        ),
    )
    .unwrap();
    // LOAD_CARD: the port's types not bound, the task without a body, a handler and a port
    // the file does not declare.
    let load_card = ModuleBuilder::from_file(&p, &file, "LOAD_CARD")
        .unwrap()
        .response("ASK_CHILD1.STATUS", |()| 0u32)
        .response("ASK_CHILD1.STATUS", |()| 1u32)
        .response("ASK_CHILD1.OTHER", |()| 0u32)
        .uses::<u32, u32>("EXTRA", &[Usage::Send], None);
    let err = ModuleBuilder::from_file(&p, &file, "LOAD_IT")
        .unwrap()
        .port::<(), u32>("ASK_CHILD1")
        .port::<(), u32>("ASK_CHILD1")
        .child(load_card)
        .load()
        .err()
        .expect("refused")
        .to_string();
    for expected in [
        "port binding `ASK_CHILD1` is declared twice",
        "load_it.toml:4:26: child `SCREW_IN_CARD` is not given",
        "in `LOAD_CARD`: load_it.toml:17:1: port `ASK_CHILD1` is declared here but its message types are not bound",
        "in `LOAD_CARD`: load_it.toml:14:10: task `FREEZE_PALLET` has no body",
        "in `LOAD_CARD`: load_it.toml: response handler `ASK_CHILD1.OTHER` is declared in code but not in the module's specification",
        "in `LOAD_CARD`: load_it.toml: used port `EXTRA` is declared in code but not in the module's specification",
        "in `LOAD_CARD`: load_it.toml: response handler `ASK_CHILD1.STATUS` is given a body twice in code",
    ] {
        assert!(err.contains(expected), "missing {expected:?} in: {err}");
    }
    // And nothing else: every problem is said once.
    assert_eq!(err.matches("; ").count(), 6, "{err}");
    // A module the file does not declare.
    let err = ModuleBuilder::from_file(&p, &file, "GATE").err().unwrap();
    assert!(
        err.to_string()
            .contains("no module `GATE`; it declares `LOAD_IT`, `LOAD_CARD`, `SCREW_IN_CARD`"),
        "{err}"
    );
    // A file's port bound on a module that has no file.
    let err = ModuleBuilder::new(&p, "PLAIN")
        .port::<u32, u32>("P")
        .load()
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("binds a port of a module file"), "{err}");
}

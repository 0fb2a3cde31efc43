//! State machines on their own thread: one queue fed from several threads and from the
//! network, processed in arrival order; actions that drive a runtime; verification before
//! anything runs.

#[path = "../../ndds-client/tests/common/mod.rs"]
mod common;

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use ndds_client::{ConsumerQos, ProducerQos, Reliability};
use ndds_components::Gain;
use ndds_runtime::fsm::{
    ActionSet, FsmError, FsmProblem, MachineState, Program, StateMachine, Stimulus, StimulusKind,
};
use ndds_runtime::{
    Clock, CsMat, HabitatOptions, ModuleError, RoutineResult, Runtime, SampleContext, SampleModule,
};

const WAIT: Duration = Duration::from_secs(5);

/// Counts `Tick`s: every tick goes Even -> Odd -> Even, and the action records its order.
fn counter(log: Arc<Mutex<Vec<String>>>) -> (Program, ActionSet) {
    let mut p = Program::new("counter", "Even");
    p.stimulus("Tick", StimulusKind::Transient);
    p.machine("counter", "Even")
        .states(&["Odd"])
        .transition("Even", "Tick", "note even", &[(0, "Odd")])
        .unwrap()
        .transition("Odd", "Tick", "note odd", &[(0, "Even")])
        .unwrap();
    let mut actions = ActionSet::new();
    actions.add("note", &[0], move |arg| {
        log.lock().unwrap().push(arg.unwrap_or("").to_owned());
        Ok(0)
    });
    (p, actions)
}

#[test]
fn stimuli_from_several_threads_are_processed_one_at_a_time_in_order() {
    let log = Arc::new(Mutex::new(Vec::new()));
    let (program, actions) = counter(log.clone());
    let fsm = Arc::new(StateMachine::start(program, actions).unwrap());
    let threads: Vec<_> = (0..4)
        .map(|_| {
            let fsm = Arc::clone(&fsm);
            std::thread::spawn(move || {
                for _ in 0..250 {
                    fsm.send(Stimulus::event("Tick")).unwrap();
                }
            })
        })
        .collect();
    for t in threads {
        t.join().unwrap();
    }
    assert!(common::eventually(WAIT, || fsm.snapshot().transitions == 1000));
    let log = log.lock().unwrap();
    assert_eq!(log.len(), 1000);
    // One at a time: the actions strictly alternate.
    for (i, entry) in log.iter().enumerate() {
        assert_eq!(entry, if i % 2 == 0 { "even" } else { "odd" }, "entry {i}");
    }
    assert_eq!(fsm.snapshot().state, "Even");
}

#[test]
fn a_program_that_does_not_verify_does_not_start() {
    let (mut program, actions) = counter(Arc::default());
    program
        .machine("counter", "Even")
        .transition("Odd", "Tock", "launch", &[(0, "Nowhere")])
        .unwrap();
    let Err(FsmError::Verify { machine, problems }) = StateMachine::start(program, actions) else {
        panic!("expected a verify error");
    };
    assert_eq!(machine, "counter");
    for expected in [
        FsmProblem::UnknownStimulus {
            machine: "counter".into(),
            transition: 2,
            stimulus: "Tock".into(),
        },
        FsmProblem::UnknownAction {
            machine: "counter".into(),
            transition: 2,
            action: "launch".into(),
        },
        FsmProblem::UnknownState {
            machine: "counter".into(),
            state: "Nowhere".into(),
            context: "successor of code 0 in transition 2".into(),
        },
    ] {
        assert!(
            problems.contains(&expected),
            "{expected:?} in {problems:#?}"
        );
    }
}

#[test]
fn a_full_queue_refuses_more() {
    let mut p = Program::new("slow", "A");
    p.stimulus("Go", StimulusKind::Transient);
    p.machine("slow", "A")
        .transition("A", "Go", "wait", &[(0, "A")])
        .unwrap();
    let gate = Arc::new(Mutex::new(()));
    let held = gate.lock().unwrap();
    let mut actions = ActionSet::new();
    let inner = Arc::clone(&gate);
    actions.add("wait", &[0], move |_| {
        drop(inner.lock().unwrap());
        Ok(0)
    });
    let fsm = StateMachine::start(p, actions).unwrap();
    let mut refused = None;
    for i in 0..ndds_runtime::fsm::QUEUE_LIMIT + 10 {
        if let Err(err) = fsm.send(Stimulus::event("Go")) {
            refused = Some((i, err));
            break;
        }
    }
    let (at, err) = refused.expect("the queue is bounded");
    assert!(matches!(err, FsmError::QueueFull(_)), "{err}");
    assert!(at >= ndds_runtime::fsm::QUEUE_LIMIT, "refused at {at}");
    drop(held);
}

/// Counts its executions; fails when told to.
struct Probe {
    runs: Arc<AtomicU32>,
    fail: bool,
}

impl SampleModule for Probe {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        self.runs.fetch_add(1, Ordering::SeqCst);
        if self.fail {
            Err(ModuleError::Failed("probe says no".into()))
        } else {
            Ok(())
        }
    }
}

#[test]
fn actions_switch_configurations_start_and_stop_habitats_and_run_modules() {
    let rt = Runtime::new("fsm-rt");
    rt.create_habitat("servo", HabitatOptions::rate(1000.0).clock(Clock::Manual))
        .unwrap();
    rt.create_mat(CsMat::from_row_slice("x", 1, 1, &[1.0]).unwrap())
        .unwrap();
    rt.group("gain", "low", &["low"]).unwrap();
    rt.group("gain", "high", &["high"]).unwrap();
    rt.configuration("Low", &[("gain", "low")]).unwrap();
    rt.configuration("High", &[("gain", "high")]).unwrap();
    rt.install("servo", "low", |b| Gain::new(b, "x", "y", 1.0))
        .unwrap();
    rt.install("servo", "high", |b| Gain::new(b, "x", "y", 10.0))
        .unwrap();

    let mut p = Program::new("mode", "Off");
    for s in ["Start", "Boost", "Check", "Halt"] {
        p.stimulus(s, StimulusKind::Transient);
    }
    p.machine("mode", "Off")
        .states(&["Running", "Boosted", "Checked", "Failed"])
        .transition(
            "Off",
            "Start",
            "start servo",
            &[(0, "Running"), (1, "Failed")],
        )
        .unwrap()
        .transition(
            "Running",
            "Boost",
            "switch High",
            &[(0, "Boosted"), (1, "Failed")],
        )
        .unwrap()
        .transition(
            "Boosted",
            "Check",
            "probe",
            &[(0, "Checked"), (1, "Failed")],
        )
        .unwrap()
        .transition("*", "Halt", "stop servo", &[(0, "Off"), (1, "Failed")])
        .unwrap();
    let runs = Arc::new(AtomicU32::new(0));
    let mut actions = ActionSet::runtime(&rt);
    actions.add_module(
        "probe",
        Probe {
            runs: runs.clone(),
            fail: false,
        },
    );
    let fsm = StateMachine::start(p, actions).unwrap();
    let servo = rt.habitat("servo");

    fsm.send(Stimulus::event("Start")).unwrap();
    assert!(fsm.wait_for_state("Running", WAIT));
    assert!(servo.is_running());
    servo.step().unwrap();
    assert_eq!(rt.mat("y").value(0, 0), 1.0);
    fsm.send(Stimulus::event("Boost")).unwrap();
    assert!(fsm.wait_for_state("Boosted", WAIT));
    assert_eq!(rt.current_configuration().as_deref(), Some("High"));
    servo.step().unwrap();
    assert_eq!(rt.mat("y").value(0, 0), 10.0);
    fsm.send(Stimulus::event("Check")).unwrap();
    assert!(fsm.wait_for_state("Checked", WAIT));
    assert_eq!(runs.load(Ordering::SeqCst), 1);
    fsm.send(Stimulus::event("Halt")).unwrap();
    assert!(fsm.wait_for_state("Off", WAIT));
    assert!(!servo.is_running());
    let state = fsm.snapshot();
    assert_eq!(state.transitions, 4);
    assert_eq!(state.faults, 0);
}

#[test]
fn stimuli_and_conditions_arrive_from_the_network_and_the_state_is_published() {
    let dir = tempfile::tempdir().unwrap();
    let participant = common::participant(&common::unique_config(dir.path(), "fsm"));
    let mut p = Program::new("catch", "Idle");
    p.stimulus("Acquire", StimulusKind::Latched)
        .stimulus("Object", StimulusKind::Condition);
    p.machine("catch", "Idle")
        .states(&["Tracking"])
        .transition(
            "Idle",
            "Object = Visible and Acquire",
            "none",
            &[(0, "Tracking")],
        )
        .unwrap();
    let fsm = StateMachine::start_on(p, ActionSet::new(), &participant).unwrap();
    let states = participant
        .consumer::<MachineState>(
            "fsm/catch/state",
            ConsumerQos {
                depth: 64,
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let events = participant
        .producer::<Stimulus>(
            "fsm/catch/events",
            ProducerQos {
                reliability: Reliability::Reliable { depth: 16 },
                ..ProducerQos::default()
            },
        )
        .unwrap();
    assert!(events.wait_for_consumers(1, WAIT));
    events.write(&Stimulus::event("Acquire")).unwrap();
    events
        .write(&Stimulus::condition("Object", "Visible"))
        .unwrap();
    assert!(fsm.wait_for_state("Tracking", WAIT));
    let mut last = None;
    assert!(common::eventually(WAIT, || {
        while let Ok(s) = states.try_recv() {
            last = Some(s.value);
        }
        last.as_ref().is_some_and(|s| s.state == "Tracking")
    }));
    let last = last.unwrap();
    assert_eq!(last.machine, "catch");
    assert_eq!(
        last.conditions,
        [("Object".to_owned(), "Visible".to_owned())]
    );
    assert!(last.latched.is_empty());
    let t = last.last_transition.unwrap();
    assert_eq!((t.from.as_str(), t.to.as_str()), ("Idle", "Tracking"));
}

#[test]
fn a_panicking_action_is_a_fault_and_the_machine_goes_on() {
    let mut p = Program::new("brittle", "A");
    p.stimulus("Go", StimulusKind::Transient)
        .stimulus("Reset", StimulusKind::Transient);
    p.machine("brittle", "A")
        .states(&["B"])
        .transition("A", "Go", "explode", &[(0, "B")])
        .unwrap()
        .transition("Error", "Reset", "none", &[(0, "A")])
        .unwrap();
    let mut actions = ActionSet::new();
    actions.add("explode", &[0], |_| panic!("boom"));
    let fsm = StateMachine::start(p, actions).unwrap();
    fsm.send(Stimulus::event("Go")).unwrap();
    assert!(fsm.wait_for_state("Error", WAIT));
    assert!(
        fsm.snapshot().last_fault.contains("boom"),
        "{:?}",
        fsm.snapshot()
    );
    fsm.send(Stimulus::event("Reset")).unwrap();
    assert!(fsm.wait_for_state("A", WAIT), "the thread still runs");
}

#[test]
fn undeclared_and_oversized_stimuli_are_refused_and_counted() {
    let (program, actions) = counter(Arc::default());
    let fsm = StateMachine::start(program, actions).unwrap();
    assert!(matches!(
        fsm.send(Stimulus::event("Tock")),
        Err(FsmError::Refused(r)) if matches!(*r, ndds_runtime::fsm::Refusal::Undeclared { .. })
    ));
    let long = "T".repeat(ndds_runtime::fsm::MAX_NAME_LEN + 1);
    assert!(matches!(
        fsm.send(Stimulus::event(&long)),
        Err(FsmError::Oversized { .. })
    ));
    assert_eq!(fsm.snapshot().dropped, 2);
    fsm.send(Stimulus::event("Tick")).unwrap();
    assert!(fsm.wait_for_state("Odd", WAIT));
}

#[test]
fn a_misspelt_habitat_is_refused_not_created() {
    let rt = Runtime::new("typo");
    let mut p = Program::new("m", "A");
    p.stimulus("Go", StimulusKind::Transient);
    p.machine("m", "A")
        .states(&["Stopped", "Refused"])
        .transition("A", "Go", "stop servoo", &[(0, "Stopped"), (1, "Refused")])
        .unwrap();
    let fsm = StateMachine::start(p, ActionSet::runtime(&rt)).unwrap();
    fsm.send(Stimulus::event("Go")).unwrap();
    assert!(fsm.wait_for_state("Refused", WAIT), "{:?}", fsm.snapshot());
    assert!(rt.habitats().is_empty(), "no placeholder habitat was made");
    assert!(rt.verify().is_ok());
}

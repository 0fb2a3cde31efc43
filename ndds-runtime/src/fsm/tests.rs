//! The engine's semantics, without threads.

use std::sync::Arc;

use proptest::prelude::*;

use super::*;

fn no_actions(name: &str, _: Option<&str>) -> Result<i32, String> {
    Err(format!("no action `{name}` in this test"))
}

fn send(m: &mut Machine, text: &str) -> Outcome {
    m.handle(&Stimulus::parse(text), &mut no_actions)
}

/// Idle --(Object = Visible and Acquire)--> Tracking --(Lost)--> Idle.
fn catcher() -> Program {
    let mut p = Program::new("catch", "Idle");
    p.stimulus("Acquire", StimulusKind::Latched)
        .stimulus("Object", StimulusKind::Condition)
        .stimulus("Lost", StimulusKind::Transient)
        .stimulus("Ping", StimulusKind::Transient);
    let m = p.machine("catch", "Idle");
    m.states(&["Tracking"]);
    m.transition(
        "Idle",
        "Object = Visible AND Acquire",
        "none",
        &[(0, "Tracking")],
    )
    .unwrap();
    m.transition("Tracking", "Lost", "none", &[(0, "Idle")])
        .unwrap();
    p
}

#[test]
fn the_papers_condition_needs_both_stimuli() {
    let mut m = Machine::new(Arc::new(catcher()));
    assert!(send(&mut m, "Acquire").fired.is_empty());
    assert!(
        m.is_latched("Acquire"),
        "latched until a transition consumes it"
    );
    assert!(send(&mut m, "Object=Hidden").fired.is_empty());
    let out = send(&mut m, "Object=Visible");
    assert_eq!(out.fired.len(), 1, "{out:?}");
    assert_eq!(m.state(), "Tracking");
    assert!(!m.is_latched("Acquire"), "consumed by the transition");
    assert_eq!(m.condition("Object"), Some("Visible"), "conditions persist");

    // The other order: the condition first, the latched command later.
    send(&mut m, "Lost");
    assert_eq!(m.state(), "Idle");
    assert!(
        send(&mut m, "Object=Visible").fired.is_empty(),
        "Acquire was consumed"
    );
    send(&mut m, "Acquire");
    assert_eq!(m.state(), "Tracking");
}

#[test]
fn transients_that_match_nothing_vanish_and_latched_ones_wait() {
    let mut m = Machine::new(Arc::new(catcher()));
    let out = send(&mut m, "Lost");
    assert!(out.vanished && out.fired.is_empty());
    send(&mut m, "Object=Visible");
    send(&mut m, "Acquire");
    assert_eq!(m.state(), "Tracking");
    // Lost was not remembered: Tracking stays until a new Lost.
    assert_eq!(m.snapshot().latched, Vec::<String>::new());

    // A latched stimulus arriving where nothing takes it fires later, on entering a state
    // where a transition names it.
    let mut p = catcher();
    p.machine("catch", "Idle")
        .transition("Tracking", "Acquire", "none", &[(0, "Catching")])
        .unwrap()
        .states(&["Catching"]);
    let mut m = Machine::new(Arc::new(p));
    send(&mut m, "Object=Visible");
    send(&mut m, "Acquire"); // Idle -> Tracking, consumes Acquire
    send(&mut m, "Lost"); // Tracking -> Idle
    send(&mut m, "Object=Hidden");
    assert_eq!(m.state(), "Idle");
    send(&mut m, "Acquire"); // waits in Idle (Object is Hidden)
    assert!(m.is_latched("Acquire"));
    let out = send(&mut m, "Object=Visible"); // Idle -> Tracking (consumes), nothing left
    assert_eq!(m.state(), "Tracking", "{out:?}");
}

#[test]
fn wildcard_and_global_transitions_and_their_priority() {
    let mut p = Program::new("m", "A");
    for s in ["Go", "Stop", "Other", "Abort"] {
        p.stimulus(s, StimulusKind::Transient);
    }
    let m = p.machine("m", "A");
    m.states(&["B", "Unexpected", "Aborted"]);
    m.transition("*", "*", "none", &[(0, "Unexpected")])
        .unwrap();
    m.transition("A", "*", "none", &[(0, "B")]).unwrap();
    m.transition("*", "Abort", "none", &[(0, "Aborted")])
        .unwrap();
    m.transition("A", "Go", "none", &[(0, "B")]).unwrap();
    m.transition("B", "Go", "none", &[(0, "A")]).unwrap();
    let program = Arc::new(p);

    // A handled stimulus never reaches a wildcard.
    let mut machine = Machine::new(program.clone());
    send(&mut machine, "Go");
    assert_eq!(machine.state(), "B");
    send(&mut machine, "Go");
    assert_eq!(machine.state(), "A");
    // Unhandled: the state's wildcard before the global one.
    send(&mut machine, "Other");
    assert_eq!(machine.state(), "B");
    send(&mut machine, "Other");
    assert_eq!(
        machine.state(),
        "Unexpected",
        "B has no wildcard: the global one"
    );
    // A global transition works from every state, before wildcards.
    for start in ["A", "B"] {
        let mut machine = Machine::new(program.clone());
        if start == "B" {
            send(&mut machine, "Go");
        }
        send(&mut machine, "Abort");
        assert_eq!(machine.state(), "Aborted");
    }
}

/// main: Idle --(Start, call Grasp)--> {0: Holding, 1: Idle}
/// Grasp: Open --(Closed)--> Check --(Ok)--> Done(return 0) / --(Slip)--> Failed(return 1)
fn with_subchain() -> Program {
    let mut p = Program::new("main", "Idle");
    for s in ["Start", "Closed", "Ok", "Slip", "Deep"] {
        p.stimulus(s, StimulusKind::Transient);
    }
    p.machine("main", "Idle")
        .states(&["Holding"])
        .transition(
            "Idle",
            "Start",
            "call Grasp",
            &[(0, "Holding"), (1, "Idle")],
        )
        .unwrap();
    let g = p.machine("Grasp", "Open");
    g.states(&["Check"]).returns("Done", 0).returns("Failed", 1);
    g.transition("Open", "Closed", "none", &[(0, "Check")])
        .unwrap();
    g.transition("Check", "Ok", "none", &[(0, "Done")]).unwrap();
    g.transition("Check", "Slip", "none", &[(0, "Failed")])
        .unwrap();
    p
}

#[test]
fn sub_chains_return_their_code_to_the_caller() {
    let program = Arc::new(with_subchain());
    for (last, expected) in [("Ok", "Holding"), ("Slip", "Idle")] {
        let mut m = Machine::new(program.clone());
        send(&mut m, "Start");
        assert_eq!(
            m.stack(),
            [
                ("main".to_owned(), "Idle".to_owned()),
                ("Grasp".to_owned(), "Open".to_owned())
            ]
        );
        send(&mut m, "Closed");
        assert_eq!(m.state(), "Check");
        let out = send(&mut m, last);
        assert_eq!(m.state(), expected, "{out:?}");
        assert_eq!(m.stack().len(), 1);
        let caller = out.fired.last().unwrap();
        assert_eq!(caller.machine, "main");
        assert_eq!(caller.code, Some(if last == "Ok" { 0 } else { 1 }));
    }
}

#[test]
fn unbounded_recursion_and_missing_codes_are_faults_that_lead_to_the_error_state() {
    let mut p = with_subchain();
    // Grasp calls itself on Deep.
    p.machine("Grasp", "Open")
        .transition("Open", "Deep", "call Grasp", &[(0, "Open")])
        .unwrap();
    let mut m = Machine::new(Arc::new(p));
    send(&mut m, "Start");
    let mut faults = Vec::new();
    for _ in 0..MAX_CALL_DEPTH + 2 {
        faults.extend(send(&mut m, "Deep").faults);
    }
    assert!(
        faults
            .iter()
            .any(|f| matches!(f, Fault::RecursionLimit { .. })),
        "{faults:?}"
    );
    assert_eq!(m.state(), "Error");
    assert_eq!(m.stack().len(), 1);

    // An action code with no successor.
    let mut p = Program::new("m", "A");
    p.stimulus("Go", StimulusKind::Transient);
    p.machine("m", "A")
        .transition("A", "Go", "measure", &[(0, "A")])
        .unwrap();
    let mut m = Machine::new(Arc::new(p));
    let out = m.handle(&Stimulus::event("Go"), &mut |_: &str, _: Option<&str>| {
        Ok(7)
    });
    assert!(
        matches!(&out.faults[..], [Fault::NoSuccessor { code: 7, .. }]),
        "{out:?}"
    );
    assert_eq!(m.state(), "Error");
    assert_eq!(m.snapshot().faults, 1);
}

#[test]
fn bad_stimuli_are_faults_that_change_nothing() {
    let mut m = Machine::new(Arc::new(catcher()));
    for (text, fault) in [
        ("Nobody", Fault::UnknownStimulus("Nobody".into())),
        ("Object", Fault::MissingValue("Object".into())),
        ("Acquire=yes", Fault::UnexpectedValue("Acquire".into())),
    ] {
        let out = send(&mut m, text);
        assert_eq!(out.faults, [fault]);
        assert_eq!(m.state(), "Idle");
    }
    assert!(!m.is_latched("Acquire"));
    assert_eq!(m.condition("Object"), None);
}

#[test]
fn actions_get_their_argument_and_choose_the_successor() {
    let mut p = Program::new("m", "A");
    p.stimulus("Go", StimulusKind::Transient);
    p.machine("m", "A")
        .states(&["Ok", "Retry"])
        .transition("A", "Go", "switch endptLQG", &[(0, "Ok"), (1, "Retry")])
        .unwrap();
    let program = Arc::new(p);
    for (code, state) in [(0, "Ok"), (1, "Retry")] {
        let mut seen = Vec::new();
        let mut m = Machine::new(program.clone());
        m.handle(
            &Stimulus::event("Go"),
            &mut |name: &str, arg: Option<&str>| {
                seen.push(format!("{name}({})", arg.unwrap_or("")));
                Ok(code)
            },
        );
        assert_eq!(seen, ["switch(endptLQG)"]);
        assert_eq!(m.state(), state);
    }
    let mut m = Machine::new(program);
    let out = m.handle(&Stimulus::event("Go"), &mut |_: &str, _: Option<&str>| {
        Err("no such configuration".to_owned())
    });
    assert!(matches!(&out.faults[..], [Fault::ActionFailed { .. }]));
    assert_eq!(m.state(), "Error");
}

#[test]
fn verify_reports_every_kind_of_problem() {
    let mut p = Program::new("main", "Idle");
    p.stimulus("Go", StimulusKind::Transient)
        .stimulus("Mode", StimulusKind::Condition);
    let m = p.machine("main", "Idle");
    m.states(&["Lonely", "Next"]);
    m.transition("Idle", "Go and Ghost", "none", &[(0, "Next")])
        .unwrap();
    m.transition("Next", "Go = fast", "move", &[(0, "Idle")])
        .unwrap();
    m.transition("Next", "Mode = x", "call Nowhere", &[])
        .unwrap();
    m.transition("Idle", "Mode = y", "none", &[(0, "Elsewhere")])
        .unwrap();
    m.transition("Somewhere", "Go", "none", &[(0, "Idle")])
        .unwrap();
    let codes = |name: &str| (name == "move").then(|| vec![0, 1]);
    let problems = verify(&p, &codes);
    let text: Vec<String> = problems.iter().map(ToString::to_string).collect();
    let expect = [
        "unknown stimulus `Ghost`",
        "`Go` is compared to a value but is not a condition",
        "calls unknown machine `Nowhere`",
        "unknown state `Elsewhere`",
        "unknown state `Somewhere`",
        "return code 1 has no successor",
        "state `Lonely` is unreachable",
    ];
    for e in expect {
        assert!(text.iter().any(|t| t.contains(e)), "{e} in {text:#?}");
    }
    let codes = |_: &str| None;
    assert!(
        verify(&p, &codes)
            .iter()
            .any(|p| matches!(p, FsmProblem::UnknownAction { action, .. } if action == "move"))
    );
    // A clean program has no problems.
    assert_eq!(verify(&with_subchain(), &|_: &str| None), []);
}

#[test]
fn a_program_loads_from_toml() {
    let text = r#"
main = "catch"
error_state = "Fault"

[stimuli]
Acquire = "latched"
Object = "condition"
Lost = "transient"

[[machine]]
name = "catch"
start = "Idle"
states = ["Idle", "Tracking", "Fault"]

[[machine.transition]]
from = "Idle"
when = "Object = Visible and Acquire"
action = "switch endptLQG"
next = { 0 = "Tracking", 1 = "Fault" }

[[machine.transition]]
from = "*"
when = "Lost"
next = { 0 = "Idle" }
"#;
    let p = Program::from_toml(text).unwrap();
    assert_eq!(p.error_state, "Fault");
    assert_eq!(p.machines["catch"].transitions.len(), 2);
    assert_eq!(verify(&p, &|_: &str| Some(vec![0, 1])), []);
    let mut m = Machine::new(Arc::new(p));
    send(&mut m, "Object=Visible");
    m.handle(
        &Stimulus::event("Acquire"),
        &mut |_: &str, _: Option<&str>| Ok(0),
    );
    assert_eq!(m.state(), "Tracking");

    let bad = text.replace("and Acquire", "and and");
    let err = Program::from_toml(&bad).unwrap_err().to_string();
    assert!(err.contains("machine `catch`, transition 0"), "{err}");
    let bad = text.replace("0 = \"Tracking\"", "zero = \"Tracking\"");
    assert!(
        Program::from_toml(&bad)
            .unwrap_err()
            .to_string()
            .contains("`zero`")
    );
    let bad = text.replace("start = \"Idle\"", "start = \"Idle\"\nstartt = 1");
    assert!(Program::from_toml(&bad).is_err());
}

fn arbitrary_program() -> impl Strategy<Value = Program> {
    let kinds = prop::collection::vec(0u8..3, 4);
    let transitions = prop::collection::vec(
        (
            0usize..5,                                         // from (4 = global)
            0usize..10,                                        // condition template
            0usize..4,                                         // action
            prop::collection::vec((0i32..3, 0usize..4), 0..3), // next
        ),
        0..12,
    );
    (kinds, transitions).prop_map(|(kinds, transitions)| {
        let names = ["a", "b", "c", "d"];
        let states = ["S0", "S1", "S2", "S3"];
        let mut p = Program::new("main", "S0");
        for (name, kind) in names.iter().zip(kinds) {
            let kind = [
                StimulusKind::Transient,
                StimulusKind::Latched,
                StimulusKind::Condition,
            ][kind as usize];
            p.stimulus(name, kind);
        }
        let conditions = [
            "a",
            "b and c",
            "not d",
            "*",
            "a or b",
            "c = x",
            "d = y and a",
            "(a or c) and not b",
            "* and not a",
            "b",
        ];
        {
            let sub = p.machine("sub", "S0");
            sub.states(&states).returns("S3", 1);
        }
        for machine in ["main", "sub"] {
            for (from, cond, action, next) in &transitions {
                let from = if *from == 4 { "*" } else { states[*from] };
                let action = ["none", "call sub", "call main", "act"][*action];
                let next: Vec<(i32, &str)> = next.iter().map(|(c, s)| (*c, states[*s])).collect();
                let m = p.machine(machine, "S0");
                m.states(&states);
                m.transition(from, conditions[*cond], action, &next)
                    .unwrap();
            }
        }
        p
    })
}

proptest! {
    #[test]
    fn random_stimuli_never_panic_and_states_stay_declared(
        program in arbitrary_program(),
        stimuli in prop::collection::vec((0usize..5, 0usize..3, 0i32..3), 0..60),
    ) {
        let program = Arc::new(program);
        let mut m = Machine::new(program.clone());
        for (name, value, code) in stimuli {
            let name = ["a", "b", "c", "d", "undeclared"][name];
            let stimulus = match value {
                0 => Stimulus::event(name),
                v => Stimulus::condition(name, ["x", "y"][v - 1]),
            };
            let _ = m.handle(&stimulus, &mut |_: &str, _: Option<&str>| Ok(code));
            let stack = m.stack();
            prop_assert!(!stack.is_empty() && stack.len() <= MAX_CALL_DEPTH);
            for (machine, state) in stack {
                let def = &program.machines[&machine];
                prop_assert!(
                    def.states.contains(&state) || state == program.error_state,
                    "{machine}:{state} is declared"
                );
            }
        }
    }
}

#[test]
fn an_outer_global_transition_ends_the_calls_below_it() {
    let mut p = with_subchain();
    p.stimulus("Abort", StimulusKind::Transient);
    p.machine("main", "Idle")
        .states(&["Aborted"])
        .transition("*", "Abort", "none", &[(0, "Aborted")])
        .unwrap();
    let mut m = Machine::new(Arc::new(p));
    send(&mut m, "Start");
    send(&mut m, "Closed");
    assert_eq!(m.stack().len(), 2);
    let out = send(&mut m, "Abort");
    assert_eq!(
        m.stack(),
        [("main".to_owned(), "Aborted".to_owned())],
        "{out:?}"
    );
}

#[test]
fn a_runaway_of_latched_retries_is_a_fault_that_leads_to_the_error_state() {
    let mut p = Program::new("m", "Waiting");
    p.stimulus("Go", StimulusKind::Transient);
    let names: Vec<String> = (0..MAX_STEPS + 6).map(|i| format!("l{i}")).collect();
    for name in &names {
        p.stimulus(name, StimulusKind::Latched);
    }
    let m = p.machine("m", "Waiting");
    m.states(&["Busy"]);
    m.transition("Waiting", "Go", "none", &[(0, "Busy")])
        .unwrap();
    for name in &names {
        m.transition("Busy", name, "none", &[(0, "Busy")]).unwrap();
    }
    let mut machine = Machine::new(Arc::new(p));
    for name in &names {
        assert!(send(&mut machine, name).fired.is_empty());
    }
    let out = send(&mut machine, "Go");
    assert_eq!(out.faults, [Fault::Runaway]);
    assert_eq!(machine.state(), "Error");
}

#[test]
fn verify_reports_a_call_of_a_machine_that_never_returns() {
    let mut p = with_subchain();
    p.machine("Grasp", "Open").returns.clear();
    let problems = verify(&p, &|_: &str| None);
    assert!(
        problems
            .iter()
            .any(|p| matches!(p, FsmProblem::NoReturn { called, .. } if called == "Grasp")),
        "{problems:?}"
    );
}

#[test]
fn return_states_written_in_toml_are_states() {
    let text = r#"
main = "main"
[stimuli]
Start = "transient"
Closed = "transient"
[[machine]]
name = "main"
start = "Idle"
states = ["Idle", "Holding"]
[[machine.transition]]
from = "Idle"
when = "Start"
action = "call Grasp"
next = { 0 = "Holding", 1 = "Idle" }
[[machine]]
name = "Grasp"
start = "Open"
states = ["Open", "Check"]
returns = { Done = 0, Failed = 1 }
[[machine.transition]]
from = "Open"
when = "Closed"
next = { 0 = "Done" }
"#;
    let p = Program::from_toml(text).unwrap();
    let problems = verify(&p, &|_: &str| None);
    // Only `Check` and `Failed` are unreachable in this short program.
    assert!(
        problems
            .iter()
            .all(|p| matches!(p, FsmProblem::Unreachable { machine, .. } if machine == "Grasp")),
        "{problems:?}"
    );
    let mut m = Machine::new(Arc::new(p));
    send(&mut m, "Start");
    send(&mut m, "Closed");
    assert_eq!(m.state(), "Holding");
}

//! Command ports: a state machine and a runtime answer requests with what happened or why
//! not, and a second one of the same name in a domain is refused when it starts (through a
//! real daemon, between two participants standing for two processes).

#[path = "../../ndds-client/tests/common/mod.rs"]
mod common;

use std::time::Duration;

use ndds_client::ports::PortUser;
use ndds_client::{ConsumerQos, Participant};
use ndds_runtime::fsm::{
    ActionSet, CommandReply, FsmError, Program, Refusal, StateMachine, Stimulus, StimulusKind,
    command_port,
};
use ndds_runtime::{CsMat, Runtime, RuntimeCommand, RuntimeError};

const WAIT: Duration = Duration::from_secs(10);

/// Two participants of one domain on one daemon (two processes of a host).
fn two(dir: &std::path::Path) -> (Participant, Participant) {
    let config = common::unique_config(dir, "commands");
    (common::participant(&config), common::participant(&config))
}

/// Idle --(Go)--> Busy --(Object = Visible)--> Idle.
fn program() -> Program {
    let mut p = Program::new("cell", "Idle");
    p.stimulus("Go", StimulusKind::Transient)
        .stimulus("Object", StimulusKind::Condition);
    let m = p.machine("cell", "Idle");
    m.states(&["Busy"]);
    m.transition("Idle", "Go", "none", &[(0, "Busy")]).unwrap();
    m.transition("Busy", "Object = Visible", "none", &[(0, "Idle")])
        .unwrap();
    p
}

fn send(user: &PortUser<Vec<Stimulus>, CommandReply>, stimuli: &[&str]) -> CommandReply {
    let stimuli: Vec<Stimulus> = stimuli.iter().map(|s| Stimulus::parse(s)).collect();
    user.send(&stimuli, WAIT).expect("the machine answers")
}

#[test]
fn a_machine_answers_with_the_outcome_or_refuses_the_whole_command() {
    let dir = tempfile::tempdir().unwrap();
    let (machine_side, tool_side) = two(dir.path());
    let machine = StateMachine::start_on(program(), ActionSet::new(), &machine_side).unwrap();
    let user =
        PortUser::<Vec<Stimulus>, CommandReply>::declare(&tool_side, &command_port("cell"), "t")
            .unwrap();

    let done = send(&user, &["Go", "Object=Visible"]).expect("accepted");
    assert_eq!(
        done,
        "Go: Idle -> Busy (none, code 0)\nObject=Visible: Busy -> Idle (none, code 0)"
    );

    // One bad stimulus refuses the command: the good one before it is not queued either.
    let refused = send(&user, &["Go", "Gp"]).expect_err("refused");
    assert!(
        refused.contains("has no stimulus `Gp` (did you mean `Go`?)"),
        "{refused}"
    );
    let refused = send(&user, &["Go", "Object=Visibel"]).expect_err("near miss");
    assert!(
        refused.contains("did you mean `Object=Visible`?"),
        "{refused}"
    );
    let refused = send(&user, &["Go=1"]).expect_err("no value");
    assert!(refused.contains("takes no value"), "{refused}");
    let state = machine.snapshot();
    assert_eq!(state.state, "Idle", "nothing of a refused command ran");
    assert_eq!(state.transitions, 2);
    assert_eq!(state.dropped, 3, "each refusal is counted");
    let accepted: Vec<String> = state.accepts.iter().map(ToString::to_string).collect();
    assert_eq!(accepted, ["Go", "Object=Visible"]);
}

#[test]
fn a_second_machine_of_one_name_is_refused_at_start() {
    let dir = tempfile::tempdir().unwrap();
    let (first_side, second_side) = two(dir.path());
    let _first = StateMachine::start_on(program(), ActionSet::new(), &first_side).unwrap();
    let port = format!("port/{}/owner", command_port("cell"));
    assert!(common::eventually(WAIT, || {
        second_side
            .graph()
            .is_ok_and(|g| g.endpoints.iter().any(|e| e.info.topic == port))
    }));
    match StateMachine::start_on(program(), ActionSet::new(), &second_side) {
        Err(FsmError::AlreadyRunning { machine, owner }) => {
            assert_eq!(machine, "cell");
            assert_eq!(owner.pid, std::process::id());
            assert!(!owner.host.is_empty());
        }
        Err(other) => panic!("wrong refusal: {other}"),
        Ok(_) => panic!("a second machine `cell` started"),
    }
}

#[test]
fn a_runtime_switches_explains_refusals_and_checks_sample_shapes() {
    let dir = tempfile::tempdir().unwrap();
    let (system_side, tool_side) = two(dir.path());
    let rt = Runtime::with_participant("lab", &system_side).unwrap();
    rt.create_mat(CsMat::zeros("u", 2, 1)).unwrap();
    rt.create_habitat(
        "servo",
        ndds_runtime::HabitatOptions::rate(100.0).clock(ndds_runtime::Clock::Manual),
    )
    .unwrap();
    rt.subscribe("servo", "u", (2, 1), "lab/u", ConsumerQos::default())
        .unwrap();
    rt.configuration("Idle", &[]).unwrap();
    let user = PortUser::<RuntimeCommand, CommandReply>::declare(
        &tool_side,
        &ndds_runtime::command_port("lab"),
        "t",
    )
    .unwrap();
    let ask = |command: RuntimeCommand| user.send(&command, WAIT).expect("the runtime answers");

    assert_eq!(
        ask(RuntimeCommand::Configure("Idle".into())),
        Ok("system `lab` switched to configuration `Idle`".into())
    );
    assert_eq!(
        ask(RuntimeCommand::Configure("Idel".into())),
        Err("system `lab` has no configuration `Idel` (did you mean `Idle`?); it has: Idle".into())
    );
    let three = CsMat::zeros("u", 3, 1);
    let refused = ask(RuntimeCommand::CheckSample {
        topic: "lab/u".into(),
        sample: three,
    })
    .expect_err("wrong shape");
    assert!(
        refused.contains("CSMat `u`, which is 2x1; this sample is 3x1"),
        "{refused}"
    );
    assert!(
        ask(RuntimeCommand::CheckSample {
            topic: "lab/u".into(),
            sample: CsMat::zeros("u", 2, 1),
        })
        .is_ok()
    );
    assert_eq!(
        ask(RuntimeCommand::CheckSample {
            topic: "lab/other".into(),
            sample: CsMat::zeros("u", 3, 1),
        }),
        Ok("system `lab` does not subscribe `lab/other`".into()),
        "no objection to a topic the system does not subscribe"
    );
}

#[test]
fn a_second_runtime_of_one_name_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (first_side, second_side) = two(dir.path());
    let _first = Runtime::with_participant("lab", &first_side).unwrap();
    let port = format!("port/{}/owner", ndds_runtime::command_port("lab"));
    assert!(common::eventually(WAIT, || {
        second_side
            .graph()
            .is_ok_and(|g| g.endpoints.iter().any(|e| e.info.topic == port))
    }));
    match Runtime::with_participant("lab", &second_side) {
        Err(RuntimeError::AlreadyRunning { name, owner }) => {
            assert_eq!(name, "lab");
            assert_eq!(owner.pid, std::process::id());
        }
        Err(other) => panic!("wrong refusal: {other}"),
        Ok(_) => panic!("a second runtime `lab` started"),
    }
    // Another name is fine.
    assert!(Runtime::with_participant("lab2", &second_side).is_ok());
}

#[test]
fn refusals_are_typed() {
    let machine = StateMachine::start(program(), ActionSet::new()).unwrap();
    assert!(matches!(
        machine.send(Stimulus::parse("Object")),
        Err(FsmError::Refused(r)) if matches!(*r, Refusal::MissingValue { .. })
    ));
}

#[test]
fn a_name_is_checked_against_other_hosts_even_on_a_daemon_started_just_now() {
    let dir = tempfile::tempdir().unwrap();
    let config = common::unique_config(dir.path(), "host-a");
    let host_a = common::participant(&config);
    let _first = Runtime::with_participant("lab", &host_a).unwrap();
    // A second host's daemon, started now: its first moments hear nobody yet.
    let host_b = common::participant(&common::sibling(&config, dir.path(), "host-b"));
    match Runtime::with_participant("lab", &host_b) {
        Err(RuntimeError::AlreadyRunning { name, .. }) => assert_eq!(name, "lab"),
        Err(other) => panic!("wrong refusal: {other}"),
        Ok(_) => panic!("a second runtime `lab` started on another host"),
    }
}

#[test]
fn the_reply_streams_of_users_that_went_away_are_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let (machine_side, tool_side) = two(dir.path());
    let _machine = StateMachine::start_on(program(), ActionSet::new(), &machine_side).unwrap();
    let replies = |g: &ndds_client::Graph| {
        g.endpoints
            .iter()
            .filter(|e| e.info.topic.starts_with("port/fsm.cell/reply/"))
            .filter(|e| e.info.qos.kind() == ndds_core::wire::EndpointKind::Producer)
            .count()
    };
    // Three tools, each sending once and leaving, as `ndds fsm send` does.
    for _ in 0..3 {
        let user = PortUser::<Vec<Stimulus>, CommandReply>::declare(
            &tool_side,
            &command_port("cell"),
            "tool",
        )
        .unwrap();
        send(&user, &["Object=Hidden"]).expect("accepted");
    }
    assert!(
        common::eventually(WAIT, || tool_side.graph().is_ok_and(|g| replies(&g) == 0)),
        "reply streams left behind: {:?}",
        tool_side.graph().map(|g| replies(&g))
    );
}

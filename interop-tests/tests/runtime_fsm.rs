//! A state machine in one process driven by stimuli sent from another over ndds: the
//! `arm_supervised` example (the PD/LQG controller under `arm_supervisor.toml`) with the
//! `arm_plant` example, both under their own daemon on loopback. The test sends stimuli as a
//! third process would, watches the machine's state topic, the controller's statistics and the
//! arm, and measures the time from sending a stimulus to the configuration switch having taken
//! effect (the machine publishes its new state after the switch returned).

mod examples;

use std::time::{Duration, Instant};

use examples::{WAIT, program, settles};
use interop_tests::{TestDomain, wait_until};
use ndds_client::{
    Consumer, ConsumerQos, EmbeddedPolicy, Participant, Producer, ProducerQos, Reliability,
};
use ndds_runtime::fsm::{MachineState, Stimulus};
use ndds_runtime::{CsMat, HabitatStats};

/// Waits for a published state that satisfies `check`.
fn published(
    states: &Consumer<MachineState>,
    check: impl Fn(&MachineState) -> bool,
) -> Option<MachineState> {
    let start = Instant::now();
    while start.elapsed() < WAIT {
        if let Ok(sample) = states.recv_timeout(Duration::from_millis(100))
            && check(&sample.value)
        {
            return Some(sample.value);
        }
    }
    None
}

/// Waits for a published state named `state`; the time it took.
fn state_reached(states: &Consumer<MachineState>, state: &str) -> Option<(Duration, MachineState)> {
    let start = Instant::now();
    published(states, |s| s.state == state).map(|s| (start.elapsed(), s))
}

fn send(events: &Producer<Stimulus>, stimulus: &str) {
    events.write(&Stimulus::parse(stimulus)).unwrap();
}

#[test]
fn stimuli_from_another_process_switch_the_controller_through_its_state_machine() {
    let domain = TestDomain::new();
    let _plant_host = domain.daemon("plant-host");
    let _control_host = domain.daemon("control-host");
    let _plant = program(&domain, "plant-host", "arm_plant");
    let _supervised = program(&domain, "control-host", "arm_supervised");

    let observer = Participant::builder()
        .socket(domain.socket("plant-host"))
        .embedded(EmbeddedPolicy::Never)
        .name("operator")
        .connect()
        .expect("observer connects");
    let deep = ConsumerQos {
        depth: 1024,
        ..ConsumerQos::default()
    };
    let tips = observer.consumer::<CsMat>("arm/tip", deep).unwrap();
    let states = observer
        .consumer::<MachineState>("fsm/arm/state", deep)
        .unwrap();
    let stats = observer
        .consumer::<HabitatStats>("cs/arm-controller/control/stats", ConsumerQos::default())
        .unwrap();
    let events = observer
        .producer::<Stimulus>(
            "fsm/arm/events",
            ProducerQos {
                reliability: Reliability::Reliable { depth: 64 },
                ..ProducerQos::default()
            },
        )
        .unwrap();
    assert!(
        events.wait_for_consumers(1, WAIT),
        "the machine's event topic"
    );
    assert!(settles(&tips, 0.1 * 400.0 / 404.0, 0.002), "JointPD first");

    // The paper's condition: Object = Visible alone does nothing ...
    send(&events, "Object=Visible");
    let visible = |s: &MachineState| s.conditions.contains(&("Object".into(), "Visible".into()));
    let seen = published(&states, visible).expect("the condition is remembered");
    assert_eq!(seen.state, "Joint", "{seen:?}");
    assert_eq!(seen.last_transition, None, "no transition yet: {seen:?}");
    // ... and with Precise (latched) the machine switches to endptLQG.
    let sent = Instant::now();
    send(&events, "Precise");
    let (_, endpoint) = state_reached(&states, "Endpoint").expect("Endpoint reached");
    let first = sent.elapsed();
    let t = endpoint.last_transition.clone().expect("the transition");
    assert_eq!(
        (t.from.as_str(), t.action.as_str(), t.code),
        ("Joint", "switch endptLQG", Some(0))
    );
    assert!(
        endpoint.latched.is_empty(),
        "Precise consumed: {endpoint:?}"
    );
    assert!(
        settles(&tips, 0.1, 0.0005),
        "endptLQG settles with no error"
    );
    assert!(
        wait_until(WAIT, || stats
            .try_recv()
            .is_ok_and(|s| s.value.configuration == "endptLQG"))
        .is_some()
    );

    // A global transition from the CLI: Abort -> Safe (JointPD).
    let run = domain.ndds("control-host", &["fsm", "send", "arm", "Abort"], WAIT);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    state_reached(&states, "Safe").expect("Safe reached");
    assert!(
        settles(&tips, 0.1 * 400.0 / 404.0, 0.002),
        "back to JointPD"
    );
    let run = domain.ndds("plant-host", &["fsm", "show", "arm"], WAIT);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    assert!(run.stdout.contains("state       Safe"), "{}", run.stdout);
    assert!(run.stdout.contains("Object=Visible"), "{}", run.stdout);
    send(&events, "Coarse");
    state_reached(&states, "Joint").expect("Joint again");

    // Latency from sending a stimulus to the switch having taken effect, 20 times each way.
    let mut latencies = vec![first];
    for _ in 0..20 {
        for (stimulus, state) in [("Precise", "Endpoint"), ("Coarse", "Joint")] {
            let sent = Instant::now();
            send(&events, stimulus);
            state_reached(&states, state).expect("switched");
            latencies.push(sent.elapsed());
        }
    }
    latencies.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "stimulus -> configuration switched (state published): n {} min {:.2} ms, median {:.2} ms, max {:.2} ms",
        latencies.len(),
        ms(latencies[0]),
        ms(latencies[latencies.len() / 2]),
        ms(latencies[latencies.len() - 1])
    );
    assert!(latencies[latencies.len() / 2] < Duration::from_secs(1));
}

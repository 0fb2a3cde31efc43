//! A subscribed input in the system's status: never received, received, then stale, in the
//! habitat's own time (a manual habitat stepped by the test, so staleness is exact; only the
//! delivery of samples waits in real time, with generous bounds).

#[path = "../../ndds-client/tests/common/mod.rs"]
mod common;

use std::time::Duration;

use ndds_client::ProducerQos;
use ndds_runtime::system::System;
use ndds_runtime::{CsMat, Freshness, InputStatus};

fn description(topic: &str) -> String {
    format!(
        r#"
[system]
name = "inputs"

[[habitat]]
name = "control"
rate = 100.0
clock = "manual"

[[subscribe]]
mat = "angles"
topic = "{topic}"
habitat = "control"
shape = [2, 1]

[[component]]
name = "double"
type = "gain"
habitat = "control"
input = "angles"
output = "command"
k = 2.0
"#
    )
}

fn input(system: &System) -> InputStatus {
    let inputs = system.status().inputs;
    assert_eq!(inputs.len(), 1, "one subscription: {inputs:?}");
    inputs.into_iter().next().unwrap()
}

fn step(system: &System, samples: usize) {
    let control = system.runtime().habitat("control");
    for _ in 0..samples {
        control.step().expect("the manual habitat steps");
    }
}

#[test]
fn a_subscribed_input_is_never_received_then_received_then_stale() {
    let dir = tempfile::tempdir().unwrap();
    let config = common::unique_config(dir.path(), "inputs");
    let participant = common::participant(&config);
    let topic = format!("inputs-test/{}/angles", fastrand::u64(..));
    let system = System::from_str(
        "inputs.toml",
        &description(&topic),
        Some(&participant),
        ndds_components::library(),
    )
    .expect("the description loads");
    system.start().expect("the system starts");

    // Nobody publishes: the controller runs on zeros, and the status says why.
    step(&system, 100);
    let never = input(&system);
    assert_eq!(
        (
            never.topic.as_str(),
            never.mat.as_str(),
            never.habitat.as_str()
        ),
        (topic.as_str(), "angles", "control")
    );
    assert_eq!(
        (never.freshness, never.age, never.received),
        (Freshness::Never, None, 0)
    );
    assert_eq!(never.sampled, Duration::from_millis(990));
    assert!(never.is_problem());

    // A producer writes until a sample is taken.
    let producer = participant
        .producer::<CsMat>(&topic, ProducerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, Duration::from_secs(10)));
    let value = CsMat::from_row_slice("angles", 2, 1, &[0.5, -0.25]).unwrap();
    assert!(
        common::eventually(Duration::from_secs(10), || {
            producer.write(&value).unwrap();
            step(&system, 1);
            input(&system).received > 0
        }),
        "no sample taken: {:?}",
        input(&system)
    );
    let received = input(&system);
    assert_eq!(
        (received.freshness, received.age),
        (Freshness::Fresh, Some(Duration::ZERO))
    );
    assert!(!received.is_problem());
    assert_eq!(system.runtime().mat("command").value(0, 0), 1.0);

    // It stops; samples still in flight are taken by the next sample.
    drop(producer);
    std::thread::sleep(Duration::from_secs(1));
    step(&system, 1);
    let drained = input(&system).age.expect("received");
    assert!(drained <= Duration::from_millis(10), "{drained:?}");
    // Stale after 0.5 s of the habitat's time (50 periods at 100 Hz), not before.
    let to_limit = (Duration::from_millis(500) - drained).as_millis() / 10;
    step(&system, usize::try_from(to_limit).unwrap());
    let old = input(&system);
    assert_eq!(
        (old.freshness, old.age),
        (Freshness::Fresh, Some(Duration::from_millis(500)))
    );
    step(&system, 1);
    let stale = input(&system);
    assert_eq!(stale.freshness, Freshness::Stale, "{stale:?}");
    assert_eq!(stale.age, Some(Duration::from_millis(510)));
    assert!(stale.is_problem() && stale.received >= 1);
    system.stop();
}

#[test]
fn a_sample_of_another_shape_is_refused_not_received() {
    let dir = tempfile::tempdir().unwrap();
    let config = common::unique_config(dir.path(), "refused");
    let participant = common::participant(&config);
    let topic = format!("inputs-test/{}/angles", fastrand::u64(..));
    let system = System::from_str(
        "inputs.toml",
        &description(&topic),
        Some(&participant),
        ndds_components::library(),
    )
    .expect("the description loads");
    system.start().expect("the system starts");
    let producer = participant
        .producer::<CsMat>(&topic, ProducerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, Duration::from_secs(10)));
    let wrong = CsMat::from_row_slice("angles", 3, 1, &[1.0, 2.0, 3.0]).unwrap();
    assert!(
        common::eventually(Duration::from_secs(10), || {
            producer.write(&wrong).unwrap();
            step(&system, 1);
            input(&system).refused > 0
        }),
        "no sample refused: {:?}",
        input(&system)
    );
    // Past the grace a fed input would get (0.5 s at 100 Hz), it is reported.
    step(&system, 60);
    let refused = input(&system);
    assert_eq!((refused.freshness, refused.received), (Freshness::Never, 0));
    assert!(refused.is_problem());
    system.stop();
}

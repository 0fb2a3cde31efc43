//! Finding topics: `ndds topics` keeps the runtime's own topics out of the way unless asked,
//! and a mistyped topic name gets a "did you mean" from echo, hz and pub.

mod common;

use std::time::{Duration, Instant};

use common::World;
use ndds_client::{Participant, Producer, ProducerQos};

/// Producers of `u64` on each topic, once all are in the daemon's graph.
fn producers(world: &World, participant: &Participant, topics: &[&str]) -> Vec<Producer<u64>> {
    let producers = topics
        .iter()
        .map(|topic| {
            participant
                .producer::<u64>(topic, ProducerQos::default())
                .unwrap()
        })
        .collect();
    assert!(world.graph_until(participant, |g| {
        topics
            .iter()
            .all(|t| g.endpoints.iter().any(|e| e.info.topic == *t))
    }));
    producers
}

#[test]
fn internal_topics_are_counted_not_listed_unless_all() {
    let world = World::start();
    let participant = world.participant("topic-names-internal");
    let _producers = producers(
        &world,
        &participant,
        &[
            "arm/angles",
            "fsm/arm/state",
            "port/gripper/owner",
            "cs/arm/configure",
        ],
    );

    let run = world.ndds(&["topics"]);
    let text = run.ok();
    assert!(text.contains("arm/angles"), "{run}");
    for internal in ["fsm/arm/state", "port/gripper/owner", "cs/arm/configure"] {
        assert!(!text.contains(internal), "{internal} hidden: {run}");
    }
    assert!(
        text.contains("3 internal topics hidden (port/, fsm/, cs/); --all lists them"),
        "{run}"
    );

    for all in ["--all", "-a"] {
        let run = world.ndds(&["topics", all, "-v"]);
        let text = run.ok();
        for topic in [
            "arm/angles",
            "fsm/arm/state",
            "port/gripper/owner",
            "cs/arm/configure",
        ] {
            assert!(text.contains(topic), "{topic} listed: {run}");
        }
        assert!(!text.contains("hidden"), "{run}");
    }

    let run = world.ndds(&["topics", "--json"]);
    let listing = run.json();
    let flags: Vec<(&str, bool)> = listing["topics"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            (
                t["name"].as_str().unwrap(),
                t["internal"].as_bool().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        flags,
        [
            ("arm/angles", false),
            ("cs/arm/configure", true),
            ("fsm/arm/state", true),
            ("port/gripper/owner", true),
        ],
        "--json lists every topic: {run}"
    );
}

#[test]
fn a_domain_of_internal_topics_only_says_so() {
    let world = World::start();
    let participant = world.participant("topic-names-only-internal");
    let _producers = producers(&world, &participant, &["fsm/arm/state"]);
    let run = world.ndds(&["topics"]);
    let text = run.ok();
    assert!(text.contains("no user topics"), "{run}");
    assert!(
        text.contains("1 internal topic hidden (fsm/); --all lists them"),
        "{run}"
    );
}

#[test]
fn a_mistyped_topic_gets_a_suggestion_from_echo_hz_and_pub() {
    let world = World::start();
    let participant = world.participant("topic-names-suggest");
    let _producers = producers(
        &world,
        &participant,
        &["arm/angles", "arm/torques", "camera/image"],
    );
    for args in [
        &["echo", "arm/angels", "--count", "1"][..],
        &["hz", "arm/angels", "--duration", "1"],
        &["pub", "arm/angels", "1"],
        &["echo", "angles", "--count", "1"],
    ] {
        let run = world.ndds(args);
        let stderr = run.err();
        assert!(stderr.contains("not found"), "{run}");
        assert!(stderr.contains("did you mean `arm/angles`?"), "{run}");
        assert!(
            !stderr.contains("camera/image"),
            "only the close names: {run}"
        );
    }

    // A name close to nothing lists the topics there are instead.
    let run = world.ndds(&["echo", "lidar/points", "--count", "1"]);
    let stderr = run.err();
    assert!(!stderr.contains("did you mean"), "{run}");
    assert!(
        stderr.contains("arm/angles, arm/torques, camera/image"),
        "{run}"
    );

    // With --wait, the suggestion comes when the wait ends.
    let started = Instant::now();
    let run = world.ndds(&["echo", "arm/angels", "--wait", "0.5", "--count", "1"]);
    assert!(run.err().contains("did you mean `arm/angles`?"), "{run}");
    assert!(started.elapsed() >= Duration::from_millis(500), "{run}");
}

#[test]
fn an_internal_topic_is_suggested_but_not_listed() {
    let world = World::start();
    let participant = world.participant("topic-names-internal-suggest");
    let _producers = producers(&world, &participant, &["user/data", "fsm/arm/state"]);
    let run = world.ndds(&["echo", "fsm/arm/stat", "--count", "1"]);
    assert!(run.err().contains("did you mean `fsm/arm/state`?"), "{run}");
    let run = world.ndds(&["echo", "nothing/like/it", "--count", "1"]);
    let stderr = run.err();
    assert!(stderr.contains("known topics: user/data"), "{run}");
    assert!(!stderr.contains("fsm/arm/state"), "{run}");
    assert!(
        stderr.contains("1 internal not listed; `ndds topics --all`"),
        "{run}"
    );
}

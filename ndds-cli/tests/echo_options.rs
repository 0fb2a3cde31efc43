//! `ndds echo --rate HZ` (the newest sample of each window) and `--field PATH` (one value of
//! each sample), against a daemon of the test's own.

mod common;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use common::{RUN_LIMIT, Run, World};
use ndds_client::{Producer, ProducerQos};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Pose {
    x: f64,
    y: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct ArmState {
    data: Vec<f64>,
    pose: Pose,
    label: String,
}

fn arm_state(i: u64) -> ArmState {
    ArmState {
        data: vec![0.5, 2.5, i as f64],
        pose: Pose { x: 1.5, y: -2.0 },
        label: "left arm".to_owned(),
    }
}

/// Writes `sample(i)` for i = 0, 1, 2... at `hz` until `stop` is set; returns how many.
fn write_at_rate<T: Serialize + serde::de::DeserializeOwned + Send + 'static>(
    producer: Producer<T>,
    hz: f64,
    sample: fn(u64) -> T,
    stop: Arc<AtomicBool>,
) -> JoinHandle<u64> {
    std::thread::spawn(move || {
        let period = Duration::from_secs_f64(1.0 / hz);
        let start = Instant::now();
        let mut written = 0u64;
        while !stop.load(Ordering::Relaxed) {
            producer.write(&sample(written)).unwrap();
            written += 1;
            let due = start + period.mul_f64(written as f64);
            std::thread::sleep(due.saturating_duration_since(Instant::now()));
        }
        written
    })
}

/// Runs `ndds echo ARGS...` while `T` samples are written at `hz` on `topic`.
fn echo_while_writing<T: Serialize + serde::de::DeserializeOwned + Send + 'static>(
    world: &World,
    topic: &str,
    hz: f64,
    sample: fn(u64) -> T,
    args: &[&str],
) -> Run {
    let participant = world.participant("echo-options-writer");
    let producer = participant
        .producer::<T>(topic, ProducerQos::default())
        .unwrap();
    assert!(world.graph_until(&participant, |g| {
        g.endpoints.iter().any(|e| e.info.topic == topic)
    }));
    let stop = Arc::new(AtomicBool::new(false));
    let writer = write_at_rate(producer, hz, sample, stop.clone());
    let mut full = vec!["echo", topic, "--wait", "10"];
    full.extend_from_slice(args);
    let run = world.spawn(&full).finish(RUN_LIMIT);
    stop.store(true, Ordering::Relaxed);
    writer.join().unwrap();
    run
}

fn json_lines(run: &Run) -> Vec<Value> {
    run.ok()
        .lines()
        .map(|line| {
            serde_json::from_str(line).unwrap_or_else(|err| panic!("{line:?}: {err}\n{run}"))
        })
        .collect()
}

#[test]
fn rate_prints_the_newest_sample_of_each_window() {
    let world = World::start();
    // 200 samples a second, printed at most 4 a second: about one in fifty.
    let run = echo_while_writing(
        &world,
        "options/fast",
        200.0,
        |i| i,
        &["--rate", "4", "--count", "3", "--json"],
    );
    let printed = json_lines(&run);
    assert_eq!(printed.len(), 3, "{run}");
    let values: Vec<u64> = printed
        .iter()
        .map(|p| p["value"].as_u64().unwrap())
        .collect();
    let received: Vec<f64> = printed
        .iter()
        .map(|p| p["reception_timestamp"].as_f64().unwrap())
        .collect();
    for pair in 1..printed.len() {
        let skipped = values[pair] - values[pair - 1];
        assert!(
            skipped >= 10,
            "samples between windows dropped: {values:?}\n{run}"
        );
        let apart = received[pair] - received[pair - 1];
        // One per 250 ms window at most (no upper bound: a loaded machine may be late).
        assert!(
            apart > 0.1,
            "printed samples arrived {apart} s apart: {received:?}\n{run}"
        );
    }
}

#[test]
fn bad_rates_are_usage_errors() {
    let world = World::start();
    for bad in ["0", "-3", "fast", "inf"] {
        let run = world.ndds(&["echo", "x", &format!("--rate={bad}")]);
        assert!(run.err().contains("--rate"), "{run}");
    }
}

#[test]
fn field_prints_one_value_of_each_sample() {
    let world = World::start();
    let cases: [(&[&str], Value); 4] = [
        (&["--field", "pose.x"], json!(1.5)),
        (&["--field", "data[1]"], json!(2.5)),
        (&["--field", "label"], json!("left arm")),
        (&["--field", "pose"], json!({"x": 1.5, "y": -2.0})),
    ];
    for (args, expected) in cases {
        let mut args = args.to_vec();
        args.extend(["--count", "2"]);
        let run = echo_while_writing(&world, "options/arm", 50.0, arm_state, &args);
        let printed: Vec<&str> = run.ok().lines().collect();
        assert_eq!(printed.len(), 2, "{run}");
        for line in printed {
            let value: Value = serde_json::from_str(line).unwrap();
            assert_eq!(value, expected, "{run}");
        }
    }
}

#[test]
fn field_with_json_keeps_the_metadata_and_names_the_field() {
    let world = World::start();
    let run = echo_while_writing(
        &world,
        "options/arm",
        50.0,
        arm_state,
        &["--field", "data", "--json", "--count", "1"],
    );
    let printed = json_lines(&run);
    assert_eq!(printed[0]["field"], "data", "{run}");
    assert_eq!(printed[0]["topic"], "options/arm", "{run}");
    let data = printed[0]["value"].as_array().expect("the list");
    assert_eq!(data[..2], [json!(0.5), json!(2.5)], "{run}");
}

#[test]
fn an_unknown_field_is_an_error_naming_the_fields() {
    let world = World::start();
    let run = echo_while_writing(
        &world,
        "options/arm",
        50.0,
        arm_state,
        &["--field", "pose.z", "--count", "1"],
    );
    let stderr = run.err();
    assert!(stderr.contains("`pose` has no field `z`"), "{run}");
    assert!(stderr.contains("`x`, `y`"), "lists the fields: {run}");
    assert!(run.stdout.is_empty(), "{run}");

    let run = echo_while_writing(
        &world,
        "options/arm",
        50.0,
        arm_state,
        &["--field", "dat[0]", "--count", "1"],
    );
    let stderr = run.err();
    assert!(stderr.contains("did you mean `data`?"), "{run}");
    assert!(stderr.contains("`data`, `pose`, `label`"), "{run}");

    let run = echo_while_writing(
        &world,
        "options/arm",
        50.0,
        arm_state,
        &["--field", "data[7]", "--count", "1"],
    );
    assert!(run.err().contains("`data` has 3 elements"), "{run}");

    let run = world.ndds(&["echo", "options/arm", "--field", "a..b"]);
    assert!(
        run.err().contains("empty field name"),
        "refused before connecting: {run}"
    );
}

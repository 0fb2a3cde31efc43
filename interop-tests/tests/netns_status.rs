//! Consumer statuses across hosts ("no new data" each deadline, "incompatible type" on both
//! sides and in `ndds topics`), and the tools run from outside every host. Real daemons and
//! test nodes on hosts simulated with network namespaces (needs root, `ip` and `nft`).

mod support;

use std::time::{Duration, Instant};

use interop_tests::netns::Cluster;
use interop_tests::{binary, process, wait_until};
use serde_json::Value;
use support::{
    WAIT, exclusive, field, ms_between, node, notifications, read_until, samples, topic,
    topics_json, unix_us_now,
};

const A: usize = 0;
const B: usize = 1;
const C: usize = 2;

/// True when the `ndds topics --json` entry of a topic lists an incompatibility between the
/// two test types.
fn incompatible_listed(entry: &Value) -> bool {
    let names: Vec<&str> = entry["types"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|t| t["name"].as_str())
        .collect();
    entry["incompatible"] == true
        && names.iter().any(|n| n.ends_with("TelemetryV2"))
        && names.iter().any(|n| n.ends_with("Telemetry"))
}

#[test]
fn a_silent_producer_yields_no_new_data_each_deadline_and_another_type_is_incompatible_on_both_sides()
 {
    if support::skipped() {
        return;
    }
    const TOPIC: &str = "status";
    const DEADLINE: Duration = Duration::from_millis(100);
    /// The window over which "no new data" is counted (it starts one deadline after the
    /// producer froze).
    const WINDOW: Duration = Duration::from_secs(2);
    let _turn = exclusive();
    let cluster = Cluster::new(3);
    let consumer = node(
        &cluster,
        C,
        &[
            "consume",
            "--topic",
            TOPIC,
            "--count",
            "1000000",
            "--timeout",
            "30",
            "--events",
            "--deadline-ms",
            &DEADLINE.as_millis().to_string(),
        ],
    );
    // Before any producer: "never received", each deadline.
    let (never, _) = read_until(&consumer, WAIT, |l| l["kind"] == "NeverReceived");
    assert!(never.is_some(), "never received before the first sample");
    let producer = node(
        &cluster,
        A,
        &[
            "produce",
            "--topic",
            TOPIC,
            "--rate",
            "50",
            "--wait-consumers",
            "1",
        ],
    );
    read_until(&consumer, WAIT, |l| l["event"] == "sample")
        .0
        .expect("samples flow");

    // A producer of another type on another host: incompatible, on both sides.
    let other = node(
        &cluster,
        B,
        &[
            "--type",
            "telemetry-v2",
            "produce",
            "--topic",
            TOPIC,
            "--rate",
            "50",
        ],
    );
    let (reported, _) = read_until(&consumer, WAIT, |l| l["kind"] == "Incompatible");
    let reported = reported.expect("the consumer is told");
    eprintln!("consumer side: {reported}");
    assert!(
        reported["type_name"]
            .as_str()
            .unwrap()
            .ends_with("TelemetryV2")
    );
    assert!(
        reported["local_type"]
            .as_str()
            .unwrap()
            .ends_with("Telemetry")
    );
    assert_ne!(reported["fingerprint"], reported["local_fingerprint"]);
    let told = other
        .event("incompatible", WAIT)
        .expect("the producer is told");
    eprintln!("producer side: {told}");
    assert_eq!(told["consumer_pid"], consumer.pid());
    assert!(told["type_name"].as_str().unwrap().ends_with("Telemetry"));
    for host in [C, B, A] {
        let topics = topics_json(&cluster, host);
        let entry = topic(&topics, TOPIC);
        assert!(
            incompatible_listed(entry),
            "ndds topics on host {host}: {entry}"
        );
    }

    // The compatible producer falls silent (frozen: no withdrawal): "no new data" each
    // deadline, counted over a window by the consumer's own timestamps.
    let frozen_us = unix_us_now();
    producer.stop();
    let lines = consumer.events_until(Instant::now() + WINDOW + DEADLINE * 3);
    let from = frozen_us + micros(DEADLINE);
    let to = from + micros(WINDOW);
    let misses: Vec<&Value> = notifications(&lines, "NoNewData")
        .into_iter()
        .filter(|l| (from..to).contains(&field(l, "unix_us")))
        .collect();
    let gaps: Vec<f64> = misses
        .windows(2)
        .map(|w| ms_between(field(w[0], "unix_us"), field(w[1], "unix_us")))
        .collect();
    let expected = WINDOW.as_secs_f64() / DEADLINE.as_secs_f64();
    eprintln!(
        "deadline {} ms: {} \"no new data\" in {} ms (expected {expected}); gaps (ms): {:?}",
        DEADLINE.as_millis(),
        misses.len(),
        WINDOW.as_millis(),
        gaps.iter().map(|g| g.round()).collect::<Vec<_>>()
    );
    let count = misses.len() as f64;
    assert!(
        (0.8 * expected..=1.1 * expected).contains(&count),
        "{count} notifications"
    );
    let silent: Vec<f64> = misses
        .iter()
        .filter_map(|l| l["silent_ms"].as_f64())
        .collect();
    assert!(
        silent.windows(2).all(|w| w[1] > w[0]),
        "silent_for grows: {silent:?}"
    );
    assert!(
        samples(&lines)
            .iter()
            .all(|s| field(s, "recv_unix_us") < frozen_us + 20_000),
        "nothing accepted while the producer is frozen"
    );

    // It resumes: fresh samples again, and the misses stop.
    producer.resume();
    read_until(&consumer, WAIT, |l| l["event"] == "sample")
        .0
        .expect("samples again");
    let lines = consumer.events_until(Instant::now() + DEADLINE * 5);
    assert!(notifications(&lines, "NoNewData").is_empty(), "{lines:?}");
}

fn micros(duration: Duration) -> u64 {
    u64::try_from(duration.as_micros()).unwrap_or(u64::MAX)
}

#[test]
fn the_tools_work_from_outside_every_host() {
    if support::skipped() {
        return;
    }
    let _turn = exclusive();
    let cluster = Cluster::new(2);
    let producer = node(
        &cluster,
        1,
        &["produce", "--topic", "outside", "--rate", "0"],
    );
    assert!(
        wait_until(WAIT, || cluster.graph(1).nodes.len() == 1).is_some(),
        "the daemons know each other"
    );
    let socket = cluster.socket(1).display().to_string();
    // This test process runs in the machine's own namespace, where the host's address does
    // not exist: the tool falls back to a loopback data socket.
    let run = |args: &[&str]| {
        let mut full = vec!["--socket".to_owned(), socket.clone()];
        full.extend(args.iter().map(|a| (*a).to_owned()));
        let started = Instant::now();
        let out = process::run(&binary("ndds"), &full, WAIT);
        (out, started.elapsed())
    };
    let (out, took) = run(&["topics", "--json"]);
    assert_eq!(out.code, Some(0), "ndds topics: {}", out.stderr);
    let topics: Value = serde_json::from_str(&out.stdout).expect("JSON");
    let entry = topic(&topics, "outside");
    assert_eq!(entry["producers"][0]["pid"], producer.pid());
    let (out, _) = run(&["nodes", "--json"]);
    assert_eq!(out.code, Some(0), "ndds nodes: {}", out.stderr);
    let nodes: Value = serde_json::from_str(&out.stdout).expect("JSON");
    let listed = nodes["nodes"].as_array().map_or(0, Vec::len);
    eprintln!("ndds topics from the root namespace took {took:?}; ndds nodes lists {listed} nodes");
    assert_eq!(listed, 2, "the local daemon and the other host's: {nodes}");
}

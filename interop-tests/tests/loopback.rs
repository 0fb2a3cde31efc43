//! Real `ndds-daemon` processes on loopback, each standing for a host, with client processes
//! under them.

use std::time::Duration;

use interop_tests::{ClientProcess, LEASE, PERIOD, TestDomain, has_endpoint, wait_until};
use serde_json::Value;

const TOPIC: &str = "telemetry";
const WAIT: Duration = Duration::from_secs(10);

fn producer(domain: &TestDomain, daemon: &str) -> ClientProcess {
    let node = ClientProcess::test_node(
        &domain.socket(daemon),
        &["produce", "--topic", TOPIC, "--rate", "100"],
    );
    node.event("ready", WAIT).expect("producer ready");
    node
}

fn topics_json(domain: &TestDomain, daemon: &str) -> Value {
    let out = domain.ndds(daemon, &["topics", "--json"], WAIT);
    assert_eq!(out.code, Some(0), "ndds topics failed: {}", out.stderr);
    serde_json::from_str(&out.stdout).expect("ndds topics --json prints JSON")
}

fn endpoint_pids(topics: &Value, kind: &str) -> Vec<u64> {
    topics["topics"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|t| t["name"] == TOPIC)
        .flat_map(|t| t[kind].as_array().cloned().unwrap_or_default())
        .filter_map(|e| e["pid"].as_u64())
        .collect()
}

#[test]
fn producer_under_one_daemon_feeds_a_consumer_under_another() {
    let domain = TestDomain::new();
    let _a = domain.daemon("a");
    let _b = domain.daemon("b");
    let producer = producer(&domain, "a");
    let consumer = ClientProcess::test_node(
        &domain.socket("b"),
        &["consume", "--topic", TOPIC, "--count", "100000"],
    );
    consumer.event("ready", WAIT).expect("consumer ready");

    let first = consumer.event("sample", WAIT).expect("a first sample");
    let since_declare = first["since_declare_ms"]
        .as_f64()
        .expect("latency reported");
    eprintln!("consumer creation to first sample: {since_declare:.2} ms");
    let mut last_seq = first["seq"].as_u64().unwrap();
    for _ in 1..20 {
        let sample = consumer.event("sample", WAIT).expect("more samples");
        let seq = sample["seq"].as_u64().unwrap();
        assert!(seq > last_seq, "samples arrive in order");
        assert_eq!(sample["position"][0].as_f64(), Some(seq as f64));
        assert_eq!(sample["label"], format!("sample {seq}"));
        last_seq = seq;
    }

    // Both daemons list both endpoints, with their processes.
    for daemon in ["a", "b"] {
        let topics = topics_json(&domain, daemon);
        assert_eq!(
            endpoint_pids(&topics, "producers"),
            vec![u64::from(producer.pid())]
        );
        assert_eq!(
            endpoint_pids(&topics, "consumers"),
            vec![u64::from(consumer.pid())]
        );
        let listed = &topics["topics"][0];
        assert_eq!(listed["incompatible"], false);
        assert!(
            listed["types"][0]["name"]
                .as_str()
                .unwrap()
                .ends_with("Telemetry")
        );
    }
}

#[test]
fn a_killed_producer_vanishes_from_every_daemon_within_a_second() {
    let domain = TestDomain::new();
    let _a = domain.daemon("a");
    let _b = domain.daemon("b");
    let (tool_a, tool_b) = (domain.tool("a"), domain.tool("b"));
    let mut producer = producer(&domain, "a");
    let pid = producer.pid();
    for tool in [&tool_a, &tool_b] {
        assert!(
            wait_until(WAIT, || has_endpoint(&tool.graph().unwrap(), TOPIC, pid)).is_some(),
            "both daemons learn the producer"
        );
    }
    producer.kill9();
    let gone_a = wait_until(WAIT, || !has_endpoint(&tool_a.graph().unwrap(), TOPIC, pid));
    let gone_b = wait_until(WAIT, || !has_endpoint(&tool_b.graph().unwrap(), TOPIC, pid));
    eprintln!("after kill -9: gone from daemon A in {gone_a:?}, from daemon B in {gone_b:?}");
    assert!(
        gone_a.is_some_and(|t| t < Duration::from_secs(1)),
        "{gone_a:?}"
    );
    // B's wait started after A's; both are measured from the kill at most.
    assert!(
        gone_b.is_some_and(|t| t < Duration::from_secs(1)),
        "{gone_b:?}"
    );
}

#[test]
fn a_frozen_daemon_is_forgotten_after_its_lease_and_found_again_when_it_resumes() {
    let domain = TestDomain::new();
    let a = domain.daemon("a");
    let _b = domain.daemon("b");
    let tool_b = domain.tool("b");
    let producer = producer(&domain, "a");
    let pid = producer.pid();
    assert!(wait_until(WAIT, || has_endpoint(&tool_b.graph().unwrap(), TOPIC, pid)).is_some());

    a.stop();
    let stopped = std::time::Instant::now();
    // Not before the lease: half-way through it, B still has A's endpoint.
    std::thread::sleep(LEASE / 2);
    assert!(
        has_endpoint(&tool_b.graph().unwrap(), TOPIC, pid),
        "forgotten before the lease"
    );
    let gone = wait_until(WAIT, || !has_endpoint(&tool_b.graph().unwrap(), TOPIC, pid));
    let forgotten_after = stopped.elapsed();
    eprintln!("frozen daemon forgotten {forgotten_after:?} after SIGSTOP (lease {LEASE:?})");
    assert!(gone.is_some());
    // The last refresh came at most one period (plus jitter) before the stop.
    assert!(forgotten_after >= LEASE - PERIOD * 2, "{forgotten_after:?}");
    assert!(forgotten_after <= LEASE + PERIOD * 2, "{forgotten_after:?}");

    a.resume();
    assert!(
        wait_until(WAIT, || has_endpoint(&tool_b.graph().unwrap(), TOPIC, pid)).is_some(),
        "a resumed daemon is discovered again"
    );
}

#[test]
fn a_daemon_stopped_with_sigterm_says_goodbye() {
    let domain = TestDomain::new();
    let mut a = domain.daemon("a");
    let _b = domain.daemon("b");
    let tool_b = domain.tool("b");
    let producer = producer(&domain, "a");
    let pid = producer.pid();
    assert!(wait_until(WAIT, || has_endpoint(&tool_b.graph().unwrap(), TOPIC, pid)).is_some());
    let a_node = tool_b
        .graph()
        .unwrap()
        .nodes
        .iter()
        .find(|n| n.info.pid == a.pid())
        .map(|n| n.node)
        .expect("B knows A");

    assert_eq!(a.terminate(WAIT), Some(0), "clean exit on SIGTERM");
    assert!(!domain.socket("a").exists(), "socket file removed");
    let gone = wait_until(WAIT, || {
        let graph = tool_b.graph().unwrap();
        !has_endpoint(&graph, TOPIC, pid) && graph.nodes.iter().all(|n| n.node != a_node)
    });
    eprintln!("B forgot A {gone:?} after its SIGTERM exit");
    assert!(
        gone.is_some_and(|t| t < LEASE / 2),
        "Bye, not decay: {gone:?}"
    );
    assert!(a.log_text().contains("ndds-daemon stopped"));
}

#[test]
fn a_second_daemon_on_the_same_socket_is_refused() {
    let domain = TestDomain::new();
    let _a = domain.daemon("a");
    let mut args = domain.daemon_args("a");
    args.push("--seed".into());
    args.push("7".into());
    let out = interop_tests::process::run(&interop_tests::binary("ndds-daemon"), &args, WAIT);
    assert_ne!(out.code, Some(0));
    assert!(
        out.stderr.contains("already serves"),
        "stderr: {}",
        out.stderr
    );
}

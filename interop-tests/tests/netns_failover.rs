//! Hot stand-by across hosts: redundant producers arbitrated by strength and persistence, and
//! a consumer host's daemon killed and restarted under a running data flow. Real daemons and
//! test nodes on hosts simulated with network namespaces (needs root, `ip` and `nft`).
//!
//! Times are measured on the consumer's reception timestamps (microseconds since the Unix
//! epoch, a clock every process of the machine shares), not when the test reads the lines.

mod support;

use std::time::{Duration, Instant};

use interop_tests::netns::Cluster;
use interop_tests::{ClientProcess, LEASE, PERIOD, has_endpoint, wait_until};
use serde_json::Value;
use support::{
    WAIT, endpoints, exclusive, field, ms_between, node, notifications, read_until, samples,
    topics_json, unix_us_now,
};

const A: usize = 0;
const B: usize = 1;
const C: usize = 2;
/// Samples per second of every producer here.
const RATE: &str = "100";
const DATA_PERIOD: Duration = Duration::from_millis(10);
/// Persistence of the producers.
const PERSISTENCE: Duration = Duration::from_millis(500);
/// Scheduling allowance on top of a protocol bound: a wake-up on a loaded 2-core machine.
const SLACK: Duration = Duration::from_millis(50);

fn ms(duration: Duration) -> f64 {
    duration.as_secs_f64() * 1000.0
}

fn producer_args(topic: &str, strength: i32, value: i64) -> Vec<String> {
    [
        "produce",
        "--topic",
        topic,
        "--rate",
        RATE,
        "--strength",
        &strength.to_string(),
        "--persistence-ms",
        &PERSISTENCE.as_millis().to_string(),
        "--value",
        &value.to_string(),
        "--wait-consumers",
        "1",
    ]
    .map(str::to_owned)
    .to_vec()
}

/// A producer of `topic` at 100 Hz with `strength`, writing `value` in its samples; returns
/// once a consumer is matched.
fn start_producer(
    cluster: &Cluster,
    host: usize,
    topic: &str,
    strength: i32,
    value: i64,
) -> ClientProcess {
    let args = producer_args(topic, strength, value);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let producer = node(cluster, host, &args);
    assert!(
        producer.event("matched", WAIT).is_some(),
        "producer on host {host} matched the consumer"
    );
    producer
}

/// A consumer on `host` reporting samples and notifications until killed.
fn start_consumer(cluster: &Cluster, host: usize, extra: &[&str]) -> ClientProcess {
    let mut args = vec![
        "consume",
        "--count",
        "1000000",
        "--timeout",
        "30",
        "--events",
    ];
    args.extend_from_slice(extra);
    node(cluster, host, &args)
}

/// The samples `consumer` reports during `window`, asserting that they all carry `value`.
fn all_from(consumer: &ClientProcess, window: Duration, value: i64) -> Vec<Value> {
    let lines = consumer.events_until(Instant::now() + window);
    let samples: Vec<Value> = samples(&lines).into_iter().cloned().collect();
    let strangers: Vec<&Value> = samples.iter().filter(|s| s["value"] != value).collect();
    assert!(
        strangers.is_empty(),
        "only the producer writing {value} is accepted; also accepted: {strangers:?}"
    );
    samples
}

#[test]
fn the_strongest_producer_wins_the_next_takes_over_when_it_dies_and_gives_way_when_it_returns() {
    if support::skipped() {
        return;
    }
    const TOPIC: &str = "failover";
    let _turn = exclusive();
    let cluster = Cluster::new(3);
    let consumer = start_consumer(&cluster, C, &["--topic", TOPIC]);
    let mut a = start_producer(&cluster, A, TOPIC, 10, 1);
    let b = start_producer(&cluster, B, TOPIC, 5, 2);

    // 1. Both write to C; only A's samples are accepted.
    let (first_a, _) = read_until(&consumer, WAIT, |l| l["value"] == 1);
    let first_a = first_a.expect("a sample of A");
    assert_eq!(first_a["strength"], 10);
    let a_writer = first_a["writer"].clone();
    let accepted = all_from(&consumer, Duration::from_secs(1), 1);
    assert!(
        accepted.len() >= 80,
        "A's samples keep coming: {} in 1 s",
        accepted.len()
    );

    // 2. A's producer crashes: B takes over.
    let killed_us = unix_us_now();
    a.kill9();
    let (takeover, before) = read_until(&consumer, WAIT, |l| l["value"] == 2);
    let takeover = takeover.expect("B takes over");
    let failover = ms_between(killed_us, field(&takeover, "recv_unix_us"));
    let lost = notifications(&before, "ProducerLost")
        .first()
        .map(|l| ms_between(killed_us, field(l, "unix_us")));
    let last_a = accepted
        .iter()
        .chain(samples(&before))
        .map(|l| field(l, "recv_unix_us"))
        .max()
        .map(|us| ms_between(killed_us, us));
    eprintln!(
        "failover after kill -9 of the strongest producer: B's first sample {failover:.1} ms \
         after the kill (A's last sample at {last_a:?} ms, ProducerLost at {lost:?} ms); \
         persistence {} ms, period {} ms",
        ms(PERSISTENCE),
        ms(DATA_PERIOD)
    );
    assert_eq!(takeover["status"], "took_over");
    assert_eq!(takeover["previous"], a_writer);
    assert_eq!(takeover["strength"], 5);
    assert!(
        failover <= ms(PERSISTENCE + DATA_PERIOD + SLACK),
        "B took over {failover:.1} ms after the kill"
    );
    let b_writer = takeover["writer"].clone();
    let accepted = all_from(&consumer, Duration::from_millis(500), 2).len();
    assert!(
        accepted >= 40,
        "B's samples keep coming: {accepted} in 0.5 s"
    );

    // 3. A's producer returns (a new process, a new guid): it wins again at once.
    let restarted_us = unix_us_now();
    let a = start_producer(&cluster, A, TOPIC, 10, 1);
    let (back, _) = read_until(&consumer, WAIT, |l| l["value"] == 1);
    let back = back.expect("A's samples again");
    eprintln!(
        "the restarted strongest producer is accepted {:.1} ms after its start",
        ms_between(restarted_us, field(&back, "recv_unix_us"))
    );
    assert_eq!(back["status"], "took_over");
    assert_eq!(back["previous"], b_writer);
    assert_ne!(back["writer"], a_writer, "a new producer");
    let a_writer = back["writer"].clone();
    let accepted = all_from(&consumer, Duration::from_secs(1), 1);
    assert!(
        accepted.len() >= 80,
        "A's samples keep coming: {} in 1 s",
        accepted.len()
    );

    // 4. A freezes (no withdrawal: its process and session live on): B's samples are refused
    //    until A's last sample is older than its persistence, then B takes over.
    a.stop();
    let (takeover, before) = read_until(&consumer, WAIT, |l| l["value"] == 2);
    let takeover = takeover.expect("B takes over from a frozen A");
    let last_a = accepted
        .iter()
        .chain(samples(&before))
        .map(|l| field(l, "recv_unix_us"))
        .max()
        .expect("A's samples were seen");
    let after_last = ms_between(last_a, field(&takeover, "recv_unix_us"));
    eprintln!(
        "frozen strongest producer: B accepted {after_last:.1} ms after A's last sample \
         (persistence {} ms)",
        ms(PERSISTENCE)
    );
    assert_eq!(takeover["previous"], a_writer);
    // The reception timestamp and the arbiter's clock are read a few statements apart.
    let skew = Duration::from_millis(1);
    assert!(
        after_last >= ms(PERSISTENCE - skew) && after_last <= ms(PERSISTENCE + DATA_PERIOD + SLACK),
        "takeover {after_last:.1} ms after A's last sample"
    );
    a.resume();
    let (back, _) = read_until(&consumer, WAIT, |l| l["value"] == 1);
    assert_eq!(back.expect("A wins again")["status"], "took_over");
    drop(b);
}

#[test]
fn samples_flow_while_the_consumers_daemon_is_down_and_its_restart_rebuilds_the_database() {
    if support::skipped() {
        return;
    }
    const TOPIC: &str = "restart";
    const TOPIC_0: &str = "restart/0";
    let _turn = exclusive();
    let mut cluster = Cluster::new(3);
    let consumer = start_consumer(&cluster, C, &["--topic", TOPIC, "--topics", "2"]);
    let producer = node(
        &cluster,
        A,
        &[
            "produce",
            "--topic",
            TOPIC,
            "--topics",
            "2",
            "--rate",
            RATE,
            "--wait-consumers",
            "1",
        ],
    );
    producer.event("matched", WAIT).expect("producer matched");
    let bystander = node(
        &cluster,
        B,
        &["produce", "--topic", "restart-bystander", "--rate", "0"],
    );
    let pids = [consumer.pid(), producer.pid(), bystander.pid()];
    let whole = |host: usize| {
        let graph = cluster.graph(host);
        graph
            .endpoints
            .iter()
            .filter(|e| pids.contains(&e.info.pid))
            .count()
            == 5
    };
    assert!(
        wait_until(WAIT, || whole(C)).is_some(),
        "C sees 5 endpoints"
    );
    let before = topics_json(&cluster, C);
    let old_node = cluster.graph(C).local.node;
    read_until(&consumer, WAIT, |l| l["event"] == "sample")
        .0
        .expect("samples flow");

    // The consumer host's daemon crashes. The remote daemons keep its entries until its lease
    // runs out, counted from its last refresh (up to a jittered period before the kill): then
    // A's daemon unmatches the consumer and the flow stops until C's daemon is back. Counted
    // over the part of the outage that is surely within the lease.
    let killed_us = unix_us_now();
    cluster.daemon_mut(C).kill9();
    let down = LEASE - PERIOD * 2;
    let lines = consumer.events_until(Instant::now() + down + Duration::from_millis(50));
    let window = killed_us..killed_us + u64::try_from(down.as_micros()).expect("short");
    let during: Vec<&Value> = samples(&lines)
        .into_iter()
        .filter(|s| window.contains(&field(s, "recv_unix_us")))
        .collect();
    let expected = down.as_secs_f64() * 100.0 * 2.0;
    eprintln!(
        "daemon of the consumer's host down: {} samples in the first {} ms (2 topics at 100 Hz: \
         {expected:.0} written)",
        during.len(),
        ms(down)
    );
    assert!(
        during.len() as f64 >= 0.9 * expected,
        "samples keep flowing while the daemon is down: {}",
        during.len()
    );

    // A new daemon: the client reconnects and declares again on its own.
    let restarting = Instant::now();
    cluster.restart_daemon(C);
    let up = restarting.elapsed();
    let reconnected = wait_until(WAIT, || has_endpoint(&cluster.graph(C), TOPIC_0, pids[0]));
    let rebuilt = wait_until(WAIT, || {
        endpoints(&topics_json(&cluster, C)) == endpoints(&before)
    });
    let after = topics_json(&cluster, C);
    let new_node = cluster.graph(C).local.node;
    let moved = wait_until(WAIT, || {
        cluster
            .graph(A)
            .endpoints
            .iter()
            .filter(|e| e.info.pid == consumer.pid())
            .all(|e| e.node == new_node)
    });
    eprintln!(
        "restarted daemon accepting after {} ms; the client re-declared after {reconnected:?} \
         (from then); the database is whole after {rebuilt:?}; A moved the consumer's entries \
         to the new node after {moved:?}",
        ms(up)
    );
    assert!(
        reconnected.is_some_and(|t| t <= Duration::from_secs(1)),
        "the client reconnects within its longest retry pause: {reconnected:?}"
    );
    assert_eq!(
        endpoints(&after),
        endpoints(&before),
        "same topics, same endpoints"
    );
    assert_ne!(new_node, old_node, "a restarted daemon is a new node");
    assert!(
        moved.is_some(),
        "A attributes the consumer to the new daemon"
    );
    let checked_us = unix_us_now();
    let fresh = read_until(&consumer, WAIT, |l| {
        l["event"] == "sample" && field(l, "recv_unix_us") > checked_us
    });
    assert!(fresh.0.is_some(), "samples still flow");
}

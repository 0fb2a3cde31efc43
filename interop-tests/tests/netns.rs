//! Several hosts as network namespaces on a bridge (see `interop_tests::netns`), a real
//! daemon on each, clients under them, and faults injected with nft and signals. Needs root,
//! `ip` and `nft`: without them every test here is skipped and says why (fails under CI or
//! with `NDDS_REQUIRE_NETNS=1`; see `support::skipped`).

mod support;

use std::sync::Mutex;
use std::time::{Duration, Instant};

use interop_tests::netns::{self, Cluster, Network, PREFIX};
use interop_tests::{ClientProcess, LEASE, PERIOD, has_endpoint, wait_until};
use serde_json::Value;

const TOPIC: &str = "telemetry";
const WAIT: Duration = Duration::from_secs(10);
const A: usize = 0;
const B: usize = 1;
const C: usize = 2;

/// A consumer on `host` that keeps running (`count` large, `timeout` long).
fn consumer(cluster: &Cluster, host: usize) -> ClientProcess {
    let node = cluster.test_node(
        host,
        &[
            "consume",
            "--topic",
            TOPIC,
            "--count",
            "1000000",
            "--timeout",
            "30",
        ],
    );
    node.event("ready", WAIT).expect("consumer ready");
    node
}

/// A producer on `host` writing at `rate` Hz once a consumer is matched.
fn producer(cluster: &Cluster, host: usize, rate: &str, extra: &[&str]) -> ClientProcess {
    let mut args = vec!["produce", "--topic", TOPIC, "--rate", rate];
    args.extend_from_slice(extra);
    let node = cluster.test_node(host, &args);
    node.event("ready", WAIT).expect("producer ready");
    node
}

/// True when the daemon of `host` lists every endpoint of `pids` on the topic.
fn sees_all(cluster: &Cluster, host: usize, pids: &[u32]) -> bool {
    let graph = cluster.graph(host);
    pids.iter().all(|&pid| has_endpoint(&graph, TOPIC, pid))
}

/// Polls every `hosts` until `check(host)` holds for each; returns when each first held,
/// measured from `since`, `None` for those that never did within `timeout` (from the call).
fn first_times(
    since: Instant,
    hosts: &[usize],
    timeout: Duration,
    mut check: impl FnMut(usize) -> bool,
) -> Vec<Option<Duration>> {
    let mut times = vec![None; hosts.len()];
    wait_until(timeout, || {
        for (slot, &host) in times.iter_mut().zip(hosts) {
            if slot.is_none() && check(host) {
                *slot = Some(since.elapsed());
            }
        }
        times.iter().all(Option::is_some)
    });
    times
}

fn topic_pids(topics: &Value, kind: &str) -> Vec<u64> {
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
fn a_producer_and_a_consumer_on_two_hosts_exchange_samples_across_the_bridge() {
    if support::skipped() {
        return;
    }
    let cluster = Cluster::new(3);
    // Each daemon binds its host's address and knows the two others by theirs.
    let met = wait_until(WAIT, || (0..3).all(|i| cluster.graph(i).nodes.len() == 2));
    assert!(met.is_some(), "the three daemons find each other");
    for i in 0..3 {
        let graph = cluster.graph(i);
        assert_eq!(graph.local.interface, cluster.host(i).ip().octets());
        let mut seen: Vec<[u8; 4]> = graph.nodes.iter().map(|n| n.interface).collect();
        seen.sort_unstable();
        let mut others: Vec<[u8; 4]> = (0..3)
            .filter(|&j| j != i)
            .map(|j| cluster.host(j).ip().octets())
            .collect();
        others.sort_unstable();
        assert_eq!(
            seen, others,
            "host {i} knows the other hosts by their addresses"
        );
    }

    let consumer = consumer(&cluster, C);
    let producer = producer(&cluster, A, "100", &["--wait-consumers", "1"]);
    producer.event("matched", WAIT).expect("producer matched");
    let first = consumer.event("sample", WAIT).expect("a first sample");
    let mut last = first["seq"].as_u64().unwrap();
    for _ in 0..20 {
        let sample = consumer.event("sample", WAIT).expect("more samples");
        let seq = sample["seq"].as_u64().unwrap();
        assert!(seq > last, "in order: {seq} after {last}");
        assert_eq!(sample["position"][0].as_f64(), Some(seq as f64));
        assert_eq!(sample["label"], format!("sample {seq}"));
        last = seq;
    }

    // Every daemon lists both endpoints; the bystander B attributes each to its own host.
    let pids = [producer.pid(), consumer.pid()];
    for i in 0..3 {
        assert!(
            wait_until(WAIT, || sees_all(&cluster, i, &pids)).is_some(),
            "host {i} sees both endpoints"
        );
    }
    let graph_b = cluster.graph(B);
    for (pid, owner) in [(producer.pid(), A), (consumer.pid(), C)] {
        let endpoint = graph_b
            .endpoints
            .iter()
            .find(|e| e.info.pid == pid)
            .expect("listed");
        assert_eq!(endpoint.node, cluster.graph(owner).local.node);
        assert_eq!(
            endpoint.info.locator.addr,
            cluster.host(owner).ip().octets()
        );
    }
    let out = cluster.ndds(B, &["topics", "--json"], WAIT);
    assert_eq!(out.code, Some(0), "ndds topics on B: {}", out.stderr);
    let topics: Value = serde_json::from_str(&out.stdout).expect("JSON");
    assert_eq!(
        topic_pids(&topics, "producers"),
        vec![u64::from(producer.pid())]
    );
    assert_eq!(
        topic_pids(&topics, "consumers"),
        vec![u64::from(consumer.pid())]
    );
}

#[test]
fn a_partitioned_host_is_forgotten_after_the_lease_and_matched_again_on_heal() {
    if support::skipped() {
        return;
    }
    let cluster = Cluster::new(3);
    let consumer = consumer(&cluster, C);
    let producer = producer(&cluster, A, "100", &["--wait-consumers", "1"]);
    producer.event("matched", WAIT).expect("producer matched");
    consumer.event("sample", WAIT).expect("samples flow");
    let pids = [producer.pid(), consumer.pid()];
    for i in 0..3 {
        assert!(wait_until(WAIT, || sees_all(&cluster, i, &pids)).is_some());
    }

    let cut = Instant::now();
    cluster.network().partition(&[A], &[B, C]);
    let installed = cut.elapsed();
    // A's producer leaves B and C; C's consumer leaves A.
    let installed_at = Instant::now();
    let gone = first_times(installed_at, &[A, B, C], LEASE * 3, |host| {
        let pid = if host == A {
            consumer.pid()
        } else {
            producer.pid()
        };
        !has_endpoint(&cluster.graph(host), TOPIC, pid)
    });
    eprintln!(
        "partition installed in {installed:?}; forgotten after (A, B, C): {gone:?}, \
         lease {LEASE:?}, period {PERIOD:?}"
    );
    for (host, gone) in [A, B, C].into_iter().zip(&gone) {
        let gone = gone.unwrap_or_else(|| panic!("host {host} never forgot the other side"));
        assert!(
            gone >= LEASE - PERIOD * 2,
            "host {host}: before the lease: {gone:?}"
        );
        assert!(gone <= LEASE + PERIOD * 2, "host {host}: late: {gone:?}");
    }
    // B and C are on one side: B still has C's consumer.
    assert!(has_endpoint(&cluster.graph(B), TOPIC, consumer.pid()));

    consumer.drain();
    let healed = Instant::now();
    cluster.network().heal();
    let known = first_times(healed, &[A, B, C], WAIT, |host| {
        sees_all(&cluster, host, &pids)
    });
    let sample = consumer.event("sample", WAIT).map(|_| healed.elapsed());
    eprintln!(
        "healed: both endpoints known again (A, B, C) after {known:?}; next sample after {sample:?}"
    );
    // The next refresh (one jittered period) re-introduces A; each side answers a node it
    // hears for the first time within the reply jitter.
    let bound = PERIOD * 2;
    for (host, known) in [A, B, C].into_iter().zip(&known) {
        assert!(
            known.is_some_and(|t| t <= bound),
            "host {host} after heal: {known:?}"
        );
    }
    assert!(
        sample.is_some_and(|t| t <= bound),
        "samples again after {sample:?}"
    );
}

#[test]
fn discovery_converges_and_data_flows_under_30_percent_incoming_loss() {
    if support::skipped() {
        return;
    }
    const SENT: u64 = 600;
    let network = Network::new(3);
    for host in 0..3 {
        network.drop_incoming(host, 30);
    }
    // The daemons start under loss: they find each other through lossy solicitations and
    // announcements.
    let started = Instant::now();
    let cluster = Cluster::start(network);
    let met = first_times(started, &[A, B, C], LEASE * 5, |host| {
        cluster.graph(host).nodes.len() == 2
    });
    let declared = Instant::now();
    let consumer = consumer(&cluster, C);
    let producer = producer(
        &cluster,
        A,
        "200",
        &["--wait-consumers", "1", "--count", &SENT.to_string()],
    );
    let pids = [producer.pid(), consumer.pid()];
    let converged = first_times(declared, &[A, B, C], LEASE * 5, |host| {
        sees_all(&cluster, host, &pids)
    });
    eprintln!(
        "with 30 % incoming loss everywhere: daemons know each other after {met:?} (from their \
         start); every daemon sees both endpoints after {converged:?} (from the clients' start)"
    );
    for (host, (met, converged)) in [A, B, C].into_iter().zip(met.iter().zip(&converged)) {
        assert!(
            met.is_some(),
            "host {host} did not find the others within 5 leases"
        );
        assert!(
            converged.is_some(),
            "host {host} did not see both endpoints within 5 leases"
        );
    }

    producer
        .event("matched", WAIT)
        .expect("producer matched under loss");
    let done = producer.event("done", WAIT).expect("producer finished");
    assert_eq!(done["sent"].as_u64(), Some(SENT));
    // Samples cross one receiver's filter (C's): about 70 % should arrive.
    let mut received = 0u64;
    while let Some(sample) = consumer.event("sample", Duration::from_millis(300)) {
        if sample["seq"]
            .as_u64()
            .is_some_and(|seq| (1..=SENT).contains(&seq))
        {
            received += 1;
        }
    }
    let share = received as f64 / SENT as f64;
    let dropped: Vec<u64> = (0..3).map(|h| cluster.host(h).dropped_packets()).collect();
    eprintln!(
        "delivered {received} of {SENT} ({:.1} %); packets dropped by nft (A, B, C): {dropped:?}",
        share * 100.0
    );
    assert!(
        dropped.iter().all(|&d| d > 0),
        "the loss rules dropped something"
    );
    assert!((0.45..=0.92).contains(&share), "delivered share {share:.3}");
}

#[test]
fn a_client_killed_on_one_host_vanishes_from_every_daemon_within_a_second() {
    if support::skipped() {
        return;
    }
    let cluster = Cluster::new(3);
    let mut producer = producer(&cluster, A, "20", &[]);
    let pid = producer.pid();
    for i in 0..3 {
        assert!(wait_until(WAIT, || sees_all(&cluster, i, &[pid])).is_some());
    }
    let killed = Instant::now();
    producer.kill9();
    let gone = first_times(killed, &[A, B, C], WAIT, |host| {
        !has_endpoint(&cluster.graph(host), TOPIC, pid)
    });
    eprintln!("killed client gone after (A, B, C): {gone:?}");
    for (host, gone) in [A, B, C].into_iter().zip(&gone) {
        assert!(
            gone.is_some_and(|t| t < Duration::from_secs(1)),
            "host {host}: {gone:?}"
        );
    }
}

#[test]
fn a_panicking_test_leaves_no_namespace_and_no_process_behind() {
    if support::skipped() {
        return;
    }
    let names = Mutex::new(Vec::new());
    let leaked = Mutex::new(None);
    let result = std::panic::catch_unwind(|| {
        let cluster = Cluster::new(2);
        *names.lock().unwrap() = cluster.network().namespaces();
        // A process nobody stops: the network must kill it.
        let child = cluster
            .host(1)
            .exec("sleep")
            .arg("30")
            .spawn()
            .expect("sleep");
        *leaked.lock().unwrap() = Some(child);
        panic!("deliberate panic: the network must still be torn down");
    });
    assert!(result.is_err());
    let names = names.into_inner().unwrap();
    assert_eq!(names.len(), 3, "switch and two hosts");
    let left: Vec<String> = netns::list()
        .into_iter()
        .filter(|n| names.contains(n))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    let mut child = leaked.into_inner().unwrap().expect("started");
    let status = wait_until(WAIT, || matches!(child.try_wait(), Ok(Some(_))));
    assert!(status.is_some(), "the process inside was killed");
}

#[test]
fn namespaces_of_a_dead_run_are_swept_and_live_ones_kept() {
    if support::skipped() {
        return;
    }
    let mut dead = std::process::Command::new("true").spawn().unwrap();
    dead.wait().unwrap();
    let stale = format!("{PREFIX}{}-dead-h0", dead.id());
    let live = format!("{PREFIX}{}-live-h0", std::process::id());
    let ip = |args: &[&str]| {
        let status = std::process::Command::new("ip")
            .args(args)
            .status()
            .unwrap();
        assert!(status.success(), "ip {args:?}");
    };
    ip(&["netns", "add", &stale]);
    ip(&["netns", "add", &live]);
    let removed = netns::sweep_stale();
    let listed = netns::list();
    ip(&["netns", "delete", &live]);
    assert!(removed.contains(&stale), "{removed:?}");
    assert!(!listed.contains(&stale));
    assert!(listed.contains(&live), "a live run's namespace is kept");
}

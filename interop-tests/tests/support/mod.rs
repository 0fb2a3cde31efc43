//! Shared by the multi-host tests (`netns*.rs`): whether they can run here at all, test nodes
//! on hosts, reading their JSON lines, the `ndds topics --json` listing, and one measuring test
//! at a time.

#![allow(dead_code)]

use std::collections::BTreeSet;
use std::io::Write as _;
use std::time::{Duration, Instant, SystemTime};

use interop_tests::ClientProcess;
use interop_tests::netns::Cluster;
use ndds_client::Graph;
use serde_json::Value;

/// How long a step that should take milliseconds may take before the test gives up.
pub const WAIT: Duration = Duration::from_secs(10);

/// The first line of every multi-host test: `if skipped() { return; }`.
///
/// True when this machine cannot run the test (not root, or no `ip` or `nft`): the test then
/// says so on stderr (past the test harness's capture, so `cargo test` shows it) and passes as
/// skipped, which lets an ordinary user run the whole suite. Under CI (`CI=true`) or with
/// `NDDS_REQUIRE_NETNS=1` a missing prerequisite fails the test instead, so CI never skips one.
pub fn skipped() -> bool {
    let missing = netns_missing();
    if missing.is_empty() {
        return false;
    }
    let missing = missing.join("; ");
    if let Some(why) = netns_required() {
        panic!(
            "the multi-host tests cannot run here ({missing}), and {why} is set, so they fail \
             instead of being skipped: run them as root with `ip` and `nft` installed \
             (apt-get install -y iproute2 nftables)"
        );
    }
    let test = std::thread::current()
        .name()
        .unwrap_or("a multi-host test")
        .to_owned();
    let _ = writeln!(
        std::io::stderr(),
        "{test}: skipped: needs root and the `ip` and `nft` commands ({missing}); \
         set NDDS_REQUIRE_NETNS=1 to fail instead"
    );
    true
}

/// What this process lacks for the multi-host tests, as `interop_tests::netns` checks it
/// (root; `ip` and `nft` on `PATH` or in the sbin directories); empty when nothing is missing.
fn netns_missing() -> Vec<String> {
    let mut missing = Vec::new();
    let uid = nix::unistd::geteuid();
    if !uid.is_root() {
        missing.push(format!("running as uid {uid}"));
    }
    for program in ["ip", "nft"] {
        if interop_tests::netns::locate(program).is_none() {
            missing.push(format!("`{program}` not found"));
        }
    }
    missing
}

/// The setting that forbids skipping, if one is set: `CI` (as CI services set it) or
/// `NDDS_REQUIRE_NETNS`, set to anything but empty, `0` or `false`.
fn netns_required() -> Option<&'static str> {
    ["NDDS_REQUIRE_NETNS", "CI"].into_iter().find(|name| {
        std::env::var(name).is_ok_and(|value| {
            let value = value.trim();
            !value.is_empty() && value != "0" && !value.eq_ignore_ascii_case("false")
        })
    })
}

/// The tests of one file take turns, so each measures its figures on an otherwise quiet
/// machine (two cores: a neighbour's 40 processes would show in a failover time).
pub fn exclusive() -> std::sync::MutexGuard<'static, ()> {
    interop_tests::exclusive()
}

/// Starts `ndds-test-node ARGS` on host `host` of `cluster`; returns once it is `ready`.
pub fn node(cluster: &Cluster, host: usize, args: &[&str]) -> ClientProcess {
    let node = cluster.test_node(host, args);
    if node.event("ready", WAIT).is_none() {
        panic!("test node {args:?} on host {host} did not get ready");
    }
    node
}

/// Microseconds since the Unix epoch, the clock of the nodes' timestamps.
pub fn unix_us_now() -> u64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

/// Milliseconds from `from_us` to `to_us` (negative if `to_us` is earlier).
pub fn ms_between(from_us: u64, to_us: u64) -> f64 {
    (to_us as f64 - from_us as f64) / 1000.0
}

/// True for a line with `"event": name`.
pub fn is(line: &Value, name: &str) -> bool {
    line["event"] == name
}

/// The `sample` lines among `lines`.
pub fn samples(lines: &[Value]) -> Vec<&Value> {
    lines.iter().filter(|l| is(l, "sample")).collect()
}

/// The `notification` lines of `kind` among `lines`.
pub fn notifications<'a>(lines: &'a [Value], kind: &str) -> Vec<&'a Value> {
    lines
        .iter()
        .filter(|l| is(l, "notification") && l["kind"] == kind)
        .collect()
}

/// Reads `node`'s lines until one satisfies `found`; returns it and every line read before
/// it, or `None` (with the lines read) at the timeout.
pub fn read_until(
    node: &ClientProcess,
    timeout: Duration,
    mut found: impl FnMut(&Value) -> bool,
) -> (Option<Value>, Vec<Value>) {
    let deadline = Instant::now() + timeout;
    let mut before = Vec::new();
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        let Some(line) = node.line(left) else { break };
        let Ok(value) = serde_json::from_str::<Value>(&line) else {
            continue;
        };
        if found(&value) {
            return (Some(value), before);
        }
        before.push(value);
    }
    (None, before)
}

/// A numeric field as u64 (panics naming the field when it is missing).
pub fn field(line: &Value, name: &str) -> u64 {
    line[name]
        .as_u64()
        .unwrap_or_else(|| panic!("no numeric {name:?} in {line}"))
}

/// `ndds topics --json` run on host `host` against its daemon, parsed.
pub fn topics_json(cluster: &Cluster, host: usize) -> Value {
    let out = cluster.ndds(host, &["topics", "--json"], WAIT);
    assert_eq!(
        out.code,
        Some(0),
        "ndds topics on host {host}: {}",
        out.stderr
    );
    serde_json::from_str(&out.stdout).expect("ndds topics --json prints JSON")
}

/// One endpoint as `ndds topics --json` lists it: (topic, "producers" or "consumers", guid).
pub type Listed = (String, &'static str, String);

/// Every endpoint of a `ndds topics --json` listing.
pub fn endpoints(topics: &Value) -> BTreeSet<Listed> {
    let mut set = BTreeSet::new();
    for topic in topics["topics"].as_array().into_iter().flatten() {
        let name = topic["name"].as_str().unwrap_or_default().to_owned();
        for kind in ["producers", "consumers"] {
            for endpoint in topic[kind].as_array().into_iter().flatten() {
                let guid = endpoint["guid"].as_str().unwrap_or_default().to_owned();
                set.insert((name.clone(), kind, guid));
            }
        }
    }
    set
}

/// The entry of `name` in a `ndds topics --json` listing.
pub fn topic<'a>(topics: &'a Value, name: &str) -> &'a Value {
    topics["topics"]
        .as_array()
        .into_iter()
        .flatten()
        .find(|t| t["name"] == name)
        .unwrap_or_else(|| panic!("topic {name} not listed: {topics}"))
}

/// A daemon counter of `graph` (panics naming it when the daemon has no such counter).
pub fn counter(graph: &Graph, name: &str) -> u64 {
    graph
        .counters
        .iter()
        .find(|(n, _)| n == name)
        .map_or_else(|| panic!("no counter {name}"), |(_, v)| *v)
}

/// Number of endpoints in `graph` whose topic starts with `prefix`.
pub fn endpoints_under(graph: &Graph, prefix: &str) -> usize {
    graph
        .endpoints
        .iter()
        .filter(|e| e.info.topic.starts_with(prefix))
        .count()
}

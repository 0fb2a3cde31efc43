//! `ndds perf` end to end, behaviour only (no timing assertions): ping/pong for a few hundred
//! round trips and pub/sub for a fraction of a second, over ndds (best effort and reliable)
//! against a daemon embedded in the test process, and over raw UDP; the JSON each side prints
//! parses and its counts agree with the other side's.

mod common;

use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};

use common::{RUN_LIMIT, Run, World};
use serde_json::Value;

fn json(run: &Run) -> Value {
    run.json()
}

fn number(value: &Value, key: &str) -> f64 {
    value[key]
        .as_f64()
        .unwrap_or_else(|| panic!("no number {key:?} in {value}"))
}

fn count(value: &Value, key: &str) -> u64 {
    value[key]
        .as_u64()
        .unwrap_or_else(|| panic!("no count {key:?} in {value}"))
}

/// A loopback port free a moment ago.
fn free_port() -> String {
    let socket = UdpSocket::bind(SocketAddrV4::new(Ipv4Addr::LOCALHOST, 0)).unwrap();
    socket.local_addr().unwrap().to_string()
}

/// Checks a ping report of `samples` round trips; returns it.
fn check_ping(run: &Run, transport: &str, samples: u64) -> Value {
    let ping = json(run);
    assert_eq!(ping["mode"], "ping", "{run}");
    assert_eq!(ping["transport"], transport, "{run}");
    assert_eq!(count(&ping, "samples"), samples, "{run}");
    let order =
        ["min_us", "p50_us", "p90_us", "p99_us", "p999_us", "max_us"].map(|key| number(&ping, key));
    assert!(
        order.windows(2).all(|w| w[0] <= w[1]),
        "percentiles out of order: {run}"
    );
    assert!(
        order[0] > 0.0 && number(&ping, "mean_us") >= order[0],
        "{run}"
    );
    ping
}

fn ping_pong(world: &World, pong_args: &[&str], ping_args: &[&str], transport: &str) {
    let pong = world.spawn(&[&["perf", "pong", "--json", "--duration", "20"], pong_args].concat());
    let run = world.ndds(
        &[
            &[
                "perf", "ping", "--json", "--count", "300", "--warmup", "20", "--size", "100",
            ],
            ping_args,
        ]
        .concat(),
    );
    let ping = check_ping(&run, transport, 300);
    let pong = pong.finish(RUN_LIMIT);
    let pong = json(&pong);
    assert_eq!(pong["mode"], "pong");
    assert_eq!(count(&pong, "errors"), 0, "{pong}");
    // Every measured and warm-up round trip was echoed; lost pings may add more.
    assert!(count(&pong, "echoed") >= 320, "{pong} {ping}");
}

#[test]
fn ping_pong_over_ndds_best_effort_and_reliable() {
    let world = World::start();
    ping_pong(&world, &[], &[], "ndds");
    ping_pong(&world, &["--reliable"], &["--reliable"], "ndds");
}

#[test]
fn ping_pong_over_raw_udp() {
    let world = World::start();
    let port = free_port();
    ping_pong(
        &world,
        &["--raw-udp", "--bind", &port],
        &["--raw-udp", "--peer", &port],
        "raw-udp",
    );
}

/// Runs sub (measuring a short window) against pub at 2 kHz; checks both reports agree.
fn pub_sub(world: &World, sub_args: &[&str], pub_args: &[&str], transport: &str) {
    let sub = world.spawn(
        &[
            &[
                "perf",
                "sub",
                "--json",
                "--duration",
                "0.3",
                "--warmup",
                "0.1",
            ],
            sub_args,
        ]
        .concat(),
    );
    let run = world.ndds(
        &[
            &[
                "perf",
                "pub",
                "--json",
                "--duration",
                "3",
                "--rate",
                "2000",
                "--size",
                "100",
            ],
            pub_args,
        ]
        .concat(),
    );
    let publ = json(&run);
    let sub = sub.finish(RUN_LIMIT);
    let sub = json(&sub);
    assert_eq!(
        (&publ["mode"], &sub["mode"]),
        (&"pub".into(), &"sub".into())
    );
    assert_eq!(
        (&publ["transport"], &sub["transport"]),
        (&transport.into(), &transport.into())
    );
    assert_eq!(count(&publ, "errors"), 0, "{publ}");
    let samples = count(&sub, "samples");
    assert!(samples > 0, "{sub}");
    assert_eq!(count(&sub, "bytes"), samples * 100, "{sub}");
    assert_eq!(count(&sub, "size"), 100, "{sub}");
    assert!(count(&sub, "total_samples") >= samples, "{sub}");
    assert!(
        count(&sub, "total_samples") + count(&sub, "total_lost") <= count(&publ, "written"),
        "{sub} {publ}"
    );
    assert!(
        number(&sub, "window_s") > 0.0 && number(&sub, "samples_per_s") > 0.0,
        "{sub}"
    );
}

#[test]
fn pub_sub_over_ndds() {
    let world = World::start();
    pub_sub(&world, &[], &[], "ndds");
    pub_sub(
        &world,
        &[],
        &["--batch-us", "200", "--batch-bytes", "4000"],
        "ndds",
    );
    pub_sub(
        &world,
        &["--reliable"],
        &["--reliable", "--depth", "256"],
        "ndds",
    );
}

#[test]
fn pub_sub_over_raw_udp() {
    let world = World::start();
    let port = free_port();
    pub_sub(
        &world,
        &["--raw-udp", "--bind", &port],
        &["--raw-udp", "--peer", &port],
        "raw-udp",
    );
}

#[test]
fn bad_arguments_are_usage_errors() {
    let world = World::start();
    for args in [
        &["perf", "ping", "--raw-udp"][..],
        &["perf", "ping", "--size", "17MiB"],
        &["perf", "ping", "--count", "3", "--duration", "1"],
        &["perf", "pub", "--rate", "0"],
        &[
            "perf",
            "pub",
            "--raw-udp",
            "--peer",
            "127.0.0.1:9",
            "--reliable",
        ],
        &["perf", "sub", "--depth", "5"],
    ] {
        let run = world.ndds(args);
        // clap's usage errors exit with 2.
        assert_eq!(run.status.and_then(|s| s.code()), Some(2), "{run}");
    }
}

#[test]
fn perf_port_serves_a_tightly_coupled_port_that_ndds_ports_shows() {
    let world = World::start();
    let server = world.spawn(&[
        "perf",
        "port",
        "--serve",
        "--tight",
        "300",
        "--seconds",
        "20",
        "--port",
        "beam",
    ]);
    let run = world.ndds(&["perf", "port", "--port", "beam", "--count", "200", "--json"]);
    let report = json(&run);
    assert_eq!(report["mode"], "send/receive/reply", "{run}");
    assert_eq!(count(&report, "count"), 200, "{run}");
    assert!(number(&report, "p50_us") > 0.0, "{run}");
    let ports = world.ndds(&["ports", "--listen", "2"]);
    let text = ports.ok();
    assert!(
        text.contains("beam") && text.contains("tightly coupled (busy-waits 300 us)"),
        "{ports}"
    );
    drop(server);
}

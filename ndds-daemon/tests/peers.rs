//! Discovery without multicast between real `ndds-daemon` processes: static peer lists given by
//! flag and by config file, one-sided lists, and the errors of peer and port settings. Every
//! daemon binds to 127.0.0.1 with its own ports and group.

mod common;

use std::io::Read;
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::path::Path;
use std::time::{Duration, Instant};

use ndds_core::ipc::{Graph, NodeSummary};

use common::*;

/// Fast timers, so a few seconds cover several leases.
const TIMERS: [&str; 4] = ["--announce-period-ms", "200", "--lease-ms", "1000"];

/// A UDP port on 127.0.0.1 that was free a moment ago.
fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port()
}

/// A daemon in `dir/name` on unicast port `port`, with `extra` flags (which replace the
/// isolating ones of the same name).
fn daemon(dir: &Path, name: &str, port: u16, extra: &[String]) -> (Spawned, std::path::PathBuf) {
    let dir = dir.join(name);
    std::fs::create_dir_all(&dir).unwrap();
    let mut args = isolated(&dir);
    for (flag, value) in [("--multicast-group", 1), ("--discovery-port", 1)] {
        if extra.iter().any(|e| e == flag)
            && let Some(at) = args.iter().position(|a| a == flag)
        {
            args.drain(at..=at + value);
        }
    }
    args.extend(["--unicast-port".into(), port.to_string()]);
    args.extend(TIMERS.iter().map(|s| s.to_string()));
    args.extend_from_slice(extra);
    (spawn(&args), dir.join("d.sock"))
}

/// Polls the daemon's graph until `check` holds; panics after [`WAIT`].
fn graph_until(socket: &Path, what: &str, check: impl Fn(&Graph) -> bool) -> Graph {
    let deadline = Instant::now() + WAIT;
    loop {
        let graph = graph(socket);
        if check(&graph) {
            return graph;
        }
        assert!(Instant::now() < deadline, "{what}: {graph:#?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn node_at(graph: &Graph, port: u16) -> Option<&NodeSummary> {
    graph.nodes.iter().find(|n| n.info.unicast.port == port)
}

fn log_of(mut child: Spawned) -> String {
    let mut log = String::new();
    if let Some(mut err) = child.stderr.take() {
        let _ = err.read_to_string(&mut log);
    }
    log
}

#[test]
fn daemons_without_multicast_find_each_other_through_their_peers() {
    let dir = tempfile::tempdir().unwrap();
    let (pa, pb) = (free_port(), free_port());
    // A takes its settings from flags, B from a config file.
    let (mut a, socket_a) = daemon(
        dir.path(),
        "a",
        pa,
        &[
            "--no-multicast".into(),
            "--peers".into(),
            format!("127.0.0.1:{pb}"),
        ],
    );
    let config = dir.path().join("b.toml");
    std::fs::write(
        &config,
        format!("multicast = false\npeers = [\"localhost:{pa}\"]\n"),
    )
    .unwrap();
    let (mut b, socket_b) = daemon(
        dir.path(),
        "b",
        pb,
        &["--config".into(), config.display().to_string()],
    );

    let graph_a = graph_until(&socket_a, "A sees B", |g| node_at(g, pb).is_some());
    let graph_b = graph_until(&socket_b, "B sees A", |g| node_at(g, pa).is_some());
    for (graph, own, other, name) in [
        (&graph_a, pa, &graph_b, format!("127.0.0.1:{pb}")),
        (&graph_b, pb, &graph_a, format!("localhost:{pa}")),
    ] {
        let local = &graph.local;
        assert_eq!(local.multicast, None, "multicast is off");
        assert_eq!(local.info.unicast.port, own);
        assert_eq!(local.peers.len(), 1);
        let peer = &local.peers[0];
        assert_eq!(peer.name, name);
        assert_eq!(peer.locator.addr, [127, 0, 0, 1]);
        assert_eq!(peer.node, Some(other.local.node), "the peer is known");
        let remote = node_at(graph, other.local.info.unicast.port).unwrap();
        assert_eq!(remote.multicast_seen_ms, None, "never heard by multicast");
        assert!(remote.unicast_copies);
    }
    assert_eq!(terminate(&mut a), Some(0));
    assert_eq!(terminate(&mut b), Some(0));
}

#[test]
fn without_multicast_a_daemon_neither_hears_nor_sends_to_the_group() {
    let dir = tempfile::tempdir().unwrap();
    let group_dir = dir.path().join("m");
    std::fs::create_dir_all(&group_dir).unwrap();
    // Our own member of the group the test daemons are configured with.
    let flags = isolated(&group_dir);
    let arg = |name: &str| {
        let at = flags.iter().position(|f| f == name).unwrap();
        flags[at + 1].clone()
    };
    let group: Ipv4Addr = arg("--multicast-group").parse().unwrap();
    let port: u16 = arg("--discovery-port").parse().unwrap();
    let listener = socket2::Socket::new(
        socket2::Domain::IPV4,
        socket2::Type::DGRAM,
        Some(socket2::Protocol::UDP),
    )
    .unwrap();
    listener.set_reuse_address(true).unwrap();
    listener
        .bind(&std::net::SocketAddr::V4(SocketAddrV4::new(group, port)).into())
        .unwrap();
    listener
        .join_multicast_v4(&group, &Ipv4Addr::LOCALHOST)
        .unwrap();
    let listener: UdpSocket = listener.into();
    listener
        .set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();

    // A and B without multicast, C with it, all on that group and port.
    let same_group = |mut extra: Vec<String>| {
        extra.extend([
            "--multicast-group".into(),
            group.to_string(),
            "--discovery-port".into(),
            port.to_string(),
        ]);
        extra
    };
    let (pa, pb, pc) = (free_port(), free_port(), free_port());
    let (mut a, socket_a) = daemon(
        dir.path(),
        "a",
        pa,
        &same_group(vec![
            "--no-multicast".into(),
            "--peers".into(),
            format!("127.0.0.1:{pb}"),
        ]),
    );
    let (mut b, socket_b) = daemon(
        dir.path(),
        "b",
        pb,
        &same_group(vec!["--no-multicast".into()]),
    );
    graph_until(&socket_a, "A sees B", |g| node_at(g, pb).is_some());
    graph_until(&socket_b, "B sees A", |g| node_at(g, pa).is_some());
    // Over several periods nothing reaches the group.
    let mut buf = [0u8; 2048];
    let quiet_until = Instant::now() + Duration::from_millis(1000);
    while Instant::now() < quiet_until {
        if let Ok((_, from)) = listener.recv_from(&mut buf) {
            panic!("a daemon without multicast sent to the group from {from}");
        }
    }

    // C, with multicast, is heard in the group but not by A or B.
    let (mut c, _socket_c) = daemon(dir.path(), "c", pc, &same_group(Vec::new()));
    let deadline = Instant::now() + WAIT;
    let from = loop {
        assert!(Instant::now() < deadline, "C's multicast never arrived");
        if let Ok((_, from)) = listener.recv_from(&mut buf) {
            break from;
        }
    };
    assert_eq!(from.port(), pc);
    std::thread::sleep(Duration::from_millis(500));
    for socket in [&socket_a, &socket_b] {
        let graph = graph(socket);
        assert!(node_at(&graph, pc).is_none(), "{graph:#?}");
    }
    for child in [&mut a, &mut b, &mut c] {
        assert_eq!(terminate(child), Some(0));
    }
}

#[test]
fn a_one_sided_peer_list_keeps_both_daemons_beyond_several_leases() {
    let dir = tempfile::tempdir().unwrap();
    let (pa, pb) = (free_port(), free_port());
    let (mut b, socket_b) = daemon(dir.path(), "b", pb, &["--no-multicast".into()]);
    let (mut a, socket_a) = daemon(
        dir.path(),
        "a",
        pa,
        &[
            "--no-multicast".into(),
            "--peers".into(),
            format!("127.0.0.1:{pb}"),
        ],
    );
    graph_until(&socket_a, "A sees B", |g| node_at(g, pb).is_some());
    let graph_b = graph_until(&socket_b, "B sees A", |g| node_at(g, pa).is_some());
    assert!(graph_b.local.peers.is_empty(), "B lists nobody");
    let b_id = graph_b.local.node;
    // Four leases later both still know each other, refreshed within the last lease.
    std::thread::sleep(Duration::from_millis(4000));
    let graph_a = graph(&socket_a);
    let graph_b = graph(&socket_b);
    let b_at_a = node_at(&graph_a, pb).expect("A still knows B");
    let a_at_b = node_at(&graph_b, pa).expect("B still knows A");
    assert_eq!(b_at_a.node, b_id, "the same B, never forgotten");
    assert!(b_at_a.last_seen_ms < 1000 && a_at_b.last_seen_ms < 1000);
    assert!(
        a_at_b.unicast_copies,
        "B sends to A although it lists nobody"
    );
    assert_eq!(terminate(&mut a), Some(0));
    assert_eq!(terminate(&mut b), Some(0));
}

#[test]
fn peers_that_cannot_be_used_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let base = isolated(dir.path());
    let with = |extra: &[&str]| {
        let mut args: Vec<&str> = base.iter().map(String::as_str).collect();
        args.extend_from_slice(extra);
        run(&args)
    };
    for (peers, expected) in [
        (
            "no-such-host.invalid",
            "cannot resolve peer no-such-host.invalid",
        ),
        ("127.0.0.1:99999", "127.0.0.1:99999"),
        ("239.255.76.1", "not a unicast host address"),
    ] {
        let out = with(&["--peers", peers]);
        assert!(!out.status.success(), "{peers} was accepted");
        assert!(stderr(&out).contains(expected), "{peers}: {}", stderr(&out));
    }

    let config = dir.path().join("many.toml");
    let list: Vec<String> = (0..300)
        .map(|i| format!("\"10.9.{}.{}\"", i / 200, i % 200 + 1))
        .collect();
    std::fs::write(&config, format!("peers = [{}]\n", list.join(", "))).unwrap();
    let out = with(&["--config", config.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("300 peers") && stderr(&out).contains("at most 256"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn a_taken_unicast_port_is_an_error_only_when_given_explicitly() {
    let dir = tempfile::tempdir().unwrap();
    let holder = UdpSocket::bind("127.0.0.1:0").unwrap();
    let taken = holder.local_addr().unwrap().port();
    let mut args = isolated(dir.path());
    args.extend(["--unicast-port".into(), taken.to_string()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = run(&args);
    assert!(!out.status.success());
    let text = stderr(&out);
    assert!(
        text.contains(&format!("unicast port {taken} on 127.0.0.1 is taken")),
        "{text}"
    );

    // The domain's default port taken: the daemon runs on another one and says so.
    let domain = fastrand::u16(1..=232);
    let default = ndds_core::domain::unicast_port(domain);
    let _default_holder = UdpSocket::bind(("127.0.0.1", default));
    let mut args = isolated(dir.path());
    args.extend(["--domain".into(), domain.to_string()]);
    let mut daemon = spawn(&args);
    let graph = graph(&dir.path().join("d.sock"));
    assert_ne!(graph.local.info.unicast.port, default);
    assert_eq!(terminate(&mut daemon), Some(0));
    let log = log_of(daemon);
    assert!(
        log.contains("default unicast discovery port is taken"),
        "{log}"
    );
}

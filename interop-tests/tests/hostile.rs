//! Bad input against real processes: malformed, truncated and foreign datagrams to a daemon
//! and to a client's data socket, and garbage on the daemon's Unix socket. Everything is
//! counted or logged; nothing crashes; service continues.

use std::io::{Read, Write};
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::os::unix::net::UnixStream;
use std::time::Duration;

use interop_tests::{TestDomain, wait_until};
use ndds_client::{ConsumerQos, EmbeddedPolicy, Graph, Participant, ProducerQos};
use ndds_core::wire::{self, Bye, Header, Message, MessageKind};

const WAIT: Duration = Duration::from_secs(10);

fn counter(graph: &Graph, name: &str) -> u64 {
    graph
        .counters
        .iter()
        .find(|(n, _)| n == name)
        .map_or_else(|| panic!("no counter {name}"), |(_, v)| *v)
}

fn header(kind: u8, domain: u16) -> Vec<u8> {
    let mut bytes = Vec::new();
    Header {
        kind: MessageKind::Bye,
        domain,
        sender: 0x5eed,
    }
    .emit(&mut bytes);
    bytes[5] = kind;
    bytes
}

/// One datagram for each drop reason a discovery receiver distinguishes.
fn hostile_datagrams(domain: u16) -> Vec<(&'static str, Vec<u8>)> {
    let mut other_version = header(MessageKind::Bye as u8, domain);
    other_version[4] = 99;
    let mut malformed = header(MessageKind::Announce as u8, domain);
    malformed.extend_from_slice(&[0xff; 40]);
    let mut trailing = Vec::new();
    wire::encode(domain, 0x5eed, &Message::Bye(Bye), &mut trailing).unwrap();
    trailing.push(0);
    vec![
        ("dropped_truncated", b"NDD".to_vec()),
        (
            "dropped_foreign_magic",
            b"RTPS\x02\x01\x01\x0f garbage".to_vec(),
        ),
        ("dropped_unsupported_version", other_version),
        ("dropped_unknown_kind", header(200, domain)),
        (
            "dropped_other_domain",
            header(MessageKind::Bye as u8, domain.wrapping_add(1)),
        ),
        ("dropped_malformed", malformed),
        ("dropped_malformed", trailing),
    ]
}

fn loopback_sender() -> UdpSocket {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    // Multicast from tests must leave through loopback, never the machine's uplink.
    socket2::SockRef::from(&socket)
        .set_multicast_if_v4(&Ipv4Addr::LOCALHOST)
        .unwrap();
    socket
}

#[test]
fn hostile_discovery_datagrams_are_counted_and_dropped() {
    let domain = TestDomain::new();
    let daemon = domain.daemon("a");
    let tool = domain.tool("a");
    let before = tool.graph().unwrap();
    let unicast = SocketAddrV4::from(before.local.info.unicast);
    let group = SocketAddrV4::new(domain.group, domain.port);
    let sender = loopback_sender();
    let datagrams = hostile_datagrams(domain.domain);
    for (_, bytes) in &datagrams {
        sender.send_to(bytes, unicast).unwrap();
        sender.send_to(bytes, group).unwrap();
    }
    let expect = |name: &str| 2 * datagrams.iter().filter(|(n, _)| *n == name).count() as u64;
    let counted = wait_until(WAIT, || {
        let graph = tool.graph().unwrap();
        datagrams
            .iter()
            .all(|(name, _)| counter(&graph, name) >= counter(&before, name) + expect(name))
    });
    let after = tool.graph().unwrap();
    assert!(counted.is_some(), "counters: {:?}", after.counters);
    assert_eq!(
        counter(&after, "datagrams_accepted"),
        counter(&before, "datagrams_accepted"),
        "none of them was accepted"
    );
    assert!(
        after.nodes.is_empty(),
        "no phantom node from the hostile sender"
    );

    // The daemon still works: a second daemon is discovered.
    let _b = domain.daemon("b");
    assert!(wait_until(WAIT, || tool.graph().unwrap().nodes.len() == 1).is_some());
    drop(daemon);
}

#[test]
fn garbage_on_the_unix_socket_disconnects_that_client_only() {
    let domain = TestDomain::new();
    let daemon = domain.daemon("a");
    let tool = domain.tool("a");
    let cases: [&[u8]; 3] = [
        // A length prefix claiming 4 GiB.
        &[0xff, 0xff, 0xff, 0xff, 1, 2, 3],
        // A well-framed body that is not a message.
        &[0, 0, 0, 4, 0xde, 0xad, 0xbe, 0xef],
        // A valid `Undeclare` before `Hello`.
        &[0, 0, 0, 2, 2, 7],
    ];
    for bytes in cases {
        let mut stream = UnixStream::connect(domain.socket("a")).unwrap();
        stream.set_read_timeout(Some(WAIT)).unwrap();
        stream.write_all(bytes).unwrap();
        // The daemon closes the connection (possibly after a `Refused` frame).
        let mut rest = Vec::new();
        let closed = stream.read_to_end(&mut rest);
        assert!(closed.is_ok(), "daemon closed the connection: {closed:?}");
    }
    let graph = tool.graph().unwrap();
    assert_eq!(counter(&graph, "protocol_errors"), 2);
    assert_eq!(counter(&graph, "sessions_refused"), 1);
    assert!(tool.is_connected(), "other sessions are unaffected");
    let log = daemon.log_text();
    assert!(
        log.contains("framing error") || log.contains("bad frame"),
        "{log}"
    );
    assert!(log.contains("undecodable frame"), "{log}");
    assert!(log.contains("the first frame must be Hello"), "{log}");
}

#[test]
fn hostile_datagrams_to_a_data_socket_are_counted_and_samples_still_flow() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let participant = Participant::builder()
        .socket(domain.socket("a"))
        .embedded(EmbeddedPolicy::Never)
        .connect()
        .unwrap();
    let consumer = participant
        .consumer::<u32>("data", ConsumerQos::default())
        .unwrap();
    let producer = participant
        .producer::<u32>("data", ProducerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    let data_socket = SocketAddrV4::from(producer.matched()[0].locator);
    let sender = loopback_sender();
    let datagrams = hostile_datagrams(domain.domain);
    for (_, bytes) in &datagrams {
        sender.send_to(bytes, data_socket).unwrap();
    }
    // A discovery message on a data socket is well-formed but unexpected.
    let mut bye = Vec::new();
    wire::encode(domain.domain, 1, &Message::Bye(Bye), &mut bye).unwrap();
    sender.send_to(&bye, data_socket).unwrap();

    producer.write(&41).unwrap();
    assert_eq!(consumer.recv_timeout(WAIT).unwrap().value, 41);
    let stats = participant.stats();
    assert_eq!(stats.delivered, 1);
    for (name, _) in &datagrams {
        let reason = name.trim_start_matches("dropped_");
        assert!(stats.dropped(reason) >= 1, "{reason}: {stats:?}");
    }
    assert_eq!(stats.dropped("unexpected"), 1);
}

#[test]
fn a_flood_of_junk_does_not_silence_a_daemon() {
    let domain = TestDomain::new();
    let a = domain.daemon("a");
    let _b = domain.daemon("b");
    let (tool_a, tool_b) = (domain.tool("a"), domain.tool("b"));
    let a_node = tool_a.graph().unwrap().local.node;
    assert!(
        wait_until(WAIT, || tool_b
            .graph()
            .unwrap()
            .nodes
            .iter()
            .any(|n| n.node == a_node))
        .is_some()
    );
    let target = SocketAddrV4::from(tool_a.graph().unwrap().local.info.unicast);

    // Junk at A's unicast port for twice the lease, bounded in time and count.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flood = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let sender = loopback_sender();
            let junk = [0xAB_u8; 64];
            let mut sent = 0u64;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) && sent < 20_000_000 {
                let _ = sender.send_to(&junk, target);
                sent += 1;
            }
            sent
        })
    };
    let started = std::time::Instant::now();
    let mut lost = false;
    while started.elapsed() < interop_tests::LEASE * 2 {
        lost |= !tool_b
            .graph()
            .unwrap()
            .nodes
            .iter()
            .any(|n| n.node == a_node);
        std::thread::sleep(Duration::from_millis(50));
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let sent = flood.join().unwrap();
    let graph = tool_a.graph().unwrap();
    eprintln!(
        "sent {sent} junk datagrams; A dropped {} as foreign, {} overflowed its queue",
        counter(&graph, "dropped_foreign_magic"),
        counter(&graph, "input_overflow")
    );
    assert!(counter(&graph, "dropped_foreign_magic") > 0);
    assert!(
        !lost,
        "B lost A during the flood: A's refreshes were starved"
    );
    drop(a);
}

#[test]
fn a_frozen_client_neither_blocks_the_daemon_nor_delays_its_shutdown() {
    let domain = TestDomain::new();
    let mut daemon = domain.daemon("a");
    let frozen = interop_tests::ClientProcess::test_node(
        &domain.socket("a"),
        &["produce", "--topic", "busy", "--rate", "10"],
    );
    frozen.event("ready", WAIT).expect("producer ready");
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(frozen.pid() as i32),
        nix::sys::signal::Signal::SIGSTOP,
    )
    .unwrap();
    // Every consumer created and dropped sends the frozen producer two events it never reads.
    let participant = Participant::builder()
        .socket(domain.socket("a"))
        .embedded(EmbeddedPolicy::Never)
        .connect()
        .unwrap();
    let tool = domain.tool("a");
    let dropped = wait_until(Duration::from_secs(60), || {
        for _ in 0..100 {
            drop(
                participant
                    .consumer::<u32>("busy", ConsumerQos::default())
                    .unwrap(),
            );
        }
        counter(&tool.graph().unwrap(), "slow_clients") >= 1
    });
    assert!(
        dropped.is_some(),
        "the daemon never gave up on the frozen client"
    );
    assert!(
        !interop_tests::has_endpoint(&tool.graph().unwrap(), "busy", frozen.pid()),
        "the frozen client's endpoints are withdrawn"
    );
    let stopping = std::time::Instant::now();
    assert_eq!(daemon.terminate(WAIT), Some(0));
    assert!(
        stopping.elapsed() < Duration::from_secs(1),
        "shutdown took {:?}",
        stopping.elapsed()
    );
    assert!(!daemon.log_text().contains("did not stop in time"));
}

/// A datagram naming one consumer many times reaches it once; from a sender discovery never
/// matched (this test's socket), it is then dropped and counted once, and nothing is
/// delivered.
#[test]
fn a_datagram_naming_one_reader_many_times_reaches_it_once() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let participant = Participant::builder()
        .socket(domain.socket("a"))
        .embedded(EmbeddedPolicy::Never)
        .connect()
        .unwrap();
    let consumer = participant
        .consumer::<u32>(
            "dup",
            ConsumerQos {
                depth: 100_000,
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let producer = participant
        .producer::<u32>("dup", ProducerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    let reader = producer.matched()[0].clone();
    let payload = postcard::to_allocvec(&5u32).unwrap();
    // The most readers a datagram may name, all the same one.
    let readers = vec![reader.guid.entity; ndds_core::wire::data::MAX_READERS];
    let mut writer = ndds_core::wire::DataWriter::new();
    writer.begin(
        domain.domain,
        0xfeed,
        &ndds_core::wire::data::Addressing {
            reader_participant: reader.guid.participant,
            writer: 1,
            token: 0x5eed,
            readers: &readers,
        },
    );
    let sample = ndds_core::wire::DataSub::Sample(ndds_core::wire::data::Sample {
        meta: ndds_core::wire::SampleMeta {
            seq: 1,
            ..ndds_core::wire::SampleMeta::default()
        },
        payload: &payload,
    });
    assert!(writer.push(&sample, wire::MAX_DATAGRAM));
    let bytes = writer.bytes().to_vec();
    loopback_sender()
        .send_to(&bytes, SocketAddrV4::from(reader.locator))
        .unwrap();
    assert!(wait_until(WAIT, || participant.stats().unmatched_sender == 1).is_some());
    assert!(consumer.recv_timeout(Duration::from_millis(1500)).is_err());
    let stats = participant.stats();
    assert_eq!(stats.delivered, 1, "handed to the consumer once");
    assert_eq!(stats.unmatched_sender, 1, "{stats:?}");
    assert_eq!(consumer.stats().unmatched, 1);
}

//! Hostile input across hosts while real traffic flows: a blast of random, truncated,
//! maximum-size and foreign datagrams at a daemon's discovery ports (unicast and the
//! multicast group) and at a consumer's data port. Real daemons and test nodes on hosts
//! simulated with network namespaces (needs root, `ip` and `nft`).

mod support;

use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::time::{Duration, Instant};

use interop_tests::netns::Cluster;
use interop_tests::{ClientProcess, has_endpoint};
use ndds_core::wire::{Header, MAX_DATAGRAM, MessageKind};
use serde_json::Value;
use support::{
    WAIT, counter, exclusive, field, node, notifications, read_until, samples, unix_us_now,
};

const A: usize = 0;
const B: usize = 1;
const C: usize = 2;
const TOPIC: &str = "hostile";
/// How long the blast lasts.
const BLAST: Duration = Duration::from_secs(3);
/// Most junk datagrams each sender sends (the blast also ends at `BLAST`).
const MAX_JUNK: u64 = 3_000_000;
/// Growth of the daemon's resident memory the blast may cause.
const RSS_BOUND_KIB: u64 = 20 * 1024;

/// The kinds of junk, sent in turn.
#[derive(Clone, Copy, Debug)]
enum Junk {
    /// Random bytes of a random length up to one Ethernet payload.
    Random,
    /// The first 1 to 15 bytes of a valid header.
    Truncated,
    /// A datagram of the largest size UDP carries, random bytes.
    MaxSize,
    /// A maximum-size datagram with a valid `Announce` header and a junk body.
    MaxSizeMalformed,
    /// Another protocol's header (RTPS).
    Foreign,
    /// A valid header of another domain.
    OtherDomain,
    /// A valid header with an unknown message kind.
    UnknownKind,
}

/// Small junk: costs the receivers per datagram.
const SMALL: [Junk; 5] = [
    Junk::Random,
    Junk::Truncated,
    Junk::Foreign,
    Junk::OtherDomain,
    Junk::UnknownKind,
];
/// Large junk: costs the receivers buffer space (and the kernel reassembly).
const LARGE: [Junk; 2] = [Junk::MaxSize, Junk::MaxSizeMalformed];

fn header(kind: u8, domain: u16) -> Vec<u8> {
    let mut bytes = Vec::new();
    Header {
        kind: MessageKind::Announce,
        domain,
        sender: 0x5eed_5eed,
    }
    .emit(&mut bytes);
    bytes[5] = kind;
    bytes
}

/// Fills `out` with one datagram of `junk` for `domain`.
fn junk(kind: Junk, domain: u16, rng: &mut fastrand::Rng, out: &mut Vec<u8>) {
    out.clear();
    match kind {
        Junk::Random => {
            let len = rng.usize(1..=1472);
            out.extend((0..len).map(|_| rng.u8(..)));
        }
        Junk::Truncated => {
            let len = rng.usize(1..16);
            out.extend_from_slice(&header(MessageKind::Announce as u8, domain)[..len]);
        }
        Junk::MaxSize => {
            out.resize(MAX_DATAGRAM, 0);
            rng.fill(out);
        }
        Junk::MaxSizeMalformed => {
            out.extend_from_slice(&header(MessageKind::Announce as u8, domain));
            out.resize(MAX_DATAGRAM, 0xff);
            let at = rng.usize(16..MAX_DATAGRAM);
            out[at] = rng.u8(..);
        }
        Junk::Foreign => {
            out.extend_from_slice(b"RTPS\x02\x01\x01\x0f");
            out.extend((0..rng.usize(8..200)).map(|_| rng.u8(..)));
        }
        Junk::OtherDomain => {
            out.extend_from_slice(&header(MessageKind::Announce as u8, domain.wrapping_add(1)))
        }
        Junk::UnknownKind => out.extend_from_slice(&header(200, domain)),
    }
}

/// Sends junk of `kinds` from `from` to every target in turn, as fast as the socket takes it,
/// until `BLAST` or `MAX_JUNK`; returns how many datagrams (and bytes) were sent.
fn blast(from: Ipv4Addr, targets: &[SocketAddrV4], domain: u16, kinds: &[Junk]) -> (u64, u64) {
    let socket = UdpSocket::bind((from, 0)).expect("junk socket");
    // Multicast leaves through this host's link, never another interface.
    socket2::SockRef::from(&socket)
        .set_multicast_if_v4(&from)
        .expect("IP_MULTICAST_IF");
    let mut rng = fastrand::Rng::with_seed(0x5eed);
    let mut buffer = Vec::with_capacity(MAX_DATAGRAM);
    let started = Instant::now();
    let (mut sent, mut bytes) = (0u64, 0u64);
    while sent < MAX_JUNK && started.elapsed() < BLAST {
        let kind = kinds[(sent as usize / targets.len()) % kinds.len()];
        junk(kind, domain, &mut rng, &mut buffer);
        if socket
            .send_to(&buffer, targets[sent as usize % targets.len()])
            .is_ok()
        {
            bytes += buffer.len() as u64;
        }
        sent += 1;
    }
    (sent, bytes)
}

/// The share of the producer's samples written between `from_us` and `to_us` (its clock)
/// that `lines` report: sequence numbers strictly between the last sample written before and
/// the first written after the window were all written inside it.
fn delivered(lines: &[Value], from_us: u64, to_us: u64) -> (u64, u64) {
    let seqs: Vec<(u64, u64)> = samples(lines)
        .iter()
        .map(|s| (field(s, "source_unix_us"), field(s, "seq")))
        .collect();
    let before = seqs
        .iter()
        .filter(|(t, _)| *t < from_us)
        .map(|(_, s)| *s)
        .max();
    let after = seqs
        .iter()
        .filter(|(t, _)| *t > to_us)
        .map(|(_, s)| *s)
        .min();
    let (Some(before), Some(after)) = (before, after) else {
        let last = seqs.last().map(|(t, _)| *t as i64 - to_us as i64);
        panic!(
            "samples before and after the window are needed: {} samples, the last {last:?} µs \
             after the window",
            seqs.len()
        );
    };
    let inside = seqs
        .iter()
        .filter(|(_, s)| (before + 1..after).contains(s))
        .count() as u64;
    (inside, after - before - 1)
}

fn counters_of(cluster: &Cluster, host: usize, names: &[&str]) -> Vec<u64> {
    let graph = cluster.graph(host);
    names.iter().map(|n| counter(&graph, n)).collect()
}

fn running(processes: &mut [&mut ClientProcess]) -> bool {
    processes.iter_mut().all(|p| p.is_running())
}

#[test]
fn a_blast_of_junk_at_discovery_and_data_ports_leaves_traffic_and_memory_intact() {
    if support::skipped() {
        return;
    }
    const DROPS: [&str; 6] = [
        "dropped_truncated",
        "dropped_foreign_magic",
        "dropped_other_domain",
        "dropped_unknown_kind",
        "dropped_malformed",
        "input_overflow",
    ];
    let _turn = exclusive();
    let mut cluster = Cluster::new(3);
    let mut consumer = node(
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
            "--duration",
            "7",
            "--events",
        ],
    );
    let mut producer = node(
        &cluster,
        A,
        &[
            "produce",
            "--topic",
            TOPIC,
            "--rate",
            "100",
            "--wait-consumers",
            "1",
        ],
    );
    producer.event("matched", WAIT).expect("producer matched");
    read_until(&consumer, WAIT, |l| l["event"] == "sample")
        .0
        .expect("samples flow");
    let graph = cluster.graph(C);
    let data_port = graph
        .endpoints
        .iter()
        .find(|e| e.info.pid == consumer.pid())
        .map(|e| SocketAddrV4::from(e.info.locator))
        .expect("the consumer's data locator");
    let domain = cluster.domain();
    let targets = [
        SocketAddrV4::from(graph.local.info.unicast),
        SocketAddrV4::new(domain.group, domain.port),
        data_port,
    ];
    // A quiet second first: the baseline, and samples from before the blast.
    let quiet_us = unix_us_now();
    let mut lines = consumer.events_until(Instant::now() + Duration::from_secs(1));
    let drops_before = counters_of(&cluster, C, &DROPS);
    let memory_before = cluster.daemon(C).memory().expect("daemon memory");
    let consumer_before = consumer.memory().expect("consumer memory");

    let started_us = unix_us_now();
    let sender = cluster.host(B).ip();
    let domain_id = domain.domain;
    let host = cluster.host(B);
    let ((small, small_bytes), (large, large_bytes)) = std::thread::scope(|scope| {
        let small = scope.spawn(|| host.enter(|| blast(sender, &targets, domain_id, &SMALL)));
        let large = host.enter(|| blast(sender, &targets, domain_id, &LARGE));
        (small.join().expect("small junk sender"), large)
    });
    let ended_us = unix_us_now();
    let alive = running(&mut [&mut consumer, &mut producer])
        && (0..3).all(|h| cluster.daemon_mut(h).is_running());
    // Samples written after the blast, and time for the daemon to drain its input.
    lines.extend(consumer.events_until(Instant::now() + Duration::from_millis(300)));
    let memory_after = cluster.daemon(C).memory().expect("daemon memory");
    let consumer_after = consumer.memory().expect("consumer memory");
    // (The first sample, read before the quiet second, is not in `lines`.)
    let (quiet, quiet_written) = delivered(&lines, quiet_us + 100_000, started_us);
    let (received, written) = delivered(&lines, started_us, ended_us);
    let share = received as f64 / written as f64;
    let drops_after = counters_of(&cluster, C, &DROPS);
    let seconds = ms(ended_us - started_us) / 1000.0;
    eprintln!(
        "blast from host B at C's discovery unicast port, the group and C's consumer data port, \
         {seconds:.2} s: {small} small junk datagrams ({:.1} MB) and {large} of maximum size \
         ({:.1} MB)",
        small_bytes as f64 / 1e6,
        large_bytes as f64 / 1e6
    );
    eprintln!(
        "  consumer received {received} of the {written} samples written during the blast \
         ({:.1} %); before it, {quiet} of {quiet_written}",
        share * 100.0
    );
    eprintln!(
        "  daemon C: RSS {} -> {} KiB (peak {} -> {} KiB); consumer RSS {} -> {} KiB",
        memory_before.rss_kib,
        memory_after.rss_kib,
        memory_before.peak_kib,
        memory_after.peak_kib,
        consumer_before.rss_kib,
        consumer_after.rss_kib
    );
    for ((name, before), after) in DROPS.iter().zip(&drops_before).zip(&drops_after) {
        eprintln!("  daemon C {name}: +{}", after - before);
    }
    assert!(alive, "every daemon and client survives");
    let lost = notifications(&lines, "ProducerLost");
    assert!(lost.is_empty(), "discovery lost the producer: {lost:?}");
    // The consumer's I/O thread discards junk after a 16-byte header check, far faster
    // than one sender host can produce it (about 80 000 small and 1 200 maximum-size
    // datagrams a second here, a third of them at the data port), and its 4 MiB receive
    // buffer absorbs the bursts: every sample arrived in every run, also with both cores
    // busy. 90 % leaves room for a slow scheduler without letting a real regression through.
    assert!(share >= 0.9, "delivered {share:.3} during the blast");
    let growth = memory_after.rss_kib.saturating_sub(memory_before.rss_kib);
    let peak = memory_after.peak_kib.saturating_sub(memory_before.rss_kib);
    assert!(growth < RSS_BOUND_KIB, "daemon RSS grew by {growth} KiB");
    assert!(peak < RSS_BOUND_KIB, "daemon RSS peaked {peak} KiB higher");
    for ((name, before), after) in DROPS.iter().zip(&drops_before).zip(&drops_after).take(5) {
        assert!(after > before, "{name} counts the junk");
    }

    // The tools show the drops: `ndds nodes --json` carries the local daemon's counters.
    let out = cluster.ndds(C, &["nodes", "--json"], WAIT);
    assert_eq!(out.code, Some(0), "ndds nodes: {}", out.stderr);
    let nodes: Value = serde_json::from_str(&out.stdout).expect("JSON");
    let local = nodes["nodes"]
        .as_array()
        .into_iter()
        .flatten()
        .find(|n| n["local"] == true)
        .expect("the local daemon is listed");
    for (name, after) in DROPS.iter().zip(&drops_after).take(5) {
        assert!(
            local["counters"][name]
                .as_u64()
                .is_some_and(|n| n >= *after),
            "ndds nodes shows {name}: {}",
            local["counters"]
        );
    }
    // Discovery is intact, and the consumer counted the junk at its data port.
    assert!(has_endpoint(&cluster.graph(C), TOPIC, producer.pid()));
    assert!(has_endpoint(&cluster.graph(B), TOPIC, consumer.pid()));
    let done = consumer
        .event("done", Duration::from_secs(15))
        .expect("consumer done");
    eprintln!("  consumer data socket: {}", done["stats"]);
    for reason in [
        "truncated",
        "foreign_magic",
        "malformed",
        "other_domain",
        "unknown_kind",
    ] {
        assert!(
            done["stats"]["dropped"][reason]
                .as_u64()
                .is_some_and(|n| n > 0),
            "the consumer counted {reason}: {}",
            done["stats"]
        );
    }
}

fn ms(us: u64) -> f64 {
    us as f64 / 1000.0
}

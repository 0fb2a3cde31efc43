//! Forged but well-formed traffic from an attacker host: samples from a writer discovery never
//! matched (strongest strength, endless persistence), and samples, heartbeats and gaps that
//! carry the real producer's id; acknowledgements and a repair flood (every one of 512 samples
//! and 512 pieces asked for again) carrying the real consumer's id sent to the producer from
//! the attacker's own address. None of it is believed: each is dropped and counted, not one
//! byte goes back to the attacker, and the genuine reliable
//! stream (through 10 % loss, so repair matters) delivers every sample once, in order, with
//! nothing reported lost. Real daemons and test nodes on hosts simulated with network
//! namespaces (needs root, `ip` and `nft`); the attacker is a host of its own.

mod support;

use std::net::{SocketAddrV4, UdpSocket};
use std::time::{Duration, Instant};

use interop_tests::netns::Cluster;
use ndds_core::wire::data::{Addressing, FLAG_RELIABLE, Gap, Heartbeat, Sample};
use ndds_core::wire::feedback::{AckNack, MAX_BITMAP_BYTES, NackFrag, encode_feedback};
use ndds_core::wire::{DataSub, DataWriter, EndpointKind, FeedbackSub, MAX_DATAGRAM, SampleMeta};
use serde_json::Value;
use support::{WAIT, exclusive, field, node, notifications, read_until, samples};

const A: usize = 0;
const ATTACKER: usize = 1;
const C: usize = 2;
const TOPIC: &str = "forged";
/// Genuine samples: written at 2000 a second, so the forgery runs through most of the transfer.
const COUNT: u64 = 10_000;
/// Rounds of forgery (each sends one datagram of every kind), one every millisecond: among
/// them as many forged samples of each kind (at most strength and persistence, a timestamp
/// at the end of time).
const ROUNDS: u64 = 5_000;

/// One datagram with one submessage, from `sender` (a participant id) to `reader` of
/// participant `reader_participant`, as writer `writer`.
fn data(domain: u16, sender: u64, writer: u32, to: (u64, u32), sub: &DataSub<'_>) -> Vec<u8> {
    let mut out = DataWriter::new();
    out.begin(
        domain,
        sender,
        &Addressing {
            reader_participant: to.0,
            writer,
            token: 0,
            readers: &[to.1],
        },
    );
    assert!(out.push(sub, MAX_DATAGRAM));
    out.bytes().to_vec()
}

#[test]
fn forged_samples_heartbeats_gaps_and_acknowledgements_are_dropped_and_counted() {
    if support::skipped() {
        return;
    }
    let _turn = exclusive();
    let cluster = Cluster::new(3);
    cluster.network().drop_incoming(C, 10);
    let consumer = node(
        &cluster,
        C,
        &[
            "consume",
            "--topic",
            TOPIC,
            "--reliable",
            "256",
            "--count",
            &COUNT.to_string(),
            "--timeout",
            "30",
            "--events",
        ],
    );
    let producer = node(
        &cluster,
        A,
        &[
            "produce",
            "--topic",
            TOPIC,
            "--reliable",
            "256",
            "--rate",
            "2000",
            "--count",
            &COUNT.to_string(),
            "--wait-consumers",
            "1",
            "--wait-timeout",
            "30",
            "--linger",
            "10",
        ],
    );
    producer.event("matched", WAIT).expect("producer matched");
    let (first, mut lines) = read_until(&consumer, WAIT, |l| l["event"] == "sample");
    lines.push(first.expect("samples flow"));

    // What the attacker learns from discovery: both endpoints' ids and locators.
    let graph = cluster.graph(C);
    let endpoint = |kind: EndpointKind| {
        graph
            .endpoints
            .iter()
            .find(|e| e.info.topic == TOPIC && e.info.kind() == kind)
            .map(|e| e.info.clone())
            .expect("both endpoints are in the graph")
    };
    let (real_writer, real_reader) = (
        endpoint(EndpointKind::Producer),
        endpoint(EndpointKind::Consumer),
    );
    let reader_at = SocketAddrV4::from(real_reader.locator);
    let writer_at = SocketAddrV4::from(real_writer.locator);
    let domain = cluster.domain().domain;
    let to = (real_reader.guid.participant, real_reader.guid.entity);
    let payload = [0_u8; 16];
    let meta = |seq: u64| SampleMeta {
        seq,
        timestamp_ns: u64::MAX,
        strength: i32::MAX,
        persistence_us: u64::MAX,
        flags: FLAG_RELIABLE,
    };
    let forged_writer = real_writer.guid.participant ^ 0x5eed;
    let mut acknack = Vec::new();
    encode_feedback(
        domain,
        real_reader.guid.participant,
        real_writer.guid.participant,
        0,
        &[FeedbackSub::AckNack(AckNack {
            reader: real_reader.guid.entity,
            writer: real_writer.guid.entity,
            acked: u64::MAX / 2,
            missing: &[],
        })],
        &mut acknack,
    )
    .expect("an acknack encodes");
    // A repair flood from the attacker's own address: every one of 512 samples and 512
    // pieces asked for again, in the real reader's name. Believed, each datagram would make
    // the producer resend hundreds of datagrams.
    let all_missing = [0xff_u8; MAX_BITMAP_BYTES];
    let mut flood = Vec::new();
    encode_feedback(
        domain,
        real_reader.guid.participant,
        real_writer.guid.participant,
        0,
        &[
            FeedbackSub::AckNack(AckNack {
                reader: real_reader.guid.entity,
                writer: real_writer.guid.entity,
                acked: 1,
                missing: &all_missing,
            }),
            FeedbackSub::NackFrag(NackFrag {
                reader: real_reader.guid.entity,
                writer: real_writer.guid.entity,
                seq: 1,
                base: 0,
                missing: &all_missing,
            }),
        ],
        &mut flood,
    )
    .expect("a repair request encodes");
    let forged: Vec<(Vec<u8>, SocketAddrV4)> = vec![
        // A writer nobody matched, as strong and persistent as can be.
        (
            data(
                domain,
                forged_writer,
                1,
                to,
                &DataSub::Sample(Sample {
                    meta: meta(1),
                    payload: &payload,
                }),
            ),
            reader_at,
        ),
        // The real writer's id: a sample far ahead, a heartbeat and a gap that would skip
        // everything.
        (
            data(
                domain,
                real_writer.guid.participant,
                real_writer.guid.entity,
                to,
                &DataSub::Sample(Sample {
                    meta: meta(1 << 40),
                    payload: &payload,
                }),
            ),
            reader_at,
        ),
        (
            data(
                domain,
                real_writer.guid.participant,
                real_writer.guid.entity,
                to,
                &DataSub::Heartbeat(Heartbeat {
                    first: 1 << 63,
                    last: (1 << 63) + 10,
                }),
            ),
            reader_at,
        ),
        (
            data(
                domain,
                real_writer.guid.participant,
                real_writer.guid.entity,
                to,
                &DataSub::Gap(Gap {
                    from: 1,
                    to: 1 << 62,
                }),
            ),
            reader_at,
        ),
        // The real reader's id, acknowledging everything the producer will ever write.
        (acknack, writer_at),
        (flood, writer_at),
    ];
    let attacker = cluster.host(ATTACKER);
    let from = attacker.ip();
    let (sent, sent_bytes, answered) = attacker.enter(|| {
        let socket = UdpSocket::bind(SocketAddrV4::new(from, 0)).expect("attacker socket");
        socket.set_nonblocking(true).expect("non-blocking");
        let (mut sent, mut sent_bytes, mut answered) = (0_u64, 0_usize, 0_usize);
        let mut buf = vec![0_u8; 65536];
        let mut drain = |answered: &mut usize| {
            while let Ok((n, _)) = socket.recv_from(&mut buf) {
                *answered += n;
            }
        };
        for _ in 0..ROUNDS {
            for (bytes, to) in &forged {
                if socket.send_to(bytes, to).is_ok() {
                    sent += 1;
                    sent_bytes += bytes.len();
                }
            }
            drain(&mut answered);
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(500));
        drain(&mut answered);
        (sent, sent_bytes, answered)
    });
    eprintln!(
        "attacker host sent {sent} forged datagrams ({ROUNDS} rounds of {}, {sent_bytes} B) \
         and received {answered} B",
        forged.len()
    );
    assert_eq!(
        answered, 0,
        "nothing is sent to an address discovery never gave (no amplification)"
    );

    let (done, rest) = read_until(&consumer, Duration::from_secs(90), |l| l["event"] == "done");
    lines.extend(rest);
    let done: Value = done.unwrap_or_else(|| panic!("the consumer did not finish: {lines:?}"));
    let seqs: Vec<u64> = samples(&lines).iter().map(|s| field(s, "seq")).collect();
    assert_eq!(
        seqs,
        (1..=COUNT).collect::<Vec<_>>(),
        "every genuine sample, once, in order"
    );
    for kind in ["SamplesLost", "OldData", "ProducerLost"] {
        assert!(notifications(&lines, kind).is_empty(), "{kind}: {lines:?}");
    }
    eprintln!(
        "genuine reliable stream through 10 % loss: {} of {COUNT} samples delivered, in order, \
         each once; no forged sample delivered; 0 SamplesLost",
        seqs.len()
    );
    let stats = &done["stats"];
    eprintln!("consumer data socket: {stats}");
    assert!(field(stats, "unmatched_sender") > 0, "{stats}");
    assert!(field(stats, "wrong_address") > 0, "{stats}");

    let deadline = Instant::now() + Duration::from_secs(60);
    let producer_stats = loop {
        if let Some(line) = producer.event("stats", Duration::from_secs(1)) {
            break line["stats"].clone();
        }
        assert!(Instant::now() < deadline, "the producer reported no stats");
    };
    eprintln!("producer data socket: {producer_stats}");
    assert!(
        field(&producer_stats, "wrong_address") >= ROUNDS,
        "the forged acknowledgements and repair requests were counted: {producer_stats}"
    );
}

//! Forged discovery naming a live node: from a host of its own, an attacker sends the
//! consumer's daemon a `Bye`, a `Withdraw` of the producer's endpoint and an `Announce` with a
//! 2 ms lease, all carrying the producer's daemon's node id (ids travel in clear), ten a second
//! for thirty seconds, while samples flow. Not one is believed: the producer's endpoint is
//! never lost, delivery stays at least 99.9 %, and every forgery is counted as `spoofed`.
//! Real daemons and test nodes on network namespaces (needs root, `ip` and `nft`).

mod support;

use std::net::{SocketAddrV4, UdpSocket};
use std::time::{Duration, Instant};

use interop_tests::has_endpoint;
use interop_tests::netns::Cluster;
use ndds_core::wire::{self, Announce, Bye, Message, Withdraw};
use support::{WAIT, counter, exclusive, field, node, samples};

const PRODUCER: usize = 0;
const ATTACKER: usize = 1;
const CONSUMER: usize = 2;
const TOPIC: &str = "forged/discovery";
const PERIOD: Duration = Duration::from_millis(100);
const FORGERIES: u64 = 300;

#[test]
fn forged_bye_withdraw_and_short_leases_naming_a_live_node_are_not_believed() {
    if support::skipped() {
        return;
    }
    let _turn = exclusive();
    let cluster = Cluster::new(3);
    let mut consumer = node(
        &cluster,
        CONSUMER,
        &[
            "consume",
            "--topic",
            TOPIC,
            "--count",
            "1000000",
            "--timeout",
            "90",
            "--events",
        ],
    );
    let producer = node(
        &cluster,
        PRODUCER,
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
    let victim = cluster.graph(CONSUMER);
    let target = SocketAddrV4::from(victim.local.info.unicast);
    let named = cluster.graph(PRODUCER);
    let named_node = named.local.node;
    let endpoint = named
        .endpoints
        .iter()
        .find(|e| e.info.pid == producer.pid())
        .map(|e| e.info.guid)
        .expect("the producer's endpoint");
    let mut short = named.local.info.clone();
    short.lease_ms = 2;
    short.announce_period_ms = 1;
    let domain = cluster.domain().domain;
    let encode = |message: &Message| {
        let mut out = Vec::new();
        wire::encode(domain, named_node, message, &mut out).expect("forgery");
        out
    };
    let forgeries = [
        encode(&Message::Bye(Bye)),
        encode(&Message::Withdraw(Withdraw {
            endpoints: vec![endpoint],
        })),
        encode(&Message::Announce(Announce {
            node: short,
            endpoints: vec![],
            withdrawn: vec![],
        })),
    ];
    let spoofed_before = counter(&victim, "dropped_spoofed");
    let attacker = cluster.host(ATTACKER);
    let from = attacker.ip();
    let started = Instant::now();
    let mut lost_seen = 0;
    let mut checks = 0;
    let sent = std::thread::scope(|scope| {
        let sender = scope.spawn(|| {
            attacker.enter(|| {
                let socket = UdpSocket::bind((from, 0)).expect("attacker socket");
                let mut sent = 0u64;
                for i in 0..FORGERIES {
                    let due = started + PERIOD * i as u32;
                    std::thread::sleep(due.saturating_duration_since(Instant::now()));
                    if socket
                        .send_to(&forgeries[i as usize % forgeries.len()], target)
                        .is_ok()
                    {
                        sent += 1;
                    }
                }
                sent
            })
        });
        // Meanwhile, once a second: is the producer's endpoint still in the victim's table?
        while !sender.is_finished() {
            checks += 1;
            if !has_endpoint(&cluster.graph(CONSUMER), TOPIC, producer.pid()) {
                lost_seen += 1;
            }
            std::thread::sleep(Duration::from_secs(1));
        }
        sender.join().expect("forgery sender")
    });
    let lines = consumer.events_until(Instant::now() + Duration::from_millis(500));
    let after = cluster.graph(CONSUMER);
    let spoofed = counter(&after, "dropped_spoofed") - spoofed_before;

    let seqs: Vec<u64> = samples(&lines).iter().map(|s| field(s, "seq")).collect();
    let (first, last) = (
        seqs.iter().min().copied().unwrap_or(0),
        seqs.iter().max().copied().unwrap_or(0),
    );
    let mut distinct = seqs.clone();
    distinct.sort_unstable();
    distinct.dedup();
    let expected = last.saturating_sub(first) + 1;
    let share = distinct.len() as f64 / expected as f64;
    eprintln!(
        "forged discovery: {sent} forgeries in {:?}, {spoofed} counted as spoofed; {} of {} \
         samples delivered ({:.3} %)",
        started.elapsed(),
        distinct.len(),
        expected,
        share * 100.0
    );
    assert_eq!(sent, FORGERIES);
    assert_eq!(spoofed, FORGERIES, "every forgery is counted");
    assert!(checks >= 25, "{checks} checks");
    assert_eq!(
        lost_seen, 0,
        "the producer's endpoint was missing at {lost_seen} checks"
    );
    assert!(consumer.is_running());
    assert!(
        expected >= 2500,
        "samples flowed through the attack ({expected})"
    );
    assert!(share >= 0.999, "delivery {share}");
}

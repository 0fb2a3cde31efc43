//! Limits of the discovery engine against a misbehaving or hostile network: addresses it
//! answers, how much it remembers, and node-id clashes.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use ndds_core::discovery::engine::{
    MAX_ENDPOINTS_PER_NODE, MAX_NODES, MAX_REMOTE_BYTES, MAX_REMOTE_ENDPOINTS,
};
use ndds_core::discovery::{Destination, DiscoveryConfig, Engine, Event, LocalError, Origin, Via};

#[path = "support/probe.rs"]
mod probe;
use ndds_core::types::TypeDescription;
use ndds_core::wire::{
    self, Announce, DropReason, EndpointInfo, EndpointQos, Guid, Locator, Message, NodeInfo,
    ProducerQosWire, Solicit,
};
use probe::answer_probe;

fn locator(host: u8, port: u16) -> Locator {
    Locator {
        addr: [10, 0, 0, host],
        port,
    }
}

fn node_info(unicast: Locator) -> NodeInfo {
    NodeInfo {
        hostname: "peer".into(),
        pid: 1,
        unicast,
        lease_ms: 5000,
        announce_period_ms: 1000,
        version: String::new(),
    }
}

fn datagram(sender: u64, message: &Message) -> Vec<u8> {
    let mut out = Vec::new();
    wire::encode(0, sender, message, &mut out).unwrap();
    out
}

fn engine(now: Instant) -> Engine {
    let mut engine = Engine::new(DiscoveryConfig::new(0, locator(1, 7600)), now).unwrap();
    // Drain the start-up solicit and announcement.
    engine.handle_timeout(now);
    while engine.poll_transmit().is_some() {}
    engine
}

fn unicast_replies(engine: &mut Engine, now: Instant) -> Vec<Locator> {
    engine.handle_timeout(now + Duration::from_millis(50));
    std::iter::from_fn(|| engine.poll_transmit())
        .filter_map(|t| match t.destination {
            Destination::Unicast(to) => Some(to),
            Destination::Multicast => None,
        })
        .collect()
}

#[test]
fn a_solicit_is_answered_only_at_its_own_source_address() {
    let now = Instant::now();
    let mut engine = engine(now);
    let honest = locator(2, 7700);
    let solicit = Message::Solicit(Solicit {
        node: node_info(honest),
    });
    engine.handle_datagram(
        now,
        SocketAddr::V4(honest.into()),
        Via::Multicast,
        &datagram(2, &solicit),
    );
    assert_eq!(unicast_replies(&mut engine, now), vec![honest]);

    // A datagram from 10.0.0.3 naming a victim's address is recorded but not answered.
    let victim = locator(99, 53);
    let forged = Message::Solicit(Solicit {
        node: node_info(victim),
    });
    let source: SocketAddr = "10.0.0.3:7700".parse().unwrap();
    engine.handle_datagram(now, source, Via::Multicast, &datagram(3, &forged));
    assert!(unicast_replies(&mut engine, now).is_empty());
}

#[test]
fn a_node_heard_by_unicast_gets_copies_only_at_its_own_source_address() {
    let now = Instant::now();
    let mut engine = engine(now);
    // Two nodes heard by unicast only: one honest, one naming a victim's address.
    let honest = locator(2, 7850);
    let announce = |unicast| {
        Message::Announce(Announce {
            node: node_info(unicast),
            endpoints: vec![],
            withdrawn: vec![],
        })
    };
    let from_honest = SocketAddr::V4(honest.into());
    engine.handle_datagram(
        now,
        from_honest,
        Via::Unicast,
        &datagram(2, &announce(honest)),
    );
    // The honest node proves its address by answering the engine's probe.
    answer_probe(&mut engine, now, honest, 0, 2);
    let victim = locator(99, 53);
    let source: SocketAddr = "10.0.0.3:7850".parse().unwrap();
    engine.handle_datagram(now, source, Via::Unicast, &datagram(3, &announce(victim)));
    assert_eq!(engine.nodes().count(), 2);
    // The forged node is known but never sent anything: no reply, no fan-out copy.
    assert_eq!(
        engine.fanout(),
        vec![Destination::Multicast, Destination::Unicast(honest)]
    );
    let later = now + Duration::from_secs(2);
    engine.handle_timeout(later);
    let destinations: Vec<Destination> = std::iter::from_fn(|| engine.poll_transmit())
        .map(|t| t.destination)
        .collect();
    assert!(destinations.contains(&Destination::Unicast(honest)));
    assert!(!destinations.contains(&Destination::Unicast(victim)));
}

/// An endpoint of a client on `host` (10.0.0.host).
fn endpoint(participant: u64, host: u8) -> EndpointInfo {
    let type_desc = TypeDescription::of::<u8>();
    EndpointInfo {
        guid: Guid {
            participant,
            entity: 1,
        },
        topic: format!("t{}", participant % 64),
        fingerprint: type_desc.fingerprint(),
        type_desc,
        qos: EndpointQos::Producer(ProducerQosWire::default()),
        locator: locator(host, 9),
        pid: 1,
        process: "p".into(),
    }
}

#[test]
fn remote_endpoints_are_bounded_per_node_and_in_all() {
    let now = Instant::now();
    let mut engine = engine(now);
    let nodes = MAX_REMOTE_ENDPOINTS / MAX_ENDPOINTS_PER_NODE + 2;
    let mut next = 1u64;
    for node in 0..nodes as u64 {
        let unicast = locator(100, 1000 + node as u16);
        let from = SocketAddr::V4(unicast.into());
        // Each node announces its full share plus one more.
        let all: Vec<EndpointInfo> = (0..=MAX_ENDPOINTS_PER_NODE)
            .map(|_| {
                next += 1;
                endpoint(next, 100)
            })
            .collect();
        for chunk in all.chunks(600) {
            let announce = Message::Announce(Announce {
                node: node_info(unicast),
                endpoints: chunk.to_vec(),
                withdrawn: vec![],
            });
            engine.handle_datagram(now, from, Via::Multicast, &datagram(1000 + node, &announce));
        }
        assert!(engine.endpoints().count() <= MAX_REMOTE_ENDPOINTS);
        assert!(engine.remote_bytes() <= MAX_REMOTE_BYTES);
    }
    // One source: its oldest nodes made room for its newest, which holds its whole share
    // (and not one more).
    let newest = engine
        .endpoints()
        .filter(|e| e.origin == Origin::Remote(1000 + nodes as u64 - 1))
        .count();
    assert_eq!(newest, MAX_ENDPOINTS_PER_NODE);
    assert!(engine.stats().evicted_nodes > 0);
    assert!(engine.stats().invalid_endpoints >= nodes as u64);
    // Decay still works at this size: everything is forgotten after the lease.
    engine.handle_timeout(now + Duration::from_secs(6));
    assert_eq!(engine.endpoints().count(), 0);
    assert_eq!(engine.nodes().count(), 0);
    assert_eq!(engine.remote_bytes(), 0);
}

#[test]
fn a_node_declares_no_more_endpoints_than_other_nodes_take_from_it() {
    let now = Instant::now();
    let mut engine = engine(now);
    let local = |n: u64| {
        let mut info = endpoint(n, 1);
        info.locator = locator(1, 9);
        info
    };
    for n in 1..=MAX_ENDPOINTS_PER_NODE as u64 {
        engine.add_local(now, local(n)).unwrap();
    }
    let over = local(MAX_ENDPOINTS_PER_NODE as u64 + 1);
    let refused = engine.add_local(now, over.clone()).unwrap_err();
    assert!(matches!(refused, LocalError::TooMany), "{refused:?}");
    assert!(refused.to_string().contains("withdraw some"), "{refused}");
    assert_eq!(engine.endpoint(&over.guid).map(|e| e.origin), None);
    // One withdrawn makes room for one.
    engine.remove_locals(&[local(1).guid]);
    engine.add_local(now, over.clone()).unwrap();
    assert_eq!(
        engine.endpoint(&over.guid).map(|e| e.origin),
        Some(Origin::Local)
    );
}

/// The flood: 5000 forged nodes with one-hour leases and 300 000 endpoints, all on the
/// topic a local consumer reads, from one address. A genuine node known before keeps its
/// endpoints, a genuine node arriving after is matched at once, the tables stay within their
/// bounds, and the flood costs linear work (quadratic matching would not finish).
#[test]
fn a_flood_of_forged_nodes_cannot_keep_genuine_nodes_out() {
    let now = Instant::now();
    let mut engine = engine(now);
    let topic = "arm/joints";
    let on_topic = |participant: u64, host: u8, kind: EndpointQos| {
        let mut info = endpoint(participant, host);
        info.topic = topic.into();
        info.qos = kind;
        info
    };
    let mut consumer = on_topic(1, 1, EndpointQos::Consumer(Default::default()));
    consumer.guid.participant = 0xC0FFEE;
    engine.add_local(now, consumer.clone()).unwrap();
    let genuine = |engine: &mut Engine, host: u8, id: u64| {
        let unicast = locator(host, 7600);
        let announce = Message::Announce(Announce {
            node: node_info(unicast),
            endpoints: vec![on_topic(
                id,
                host,
                EndpointQos::Producer(Default::default()),
            )],
            withdrawn: vec![],
        });
        let from = SocketAddr::V4(unicast.into());
        engine.handle_datagram(now, from, Via::Multicast, &datagram(id, &announce));
    };
    genuine(&mut engine, 2, 0xA);
    while engine.poll_event().is_some() {}

    let started = Instant::now();
    let attacker = locator(66, 7600);
    let from = SocketAddr::V4(attacker.into());
    let mut forged_endpoint = 1_000_000u64;
    for node in 0..5000u64 {
        let mut info = node_info(attacker);
        info.lease_ms = 3_600_000;
        let endpoints = (0..60)
            .map(|_| {
                forged_endpoint += 1;
                on_topic(
                    forged_endpoint,
                    66,
                    EndpointQos::Producer(Default::default()),
                )
            })
            .collect();
        let announce = Message::Announce(Announce {
            node: info,
            endpoints,
            withdrawn: vec![],
        });
        engine.handle_datagram(
            now,
            from,
            Via::Multicast,
            &datagram(0xF000_0000 + node, &announce),
        );
        while engine.poll_event().is_some() {}
    }
    let flood = started.elapsed();
    assert!(engine.nodes().count() <= MAX_NODES);
    assert!(engine.endpoints().count() <= MAX_REMOTE_ENDPOINTS + 1);
    assert!(engine.remote_bytes() <= MAX_REMOTE_BYTES);
    assert!(engine.stats().evicted_nodes > 0, "{:?}", engine.stats());
    let known = |engine: &Engine, id: u64| {
        engine
            .endpoint(&Guid {
                participant: id,
                entity: 1,
            })
            .is_some()
    };
    assert!(
        known(&engine, 0xA),
        "the genuine node known before the flood was evicted"
    );

    genuine(&mut engine, 3, 0xB);
    let matched: Vec<_> = std::iter::from_fn(|| engine.poll_event()).collect();
    assert!(
        matched
            .iter()
            .any(|e| matches!(e, Event::Matched { local, remote }
            if *local == consumer.guid && remote.guid.participant == 0xB)),
        "the genuine newcomer is matched at once"
    );
    assert!(known(&engine, 0xA) && known(&engine, 0xB));
    eprintln!(
        "flood of 5000 nodes / 300000 endpoints: {:?}, {} nodes and {} endpoints kept, {} bytes \
         accounted, {} nodes evicted",
        flood,
        engine.nodes().count(),
        engine.endpoints().count(),
        engine.remote_bytes(),
        engine.stats().evicted_nodes
    );
}

#[test]
fn two_nodes_with_one_id_cannot_see_each_other_and_say_so() {
    let now = Instant::now();
    let mut a_config = DiscoveryConfig::new(0, locator(1, 7600));
    a_config.node_id = Some(42);
    let mut b_config = DiscoveryConfig::new(0, locator(2, 7600));
    b_config.node_id = Some(42);
    let mut a = Engine::new(a_config, now).unwrap();
    let mut b = Engine::new(b_config, now).unwrap();
    a.handle_timeout(now);
    let from_a = SocketAddr::V4(locator(1, 7600).into());
    for transmit in std::iter::from_fn(|| a.poll_transmit()) {
        b.handle_datagram(now, from_a, Via::Multicast, &transmit.payload);
    }
    assert_eq!(b.node_id(), 42);
    assert!(b.stats().dropped(DropReason::Own) >= 1);
    assert_eq!(b.nodes().count(), 0);
}

/// Node ids travel in clear, so the engine believes a known node only from its own address:
/// a `Bye`, a `Withdraw` or a short-lease `Announce` naming it from elsewhere is dropped as
/// `spoofed`; an endpoint is believed only on its announcing node's host; and another node
/// cannot change or take over an endpoint.
#[test]
fn forgeries_naming_a_known_node_or_its_endpoints_are_not_believed() {
    let now = Instant::now();
    let mut engine = engine(now);
    let genuine = locator(2, 7600);
    let genuine_from = SocketAddr::V4(genuine.into());
    let attacker_from = SocketAddr::V4(locator(66, 7600).into());
    let announce = |node: NodeInfo, endpoints: Vec<EndpointInfo>| {
        Message::Announce(Announce {
            node,
            endpoints,
            withdrawn: vec![],
        })
    };
    let ours = endpoint(0xA, 2);
    let first = announce(node_info(genuine), vec![ours.clone()]);
    engine.handle_datagram(now, genuine_from, Via::Multicast, &datagram(7, &first));
    assert!(engine.endpoint(&ours.guid).is_some());

    let mut short = node_info(genuine);
    short.lease_ms = 2;
    short.announce_period_ms = 1;
    let forgeries = [
        datagram(7, &Message::Bye(wire::Bye)),
        datagram(
            7,
            &Message::Withdraw(wire::Withdraw {
                endpoints: vec![ours.guid],
            }),
        ),
        datagram(7, &announce(short, vec![])),
    ];
    for forged in &forgeries {
        engine.handle_datagram(now, attacker_from, Via::Unicast, forged);
    }
    assert_eq!(engine.stats().dropped(DropReason::Spoofed), 3);
    engine.handle_timeout(now + Duration::from_millis(100));
    assert!(
        engine.endpoint(&ours.guid).is_some(),
        "the endpoint survived"
    );
    assert!(engine.nodes().any(|(id, _)| id == 7), "the node survived");

    // The attacker's own node: an endpoint located elsewhere, a changed copy of the genuine
    // endpoint, and an identical copy (a takeover) are all refused.
    let mut elsewhere = endpoint(0xB, 2);
    elsewhere.guid.participant = 0xB;
    let mut changed = ours.clone();
    changed.locator = locator(66, 9);
    let invalid_before = engine.stats().invalid_endpoints;
    let attack = announce(
        node_info(locator(66, 7600)),
        vec![elsewhere.clone(), changed, ours.clone()],
    );
    engine.handle_datagram(now, attacker_from, Via::Unicast, &datagram(66, &attack));
    assert_eq!(engine.stats().invalid_endpoints - invalid_before, 3);
    assert!(engine.endpoint(&elsewhere.guid).is_none());
    assert_eq!(
        engine
            .endpoint(&ours.guid)
            .map(|e| (e.origin, e.info.locator)),
        Some((Origin::Remote(7), ours.locator))
    );

    // The genuine node's own Bye is believed.
    engine.handle_datagram(
        now,
        genuine_from,
        Via::Unicast,
        &datagram(7, &Message::Bye(wire::Bye)),
    );
    assert!(engine.endpoint(&ours.guid).is_none());
}

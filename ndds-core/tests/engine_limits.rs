//! Limits of the discovery engine against a misbehaving or hostile network: addresses it
//! answers, how much it remembers, and node-id clashes.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use ndds_core::discovery::engine::{MAX_ENDPOINTS_PER_NODE, MAX_REMOTE_ENDPOINTS};
use ndds_core::discovery::{Destination, DiscoveryConfig, Engine, Via};
use ndds_core::types::TypeDescription;
use ndds_core::wire::{
    self, Announce, DropReason, EndpointInfo, EndpointQos, Guid, Locator, Message, NodeInfo,
    ProducerQosWire, Solicit,
};

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

fn endpoint(participant: u64) -> EndpointInfo {
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
        locator: locator(9, 9),
        pid: 1,
        process: "p".into(),
    }
}

#[test]
fn remote_endpoints_are_capped_per_node_and_in_all() {
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
                endpoint(next)
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
    }
    assert_eq!(engine.endpoints().count(), MAX_REMOTE_ENDPOINTS);
    let announced = nodes * (MAX_ENDPOINTS_PER_NODE + 1);
    assert_eq!(
        engine.stats().invalid_endpoints,
        (announced - MAX_REMOTE_ENDPOINTS) as u64
    );
    // Decay still works at this size: everything is forgotten after the lease.
    engine.handle_timeout(now + Duration::from_secs(6));
    assert_eq!(engine.endpoints().count(), 0);
    assert_eq!(engine.nodes().count(), 0);
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

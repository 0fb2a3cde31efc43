//! Discovery in a sealed domain (see `support/simnet.rs`): daemons that hold the domain key
//! find each other and match as in an open domain, also through loss; a daemon with another
//! key or none is neither seen nor sees, forged `Bye`s without the key change nothing, and
//! every refused datagram is counted by reason.

#[path = "support/fixtures.rs"]
mod fixtures;
#[path = "support/simnet.rs"]
mod simnet;

use std::time::Duration;

use ndds_core::seal::{DomainKey, Keyring, OpenError, SealMode, SealSetup};
use ndds_core::wire::{Bye, Header, Message, MessageKind};

use fixtures::*;
use simnet::{SimNet, config};

const PERIOD: Duration = Duration::from_secs(1);
const LEASE: Duration = Duration::from_secs(5);

fn sealed(key: u8, session: u64) -> SealSetup {
    SealSetup {
        keyring: Keyring::new(1, DomainKey::from_bytes([key; 32])),
        mode: SealMode::Encrypt,
        session,
        require_encryption: true,
    }
}

#[test]
fn daemons_with_the_key_match_and_the_others_stay_outside() {
    let mut net = SimNet::new(3);
    net.set_loss(0.2);
    for i in 0..3 {
        net.add_node_with(config(i, 300 + i as u64, PERIOD, LEASE), |engine| {
            engine.seal_with(sealed(7, 1000 + i as u64));
        });
    }
    // Node 3 holds another key, node 4 none.
    net.add_node_with(config(3, 303, PERIOD, LEASE), |engine| {
        engine.seal_with(sealed(8, 1));
    });
    net.add_node(config(4, 304, PERIOD, LEASE));
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    for n in 1..5 {
        net.add_local(n, consumer::<Pose>(guid(n, 1), "arm/pose"));
    }
    net.run_for(Duration::from_secs(4));
    for n in 0..3 {
        assert_eq!(net.engine(n).nodes().count(), 2, "node {n}");
    }
    for n in 1..3 {
        assert!(net.knows(n, pose_producer.guid), "node {n}");
    }
    for n in 3..5 {
        assert_eq!(net.engine(n).nodes().count(), 0, "outsider {n}");
        assert!(!net.knows(n, pose_producer.guid), "outsider {n}");
        assert!(
            !net.knows(0, guid(n, 1)),
            "outsider {n}'s consumer at node 0"
        );
    }
    let inside = &net.engine(0).stats().seal;
    assert!(inside.opened > 0);
    assert!(inside.dropped(OpenError::BadTag) > 0, "{inside:?}");
    assert!(inside.dropped(OpenError::NotSealed) > 0, "{inside:?}");
    assert!(net.engine(4).stats().sealed_without_key > 0);
    assert!(net.engine(3).stats().seal.dropped(OpenError::BadTag) > 0);
}

#[test]
fn a_forged_bye_without_the_key_removes_nobody() {
    let mut net = SimNet::new(4);
    for i in 0..2 {
        net.add_node_with(config(i, 400 + i as u64, PERIOD, LEASE), |engine| {
            engine.seal_with(sealed(7, 1));
        });
    }
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    net.run_for(Duration::from_millis(500));
    assert!(net.knows(1, pose_producer.guid));
    // A Bye in node 0's name, sealed and not: neither is believed.
    let node0 = net.engine(0).node_id();
    let mut bye = Vec::new();
    ndds_core::wire::encode(simnet::DOMAIN, node0, &Message::Bye(Bye {}), &mut bye).unwrap();
    let mut forged_seal = bye.clone();
    ndds_core::seal::Sealer::new(
        &sealed(9, 5).keyring,
        simnet::DOMAIN,
        node0,
        5,
        SealMode::Encrypt,
    )
    .seal(&mut forged_seal)
    .unwrap();
    let header = Header::parse(&bye).unwrap().0;
    assert_eq!(header.kind, MessageKind::Bye);
    for datagram in [bye, forged_seal] {
        net.inject(1, simnet::locator(0), &datagram);
    }
    net.run_for(Duration::from_millis(10));
    assert!(
        net.knows(1, pose_producer.guid),
        "the forged Bye removed node 0"
    );
    let seal = &net.engine(1).stats().seal;
    assert_eq!(seal.dropped(OpenError::NotSealed), 1, "{seal:?}");
    assert_eq!(seal.dropped(OpenError::BadTag), 1, "{seal:?}");
}

//! Discovery with identities and a permissions document (see `support/simnet.rs` and
//! `ndds_core::security`): a subject matches what its rules allow and nothing else, both
//! sides say why, a node is bound to the identity it signs with, an unsigned node is not
//! heard, participants are their daemon's identity's, recorded signed datagrams are taken
//! once (also after their node is gone), and a new document (or the old one's end) takes
//! effect at once, for remote and local endpoints.

#[path = "support/fixtures.rs"]
mod fixtures;
#[path = "support/simnet.rs"]
mod simnet;

use std::sync::Arc;
use std::time::Duration;

use ndds_core::discovery::{Engine, Event, LocalError};
use ndds_core::security::{Guard, Identity, Pattern, Permissions, Subject};
use ndds_core::wire::{self, Bye, DropReason, EndpointInfo, Guid, Message, MessageKind, signed};
use serde::Serialize;
use serde::de::DeserializeOwned;

use fixtures::*;
use simnet::{SimNet, config};

const PERIOD: Duration = Duration::from_secs(1);
const LEASE: Duration = Duration::from_secs(5);

fn identity(n: u8) -> Identity {
    Identity::from_secret([n + 1; 32])
}

/// Endpoint `entity` of a participant of identity `n`'s daemon: in a domain with permissions
/// a participant id is one of its daemon's identity, as node ids are.
fn guid(n: u8, entity: u32) -> Guid {
    Guid {
        participant: ndds_core::security::node_id_for(&identity(n).public(), 0x5000),
        entity,
    }
}

/// `info` located on the host of node `n` (identity `n` runs at index `n` unless a test says
/// otherwise).
fn placed(mut info: EndpointInfo) -> EndpointInfo {
    let n = (0..3u8)
        .find(|n| guid(*n, 0).participant == info.guid.participant)
        .map_or(200, usize::from);
    info.locator = simnet::locator(n);
    info
}

fn producer<T: Serialize + DeserializeOwned>(guid: Guid, topic: &str) -> EndpointInfo {
    placed(fixtures::producer::<T>(guid, topic))
}

fn consumer<T: Serialize + DeserializeOwned>(guid: Guid, topic: &str) -> EndpointInfo {
    placed(fixtures::consumer::<T>(guid, topic))
}

fn patterns(list: &[&str]) -> Vec<Pattern> {
    list.iter().map(|p| Pattern::new(p).unwrap()).collect()
}

fn subject(name: &str, n: u8, publish: &[&str], subscribe: &[&str]) -> Subject {
    Subject {
        name: name.to_owned(),
        key: identity(n).public(),
        publish: patterns(publish),
        subscribe: patterns(subscribe),
        own: Vec::new(),
        use_: Vec::new(),
    }
}

fn document(serial: u64, subjects: Vec<Subject>) -> Arc<Permissions> {
    Arc::new(Permissions {
        serial,
        domain: None,
        not_before: 0,
        not_after: u64::MAX,
        subjects,
    })
}

/// The administrator's document: node 0 is `arm` (publishes `arm/*`, reads everything), node 1
/// is `viewer` (only `status/*`). Node 2 holds the domain key but is no subject.
fn official() -> Arc<Permissions> {
    document(
        1,
        vec![
            subject("arm", 0, &["arm/*", "status/*"], &["*"]),
            subject("viewer", 1, &["status/*"], &["status/*"]),
        ],
    )
}

fn guard(n: u8, permissions: Arc<Permissions>) -> impl FnOnce(&mut Engine) {
    move |engine| {
        engine.guard_with(Guard {
            identity: identity(n),
            permissions,
            valid_until: None,
        })
    }
}

/// Nodes 0 and 1 enforce the official document; node 2 enforces one it wrote itself, which
/// lets it do everything.
fn three_nodes() -> SimNet {
    let mut net = SimNet::new(11);
    net.add_node_with(signing(0, 500), guard(0, official()));
    net.add_node_with(signing(1, 501), guard(1, official()));
    let own = document(99, vec![subject("rogue", 2, &["*"], &["*"])]);
    net.add_node_with(signing(2, 502), guard(2, own));
    net
}

/// The configuration of node `n`, whose node id is one of its identity's.
fn signing(n: u8, seed: u64) -> ndds_core::discovery::DiscoveryConfig {
    let mut config = config(usize::from(n), seed, PERIOD, LEASE);
    config.node_id = Some(ndds_core::security::node_id_for(
        &identity(n).public(),
        seed,
    ));
    config
}

/// Arm's producer of `status/arm` (node 0) and the viewer's consumer of it (node 1), declared
/// and matched.
fn status_pair(net: &mut SimNet) -> (EndpointInfo, EndpointInfo) {
    let arm_status = producer::<Pose>(guid(0, 1), "status/arm");
    let reader = consumer::<Pose>(guid(1, 1), "status/arm");
    net.add_local(0, arm_status.clone());
    net.add_local(1, reader.clone());
    net.run_for(Duration::from_secs(2));
    assert_eq!(
        count(
            net,
            1,
            Duration::ZERO,
            matched(reader.guid, arm_status.guid)
        ),
        1
    );
    (arm_status, reader)
}

fn refused(
    local: ndds_core::wire::Guid,
    other: ndds_core::wire::Guid,
    words: &str,
) -> impl Fn(&Event) -> bool {
    move |e| {
        matches!(e, Event::Refused { local: l, remote, reason }
            if *l == local && remote.guid == other && reason.contains(words))
    }
}

#[test]
fn a_subject_matches_what_its_rules_allow_and_both_sides_say_why() {
    let mut net = three_nodes();
    let arm_pose = producer::<Pose>(guid(0, 1), "arm/pose");
    let arm_status = producer::<Pose>(guid(0, 2), "status/arm");
    let arm_cmd_in = consumer::<Pose>(guid(0, 3), "arm/cmd");
    for info in [&arm_pose, &arm_status, &arm_cmd_in] {
        net.add_local(0, info.clone());
    }
    // The viewer's own daemon refuses what the document does not give it, at declaration.
    let viewer_status = consumer::<Pose>(guid(1, 1), "status/arm");
    net.add_local(1, viewer_status.clone());
    let refusal = net
        .try_add_local(1, consumer::<Pose>(guid(1, 2), "arm/pose"))
        .expect_err("viewer may not read arm/pose");
    let text = refusal.to_string();
    assert!(matches!(refusal, LocalError::NotPermitted(_)), "{text}");
    assert!(
        text.contains("`viewer` may not subscribe `arm/pose`")
            && text.contains("subscribe 'status/*'"),
        "{text}"
    );
    assert_eq!(net.engine(1).stats().refused_local, 1);
    // The rogue's document lets it declare anything; the others refuse it.
    let rogue_reader = consumer::<Pose>(guid(2, 1), "arm/pose");
    let rogue_writer = producer::<Pose>(guid(2, 2), "arm/cmd");
    net.add_local(2, rogue_reader.clone());
    net.add_local(2, rogue_writer.clone());
    net.run_for(Duration::from_secs(3));

    assert_eq!(
        count(
            &net,
            1,
            Duration::ZERO,
            matched(viewer_status.guid, arm_status.guid)
        ),
        1
    );
    let not_subject = "is not a subject of permissions document 1";
    assert!(
        first(
            &net,
            0,
            Duration::ZERO,
            refused(arm_pose.guid, rogue_reader.guid, not_subject)
        )
        .is_some()
    );
    assert!(
        first(
            &net,
            0,
            Duration::ZERO,
            refused(arm_cmd_in.guid, rogue_writer.guid, not_subject)
        )
        .is_some()
    );
    // The rogue's document does not name node 0: it refuses node 0's endpoints too.
    assert!(
        first(
            &net,
            2,
            Duration::ZERO,
            refused(rogue_reader.guid, arm_pose.guid, "document 99")
        )
        .is_some()
    );
    for n in 0..3 {
        let matched_with_rogue = net.events_since(n, Duration::ZERO).any(|(_, e)| {
            matches!(e, Event::Matched { local, remote }
                if (local.participant == guid(2, 1).participant) != (remote.guid.participant == guid(2, 1).participant))
        });
        assert!(!matched_with_rogue, "node {n} matched across the rogue");
    }
    assert!(net.engine(0).stats().refused_endpoints >= 2);
    // Every node knows every other and whom it signs as.
    let rogue_id = net.engine(2).node_id();
    let (_, rogue) = net
        .engine(0)
        .nodes()
        .find(|(id, _)| *id == rogue_id)
        .unwrap();
    assert_eq!(rogue.identity, Some(identity(2).public()));
    assert_eq!(
        net.engine(0).subject_of(&identity(1).public()),
        Some("viewer")
    );
    assert_eq!(net.engine(0).subject_of(&identity(2).public()), None);
}

#[test]
fn a_node_is_bound_to_the_identity_it_signs_with() {
    let mut net = three_nodes();
    let arm_pose = producer::<Pose>(guid(0, 1), "arm/pose");
    net.add_local(0, arm_pose.clone());
    net.add_local(1, consumer::<Pose>(guid(1, 1), "status/x"));
    net.run_for(Duration::from_secs(2));
    assert!(net.knows(1, arm_pose.guid));
    let node0 = net.engine(0).node_id();
    let mut bye = Vec::new();
    wire::encode(simnet::DOMAIN, node0, &Message::Bye(Bye {}), &mut bye).unwrap();
    // Unsigned, then signed by another subject of the document, from node 0's own address.
    let by_viewer = signed::wrap(&bye, &identity(1), u64::MAX).unwrap();
    // Node 0's identity with a signature changed in one bit.
    let mut tampered = signed::wrap(&bye, &identity(0), u64::MAX).unwrap();
    tampered[wire::HEADER_LEN + 32 + 32 + 8 + 10] ^= 1;
    for datagram in [&bye, &by_viewer, &tampered] {
        net.inject(1, simnet::locator(0), datagram);
    }
    net.run_for(Duration::from_millis(10));
    assert!(net.knows(1, arm_pose.guid), "a forged Bye removed node 0");
    assert_eq!(net.engine(1).stats().dropped(DropReason::Unverified), 3);
}

#[test]
fn an_unsigned_node_is_not_heard() {
    let mut net = SimNet::new(12);
    net.add_node_with(signing(0, 600), guard(0, official()));
    net.add_node(config(1, 601, PERIOD, LEASE));
    let arm_pose = producer::<Pose>(guid(0, 1), "arm/pose");
    let open_reader = consumer::<Pose>(guid(1, 1), "arm/pose");
    net.add_local(0, arm_pose.clone());
    net.add_local(1, open_reader.clone());
    net.run_for(Duration::from_secs(3));
    let open_id = net.engine(1).node_id();
    assert!(!net.knows_node(0, open_id), "an unsigned node was believed");
    assert!(!net.knows(0, open_reader.guid));
    let stats = net.engine(0).stats();
    assert!(stats.dropped(DropReason::Unverified) >= 3, "{stats:?}");
    assert_eq!(
        stats.dropped(DropReason::Unverified),
        stats.received - stats.accepted
    );
    assert_eq!(
        count(
            &net,
            0,
            Duration::ZERO,
            matched(arm_pose.guid, open_reader.guid)
        ),
        0
    );
    // The open node, which checks nothing, hears the signed one (and could match it: its
    // own business; node 0 never sends it samples).
    assert!(net.knows(1, arm_pose.guid));
}

#[test]
fn a_new_document_and_the_end_of_one_take_effect_at_once() {
    let mut net = three_nodes();
    let arm_pose = producer::<Pose>(guid(0, 1), "arm/pose");
    let rogue_reader = consumer::<Pose>(guid(2, 1), "arm/pose");
    net.add_local(0, arm_pose.clone());
    net.add_local(2, rogue_reader.clone());
    net.run_for(Duration::from_secs(2));
    assert_eq!(
        count(
            &net,
            0,
            Duration::ZERO,
            matched(arm_pose.guid, rogue_reader.guid)
        ),
        0
    );
    // The administrator admits node 2 as `logger`; node 0 installs the new version, which
    // is valid for one more second.
    let mut subjects = official().subjects.clone();
    subjects.push(subject("logger", 2, &[], &["arm/*"]));
    let second = document(2, subjects);
    let now = net.elapsed();
    let until = net.now() + Duration::from_secs(1);
    net.command(0, move |engine| engine.set_permissions(second, Some(until)));
    assert!(first(&net, 0, now, matched(arm_pose.guid, rogue_reader.guid)).is_some());
    assert_eq!(
        net.engine(0).subject_of(&identity(2).public()),
        Some("logger")
    );
    // Its end refuses the pair again.
    net.run_for(Duration::from_secs(2));
    assert!(first(&net, 0, now, unmatched(arm_pose.guid, rogue_reader.guid)).is_some());
    assert!(
        first(
            &net,
            0,
            now,
            refused(arm_pose.guid, rogue_reader.guid, "is not valid now")
        )
        .is_some()
    );
    // A valid document again.
    let later = net.elapsed();
    net.command(0, |engine| engine.set_permissions(official(), None));
    assert!(
        first(
            &net,
            0,
            later,
            refused(arm_pose.guid, rogue_reader.guid, "document 1")
        )
        .is_some()
    );
}

#[test]
fn nobody_takes_a_daemons_node_id_before_it_is_heard() {
    // Index 0 runs with identity 1 (`viewer`); the daemon at index 1 (identity 0, `arm`)
    // starts later.
    let with_identity = |index: usize, n: u8, seed: u64| {
        let mut config = config(index, seed, PERIOD, LEASE);
        config.node_id = Some(ndds_core::security::node_id_for(
            &identity(n).public(),
            seed,
        ));
        config
    };
    let mut net = SimNet::new(13);
    net.add_node_with(with_identity(0, 1, 701), guard(1, official()));
    net.run_for(Duration::from_millis(100));
    // Arm's future id, claimed first by identity 2 (it holds the domain key; it even signs
    // correctly), from arm's address.
    let squatted = ndds_core::security::node_id_for(&identity(0).public(), 700);
    let mut node = net.engine(0).node_info();
    node.unicast = simnet::locator(1);
    let mut solicit = Vec::new();
    wire::encode(
        simnet::DOMAIN,
        squatted,
        &Message::Solicit(wire::Solicit { node }),
        &mut solicit,
    )
    .unwrap();
    let signed = signed::wrap(&solicit, &identity(2), 1).unwrap();
    net.inject(0, simnet::locator(1), &signed);
    assert!(!net.knows_node(0, squatted), "the squatter took the id");
    assert_eq!(net.engine(0).stats().dropped(DropReason::Unverified), 1);
    // Arm then starts with that id, and is heard and matched.
    // (Identity 0 runs at index 1 here, identity 1 at index 0.)
    let mut arm_pose = producer::<Pose>(guid(0, 1), "status/arm");
    arm_pose.locator = simnet::locator(1);
    let mut reader = consumer::<Pose>(guid(1, 1), "status/arm");
    reader.locator = simnet::locator(0);
    net.add_node_with(with_identity(1, 0, 700), guard(0, official()));
    net.add_local(1, arm_pose.clone());
    net.add_local(0, reader.clone());
    net.run_for(Duration::from_secs(2));
    assert!(net.knows_node(0, squatted));
    assert_eq!(
        count(&net, 0, Duration::ZERO, matched(reader.guid, arm_pose.guid)),
        1
    );
}

#[test]
fn nobody_announces_endpoints_of_another_daemons_participants() {
    let mut net = three_nodes();
    let (arm_status, reader) = status_pair(&mut net);
    // Identity 2 (no subject of the official document) announces arm's endpoint, unchanged,
    // as its own node, from arm's address (a forged source address).
    let rogue_node = ndds_core::security::node_id_for(&identity(2).public(), 9);
    let mut node = net.engine(0).node_info();
    node.unicast = simnet::locator(0);
    let mut announce = Vec::new();
    wire::encode(
        simnet::DOMAIN,
        rogue_node,
        &Message::Announce(wire::Announce {
            node,
            endpoints: vec![arm_status.clone()],
            withdrawn: Vec::new(),
        }),
        &mut announce,
    )
    .unwrap();
    let signed = signed::wrap(&announce, &identity(2), 1).unwrap();
    let since = net.elapsed();
    net.inject(1, simnet::locator(0), &signed);
    // The participant is arm's identity's: node 1 ignores the rogue's claim and keeps the pair
    // with arm, keys and all.
    assert!(first(&net, 1, since, unmatched(reader.guid, arm_status.guid)).is_none());
    assert_eq!(net.engine(1).stats().foreign_participants, 1);
    let keys = net.engine(1).data_keys(&reader.guid, &arm_status.guid);
    assert!(keys.is_some());
    net.run_for(Duration::from_secs(3));
    assert_eq!(
        net.engine(1).data_keys(&reader.guid, &arm_status.guid),
        keys,
        "the pair's keys changed"
    );
    // A daemon refuses its own clients' endpoints under ids not its identity's.
    let foreign = producer::<Pose>(guid(1, 9), "status/x");
    let refusal = net
        .try_add_local(0, foreign)
        .expect_err("a foreign participant");
    assert!(
        matches!(refusal, LocalError::ForeignParticipant(p) if p == guid(1, 9).participant),
        "{refusal}"
    );
}

/// The first `upto` signed datagrams node 0 sent while it was recorded, of `kinds`, replayed
/// as a recording host with the domain key would (re-sealed, from node 0's address).
fn replay_recorded(net: &mut SimNet, upto: usize, kinds: &[MessageKind]) -> u64 {
    let recorded: Vec<_> = net.recorded[..upto]
        .iter()
        .filter(|(from, kind, _)| *from == 0 && kinds.contains(kind))
        .map(|(_, _, bytes)| bytes.clone())
        .collect();
    for bytes in &recorded {
        net.inject(1, simnet::locator(0), bytes);
    }
    recorded.len() as u64
}

#[test]
fn recorded_signed_datagrams_are_taken_once_even_after_their_node_is_gone() {
    let mut net = SimNet::new(14);
    net.add_node_with(signing(0, 800), guard(0, official()));
    net.add_node_with(signing(1, 801), guard(1, official()));
    net.record(0);
    let (arm_status, _reader) = status_pair(&mut net);
    net.run_for(Duration::from_secs(1));
    // Arm withdraws its endpoint; its announcements from before, replayed, do not bring it
    // back.
    let announced = net.recorded.len();
    net.remove_locals(0, &[arm_status.guid]);
    net.run_for(Duration::from_secs(1));
    assert!(!net.knows(1, arm_status.guid));
    let replayed = replay_recorded(&mut net, announced, &[MessageKind::Announce]);
    assert!(replayed >= 3, "{replayed} announcements recorded");
    assert!(
        !net.knows(1, arm_status.guid),
        "a withdrawn endpoint came back"
    );
    assert_eq!(
        net.engine(1).stats().dropped(DropReason::Replayed),
        replayed
    );
    // Node 0 goes on being heard (the replays took nothing of its window).
    net.run_for(Duration::from_secs(8));
    let node0 = net.engine(0).node_id();
    assert!(net.knows_node(1, node0), "node 0 was lost");
    // It says Bye; everything it ever sent, replayed, brings back no ghost.
    net.close(0);
    net.run_for(Duration::from_millis(100));
    assert!(!net.knows_node(1, node0));
    let before = net.engine(1).stats().dropped(DropReason::Replayed);
    // (Its withdrawals and its Bye left out: replayed last, they would hide a ghost.)
    let all = [MessageKind::Solicit, MessageKind::Announce];
    let everything = net.recorded.len();
    let replayed = replay_recorded(&mut net, everything, &all);
    assert!(!net.knows_node(1, node0), "a node that said Bye came back");
    assert_eq!(
        net.engine(1).stats().dropped(DropReason::Replayed) - before,
        replayed
    );
}

#[test]
fn a_new_document_judges_local_endpoints_too() {
    let mut net = three_nodes();
    let (arm_status, reader) = status_pair(&mut net);
    // The viewer's daemon installs a document that no longer lets it read `status/*`.
    let narrower = document(
        3,
        vec![
            subject("arm", 0, &["arm/*", "status/*"], &["*"]),
            subject("viewer", 1, &["status/*"], &["other/*"]),
        ],
    );
    let since = net.elapsed();
    net.command(1, move |engine| engine.set_permissions(narrower, None));
    assert!(first(&net, 1, since, unmatched(reader.guid, arm_status.guid)).is_some());
    assert!(
        first(
            &net,
            1,
            since,
            refused(
                reader.guid,
                arm_status.guid,
                "`viewer` may not subscribe `status/arm`"
            )
        )
        .is_some()
    );
    assert_eq!(net.engine(1).stats().refused_local, 1);
    assert!(
        net.engine(1)
            .data_keys(&reader.guid, &arm_status.guid)
            .is_none()
    );
    // Allowed again: matched again, without being declared again.
    let again = net.elapsed();
    net.command(1, |engine| engine.set_permissions(official(), None));
    assert!(first(&net, 1, again, matched(reader.guid, arm_status.guid)).is_some());
    assert!(
        net.engine(1)
            .data_keys(&reader.guid, &arm_status.guid)
            .is_some()
    );
}

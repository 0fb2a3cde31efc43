//! Discovery over a simulated network (see `support/simnet.rs`): matching, late joiners,
//! withdrawals, crashes, restarts, `Bye`, loss, partitions. Every timing assertion is in virtual
//! time, so these tests are exact and replay identically.

#[path = "support/fixtures.rs"]
mod fixtures;
#[path = "support/simnet.rs"]
mod simnet;

use std::collections::BTreeSet;
use std::time::Duration;

use ndds_core::discovery::{DiscoveryConfig, Engine, Event, LossReason, Origin, Via};
use ndds_core::types::TypeDescription;
use ndds_core::wire::{DropReason, Guid, MessageKind};

use fixtures::*;
use simnet::{SimNet, config, locator};

const PERIOD: Duration = Duration::from_secs(1);
const LEASE: Duration = Duration::from_secs(5);
const MS: Duration = Duration::from_millis(1);

/// A network of `n` nodes with the given timers, run until they all know each other.
fn network(seed: u64, n: usize, period: Duration, lease: Duration) -> SimNet {
    let mut net = SimNet::new(seed);
    for i in 0..n {
        net.add_node(config(i, seed * 100 + i as u64, period, lease));
    }
    net.run_for(Duration::from_millis(100));
    for i in 0..n {
        assert_eq!(
            net.engine(i).nodes().count(),
            n - 1,
            "node {i} after start-up"
        );
    }
    net
}

// ----- matching ------------------------------------------------------------------------------

#[test]
fn late_joiner_matches_without_waiting_for_a_refresh() {
    let mut net = network(1, 2, PERIOD, LEASE);
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    let scan_consumer = consumer::<Scan>(guid(1, 1), "lidar/scan");
    net.add_local(0, pose_producer.clone());
    net.add_local(1, scan_consumer.clone());
    net.run_for(Duration::from_millis(3450));

    let joined = net.elapsed();
    let late = net.add_node(config(2, 7, PERIOD, LEASE));
    let pose_consumer = consumer::<Pose>(guid(2, 1), "arm/pose");
    let scan_producer = producer::<Scan>(guid(2, 2), "lidar/scan");
    net.add_local(late, pose_consumer.clone());
    net.add_local(late, scan_producer.clone());
    net.run_for(Duration::from_millis(100));

    // The refresh period is 1 s; the late joiner knows everything within the reply jitter
    // (10 ms) plus latency, on both sides of both topics.
    let deadline = joined + Duration::from_millis(20);
    for (n, local, other) in [
        (late, pose_consumer.guid, pose_producer.guid),
        (late, scan_producer.guid, scan_consumer.guid),
        (0, pose_producer.guid, pose_consumer.guid),
        (1, scan_consumer.guid, scan_producer.guid),
    ] {
        let at = first(&net, n, joined, matched(local, other));
        assert!(
            at.is_some_and(|t| t <= deadline),
            "node {n}: {local} ~ {other} at {at:?}"
        );
    }
    assert_eq!(net.engine(late).endpoints().count(), 4);
    assert!(net.knows_node(late, net.engine(0).node_id()));
    assert!(net.knows_node(late, net.engine(1).node_id()));
    // What the late joiner learnt of node 0 came by unicast: the answer to its Solicit.
    let first_announce = net
        .deliveries
        .iter()
        .find(|d| d.at >= joined && d.from == 0 && d.to == late && d.kind == MessageKind::Announce)
        .unwrap();
    assert!(first_announce.unicast, "{first_announce:?}");
    assert!(first_announce.at <= deadline);
}

#[test]
fn a_burst_of_declarations_is_announced_in_a_datagram_per_hold() {
    let mut net = network(21, 2, PERIOD, LEASE);
    net.run_for(Duration::from_millis(1500));
    net.record(0);
    let since = net.elapsed();
    // A program declaring its endpoints one by one, 200 µs apart (its daemon's answer each
    // time), 2 ms in all.
    let producers: Vec<_> = (1..=10)
        .map(|entity| producer::<Pose>(guid(0, entity), &format!("arm/joint{entity}")))
        .collect();
    for info in &producers {
        net.add_local(0, info.clone());
        net.run_for(Duration::from_micros(200));
    }
    net.run_for(Duration::from_millis(20));
    let hold = DiscoveryConfig::new(0, locator(0)).declare_coalesce;
    // The first went at once, the other nine together when the hold ended.
    let announces: Vec<_> = net
        .deliveries
        .iter()
        .filter(|d| d.at >= since && d.from == 0 && d.kind == MessageKind::Announce)
        .map(|d| d.at - since)
        .collect();
    assert_eq!(announces.len(), 2, "{announces:?}");
    assert!(announces[0] <= 2 * MS, "{announces:?}");
    assert!(announces[1] <= hold + 2 * MS, "{announces:?}");
    for info in &producers {
        assert!(net.knows(1, info.guid), "{} not known", info.guid);
    }
    // A declaration alone, after the hold, goes at once.
    net.run_for(Duration::from_millis(100));
    let alone = producer::<Pose>(guid(0, 11), "arm/gripper");
    net.add_local(0, alone.clone());
    net.run_for(2 * MS);
    assert!(net.knows(1, alone.guid), "a single declaration waited");
}

#[test]
fn local_endpoint_matches_on_both_nodes_and_locally() {
    let mut net = network(2, 2, PERIOD, LEASE);
    let t0 = net.elapsed();
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    let local_consumer = consumer::<Pose>(guid(0, 2), "arm/pose");
    let remote_consumer = consumer::<Pose>(guid(1, 1), "arm/pose");
    let unrelated = consumer::<Pose>(guid(1, 2), "arm/other");
    net.add_local(0, pose_producer.clone());
    net.add_local(0, local_consumer.clone());
    net.add_local(1, remote_consumer.clone());
    net.add_local(1, unrelated.clone());
    net.run_for(Duration::from_millis(10));

    let on_a = matches_since(&net, 0, t0);
    let expected_a = BTreeSet::from([
        (pose_producer.guid, local_consumer.guid),
        (local_consumer.guid, pose_producer.guid),
        (pose_producer.guid, remote_consumer.guid),
    ]);
    assert_eq!(on_a, expected_a);
    let on_b = matches_since(&net, 1, t0);
    assert_eq!(
        on_b,
        BTreeSet::from([(remote_consumer.guid, pose_producer.guid)])
    );

    // The match carries the other side's declaration as declared.
    let remote_seen_by_b = net.events_since(1, t0).find_map(|(_, e)| match e {
        Event::Matched { remote, .. } => Some(remote.clone()),
        _ => None,
    });
    assert_eq!(remote_seen_by_b, Some(pose_producer.clone()));
    assert_eq!(
        net.engine(1)
            .endpoint(&pose_producer.guid)
            .map(|e| e.origin),
        Some(Origin::Remote(net.engine(0).node_id()))
    );
    assert_eq!(
        net.engine(0)
            .endpoint(&pose_producer.guid)
            .map(|e| e.origin),
        Some(Origin::Local)
    );
    assert!(net.knows(0, unrelated.guid));

    // Refreshes change nothing.
    net.run_for(3 * PERIOD);
    assert_eq!(matches_since(&net, 0, t0), expected_a);
    assert_eq!(matches_since(&net, 1, t0).len(), 1);
}

#[test]
fn of_two_local_endpoints_the_consumer_hears_of_the_pair_first() {
    // A producer may write the moment it hears of a consumer; the consumer, told first,
    // already holds the pair's data keys where a domain has permissions.
    for producer_first in [true, false] {
        let mut net = network(3, 1, PERIOD, LEASE);
        let t0 = net.elapsed();
        let writer = producer::<Pose>(guid(0, 1), "arm/pose");
        let reader = consumer::<Pose>(guid(0, 2), "arm/pose");
        let order = if producer_first {
            [writer.clone(), reader.clone()]
        } else {
            [reader.clone(), writer.clone()]
        };
        for info in order {
            net.add_local(0, info);
        }
        net.run_for(Duration::from_millis(10));
        let told: Vec<Guid> = net
            .events_since(0, t0)
            .filter_map(|(_, e)| match e {
                Event::Matched { local, .. } => Some(*local),
                _ => None,
            })
            .collect();
        assert_eq!(
            told,
            [reader.guid, writer.guid],
            "declared producer first: {producer_first}"
        );
    }
}

#[test]
fn different_fingerprints_are_incompatible_on_both_sides() {
    let mut net = network(3, 2, PERIOD, LEASE);
    let t0 = net.elapsed();
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    let local_v2 = consumer::<PoseV2>(guid(0, 2), "arm/pose");
    let remote_v2 = consumer::<PoseV2>(guid(1, 1), "arm/pose");
    assert_ne!(pose_producer.fingerprint, remote_v2.fingerprint);
    net.add_local(0, pose_producer.clone());
    net.add_local(0, local_v2.clone());
    net.add_local(1, remote_v2.clone());
    net.run_for(Duration::from_millis(10));

    for (n, local, other) in [
        (0, pose_producer.guid, local_v2.guid),
        (0, local_v2.guid, pose_producer.guid),
        (0, pose_producer.guid, remote_v2.guid),
        (1, remote_v2.guid, pose_producer.guid),
    ] {
        assert_eq!(
            count(&net, n, t0, incompatible(local, other)),
            1,
            "node {n}"
        );
    }
    for n in 0..2 {
        assert_eq!(
            count(&net, n, t0, |e| matches!(e, Event::Matched { .. })),
            0
        );
    }

    // A compatible consumer on the same topic still matches, unaffected.
    let t1 = net.elapsed();
    let remote_v1 = consumer::<Pose>(guid(1, 2), "arm/pose");
    net.add_local(1, remote_v1.clone());
    net.run_for(Duration::from_millis(10));
    assert!(first(&net, 1, t1, matched(remote_v1.guid, pose_producer.guid)).is_some());
    assert!(first(&net, 0, t1, matched(pose_producer.guid, remote_v1.guid)).is_some());
    assert_eq!(
        count(&net, 1, t1, |e| matches!(e, Event::Incompatible { .. })),
        0
    );

    // Incompatible pairs are also ended by Unmatched when one side goes away.
    let t2 = net.elapsed();
    net.remove_locals(0, &[pose_producer.guid]);
    net.run_for(Duration::from_millis(10));
    assert!(first(&net, 1, t2, unmatched(remote_v2.guid, pose_producer.guid)).is_some());
    assert!(first(&net, 0, t2, unmatched(local_v2.guid, pose_producer.guid)).is_some());
}

// ----- withdrawal, Bye, expiry ---------------------------------------------------------------

#[test]
fn removed_endpoints_are_unmatched_at_once_everywhere() {
    let mut net = network(4, 2, PERIOD, LEASE);
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    let pose_consumer = consumer::<Pose>(guid(1, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    net.add_local(1, pose_consumer.clone());
    net.run_for(Duration::from_millis(2500));
    assert!(net.knows(1, pose_producer.guid));

    let t = net.elapsed();
    net.remove_locals(0, &[pose_producer.guid]);
    net.run_for(Duration::from_millis(10));
    let at_b = first(
        &net,
        1,
        t,
        unmatched(pose_consumer.guid, pose_producer.guid),
    );
    assert_eq!(at_b, Some(t + MS), "one latency after the removal");
    assert_eq!(
        first(
            &net,
            0,
            t,
            unmatched(pose_producer.guid, pose_consumer.guid)
        ),
        Some(t)
    );
    assert!(!net.knows(1, pose_producer.guid));

    // The node itself is still there, and the endpoint never comes back.
    net.run_for(2 * LEASE);
    assert!(net.knows_node(1, net.engine(0).node_id()));
    assert_eq!(
        count(&net, 1, t, matched(pose_consumer.guid, pose_producer.guid)),
        0
    );
    assert_eq!(count(&net, 1, t, any_unmatched), 1);
}

#[test]
fn a_lost_withdraw_is_healed_by_the_next_announcement() {
    let mut net = network(5, 2, PERIOD, LEASE);
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    let pose_consumer = consumer::<Pose>(guid(1, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    net.add_local(1, pose_consumer.clone());
    net.run_for(Duration::from_millis(2500));

    let t = net.elapsed();
    net.set_link_loss(0, 1, 1.0);
    net.remove_locals(0, &[pose_producer.guid]);
    net.set_link_loss(0, 1, 0.0);
    net.run_for(2 * PERIOD);
    let at = first(
        &net,
        1,
        t,
        unmatched(pose_consumer.guid, pose_producer.guid),
    )
    .unwrap();
    // Not at once (the Withdraw was lost), but by the next refresh, long before the lease.
    assert!(at > t + MS && at <= t + PERIOD.mul_f64(1.1) + MS, "{at:?}");
    assert!(!net.knows(1, pose_producer.guid));
}

#[test]
fn a_crashed_node_is_forgotten_after_its_lease() {
    let period = Duration::from_millis(500);
    let lease = Duration::from_secs(3);
    let mut net = network(6, 2, period, lease);
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    let pose_consumer = consumer::<Pose>(guid(1, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    net.add_local(1, pose_consumer.clone());
    net.run_for(Duration::from_secs(4));

    let crashed_id = net.engine(0).node_id();
    let t = net.elapsed();
    net.crash(0);
    let last_heard = net
        .deliveries
        .iter()
        .rev()
        .find(|d| d.from == 0)
        .unwrap()
        .at;
    assert!(
        last_heard + period.mul_f64(1.1) >= t,
        "refreshes were regular"
    );

    // Not before: present at every step until the earliest possible end of the lease.
    let earliest_end = t + lease - period.mul_f64(1.1);
    net.run_for_checked(earliest_end - t - MS, |net| {
        assert!(
            net.knows(1, pose_producer.guid),
            "forgotten early at {:?}",
            net.elapsed()
        );
        assert!(net.knows_node(1, crashed_id));
    });
    // Not much after: gone exactly when the lease of the last datagram ends.
    net.run_for(lease + period - (net.elapsed() - t));
    let expired = last_heard + lease;
    assert_eq!(
        first(&net, 1, t, lost(crashed_id, LossReason::Expired)),
        Some(expired)
    );
    assert_eq!(
        first(
            &net,
            1,
            t,
            unmatched(pose_consumer.guid, pose_producer.guid)
        ),
        Some(expired)
    );
    assert!(!net.knows(1, pose_producer.guid));
    assert!(!net.knows_node(1, crashed_id));
    assert_eq!(net.engine(1).endpoints().count(), 1);
}

#[test]
fn a_restarted_node_is_discovered_and_matched_again() {
    let lease = Duration::from_secs(3);
    let mut net = network(7, 2, PERIOD, lease);
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    let pose_consumer = consumer::<Pose>(guid(1, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    net.add_local(1, pose_consumer.clone());
    net.run_for(Duration::from_secs(2));
    let old_id = net.engine(0).node_id();
    let t = net.elapsed();
    net.crash(0);
    net.run_for(lease + PERIOD);
    assert!(first(&net, 1, t, lost(old_id, LossReason::Expired)).is_some());

    let restarted = net.elapsed();
    net.restart(0, 7777);
    let new_id = net.engine(0).node_id();
    assert_ne!(new_id, old_id);
    net.add_local(0, pose_producer.clone());
    net.run_for(Duration::from_millis(50));

    let discovered = first(
        &net,
        1,
        restarted,
        |e| matches!(e, Event::NodeDiscovered { node, .. } if *node == new_id),
    );
    assert_eq!(discovered, Some(restarted + MS));
    assert_eq!(
        first(
            &net,
            1,
            restarted,
            matched(pose_consumer.guid, pose_producer.guid)
        ),
        Some(restarted + MS)
    );
    // The restarted node learns of the consumer from the answer to its Solicit.
    let at = first(
        &net,
        0,
        restarted,
        matched(pose_producer.guid, pose_consumer.guid),
    );
    assert!(
        at.is_some_and(|t| t <= restarted + Duration::from_millis(20)),
        "{at:?}"
    );
    assert!(net.knows_node(0, net.engine(1).node_id()));
}

#[test]
fn a_quickly_restarted_node_takes_over_its_endpoints_without_a_flap() {
    let mut net = network(8, 2, PERIOD, LEASE);
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    let pose_consumer = consumer::<Pose>(guid(1, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    net.add_local(1, pose_consumer.clone());
    net.run_for(Duration::from_secs(2));

    // kill -9 and restart at once; the client reconnects and re-declares its producer.
    let t = net.elapsed();
    net.crash(0);
    net.restart(0, 8888);
    net.add_local(0, pose_producer.clone());
    let new_id = net.engine(0).node_id();
    net.run_for(2 * LEASE);

    assert!(net.knows(1, pose_producer.guid));
    assert_eq!(
        net.engine(1)
            .endpoint(&pose_producer.guid)
            .map(|e| e.origin),
        Some(Origin::Remote(new_id))
    );
    assert_eq!(
        count(&net, 1, t, any_unmatched),
        0,
        "the flow was interrupted"
    );
    assert_eq!(net.engine(1).stats().invalid_endpoints, 0);
}

#[test]
fn bye_removes_a_node_everywhere_at_once() {
    let mut net = network(9, 3, PERIOD, LEASE);
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    for n in 1..3 {
        net.add_local(n, consumer::<Pose>(guid(n, 1), "arm/pose"));
    }
    net.run_for(Duration::from_millis(1500));
    let leaving = net.engine(0).node_id();

    let t = net.elapsed();
    net.close(0);
    net.run_for(Duration::from_millis(10));
    for n in 1..3 {
        assert_eq!(
            first(&net, n, t, lost(leaving, LossReason::Bye)),
            Some(t + MS)
        );
        assert_eq!(
            first(&net, n, t, unmatched(guid(n, 1), pose_producer.guid)),
            Some(t + MS)
        );
        assert!(!net.knows(n, pose_producer.guid));
        assert!(!net.knows_node(n, leaving));
        assert_eq!(net.engine(n).nodes().count(), 1);
    }

    // A closed engine is silent: it never comes back.
    net.run_for(2 * LEASE);
    for n in 1..3 {
        assert_eq!(
            net.events_since(n, t).count(),
            2,
            "NodeLost and Unmatched only"
        );
        assert!(!net.knows_node(n, leaving));
    }
}

// ----- loss and partitions -----------------------------------------------------------------

#[test]
fn lossy_network_converges_and_never_drops_a_live_endpoint() {
    // 30 % loss on every link. A live endpoint is dropped only when every refresh of one link
    // within a lease is lost: with a lease of 5 periods that is 4 or 5 losses in a row, and the
    // simulator measures about 3e-3 spurious expiries per link and period (3.5 expected in this
    // run of 20 links × 60 periods). With 10 periods it is about 1e-5 (1 % per run), so that is
    // the lease this test holds to "never".
    let lease = 10 * PERIOD;
    let nodes = 5;
    let all: Vec<usize> = (0..nodes).collect();
    let mut net = SimNet::new(10);
    net.set_loss(0.3);
    for n in 0..nodes {
        net.add_node(config(n, 1000 + n as u64, PERIOD, lease));
    }
    shared_topic(&mut net, nodes);

    let converged = net.run_until(3 * lease, |net| {
        (0..nodes).all(|n| {
            sees_all(net, n, &all)
                && net.engine(n).nodes().count() == nodes - 1
                && match_set(net, n) == full_match_set(n, &all)
        })
    });
    assert!(
        converged.is_some_and(|t| t <= lease),
        "converged at {converged:?}"
    );

    net.run_for_checked(60 * PERIOD, |net| {
        for n in 0..nodes {
            assert!(
                sees_all(net, n, &all),
                "node {n} lost an endpoint at {:?}",
                net.elapsed()
            );
        }
    });
    for n in 0..nodes {
        assert_eq!(count(&net, n, Duration::ZERO, any_unmatched), 0);
        assert_eq!(
            count(&net, n, Duration::ZERO, |e| matches!(
                e,
                Event::NodeLost { .. }
            )),
            0
        );
        assert_eq!(match_set(&net, n), full_match_set(n, &all));
    }
}

#[test]
fn partition_decays_after_the_lease_and_heals() {
    let nodes = 4;
    let all = [0, 1, 2, 3];
    let groups = [[0, 1], [2, 3]];
    let mut net = network(11, nodes, PERIOD, LEASE);
    shared_topic(&mut net, nodes);
    net.run_for(Duration::from_millis(2500));
    for n in 0..nodes {
        assert_eq!(match_set(&net, n), full_match_set(n, &all));
    }

    let t = net.elapsed();
    net.partition(&groups[0], &groups[1]);
    // Not before the lease: every endpoint stays while the other side may still be alive.
    let earliest_end = t + LEASE - PERIOD.mul_f64(1.1);
    net.run_for_checked(earliest_end - t - MS, |net| {
        for n in 0..nodes {
            assert!(sees_all(net, n, &all), "node {n} at {:?}", net.elapsed());
        }
    });
    // By the lease: only the own side is left, each far node lost by expiry.
    net.run_for(LEASE + MS - (net.elapsed() - t));
    for (side, other) in [(groups[0], groups[1]), (groups[1], groups[0])] {
        for n in side {
            assert!(sees_all(&net, n, &side), "node {n}");
            assert_eq!(match_set(&net, n), full_match_set(n, &side));
            for m in other {
                let id = net.engine(m).node_id();
                let at = first(&net, n, t, lost(id, LossReason::Expired));
                assert!(
                    at.is_some_and(|at| at >= earliest_end),
                    "{n} lost {m} at {at:?}"
                );
            }
            // Pairs inside one side were never interrupted.
            for (_, e) in net.events_since(n, Duration::ZERO) {
                if let Event::Unmatched { remote, .. } = e {
                    assert!(
                        other
                            .iter()
                            .any(|&m| *remote == guid(m, 1) || *remote == guid(m, 2))
                    );
                }
            }
        }
    }

    // Healing: the next refreshes rediscover the far side, whose answer completes the view.
    let healed = net.elapsed();
    net.heal();
    let rejoined = net.run_until(3 * PERIOD, |net| {
        (0..nodes).all(|n| sees_all(net, n, &all) && match_set(net, n) == full_match_set(n, &all))
    });
    assert!(
        rejoined.is_some_and(|at| at <= healed + PERIOD.mul_f64(1.1) + Duration::from_millis(20)),
        "healed at {healed:?}, rejoined at {rejoined:?}"
    );
}

#[test]
fn isolated_node_is_forgotten_and_forgets_everyone() {
    let mut net = network(12, 3, PERIOD, LEASE);
    shared_topic(&mut net, 3);
    net.run_for(Duration::from_secs(2));
    let t = net.elapsed();
    net.isolate(2);
    net.run_for(LEASE + PERIOD);
    assert!(sees_all(&net, 2, &[2]));
    assert_eq!(net.engine(2).nodes().count(), 0);
    for n in 0..2 {
        assert!(sees_all(&net, n, &[0, 1]));
        let id = net.engine(2).node_id();
        assert!(first(&net, n, t, lost(id, LossReason::Expired)).is_some());
    }
}

// ----- robustness of the engine's bookkeeping ----------------------------------------------

#[test]
fn own_and_foreign_domain_datagrams_are_counted_and_ignored() {
    let start = std::time::Instant::now();
    let mut engine = Engine::new(config(0, 1, PERIOD, LEASE), start).unwrap();
    engine
        .add_local(start, producer::<Pose>(guid(0, 1), "arm/pose"))
        .unwrap();
    engine.handle_timeout(start);
    let own: Vec<Vec<u8>> = std::iter::from_fn(|| engine.poll_transmit())
        .map(|t| t.payload.to_vec())
        .collect();
    assert!(own.len() >= 2, "announcement and solicit");
    while engine.poll_event().is_some() {}

    let from = "10.0.0.1:7400".parse().unwrap();
    for bytes in &own {
        engine.handle_datagram(start, from, Via::Multicast, bytes);
    }
    // The same datagrams from a node of another domain.
    let mut other =
        Engine::new(DiscoveryConfig::new(simnet::DOMAIN + 1, locator(1)), start).unwrap();
    other
        .add_local(start, producer::<Pose>(guid(1, 1), "arm/pose"))
        .unwrap();
    let foreign = other.poll_transmit().unwrap().payload;
    engine.handle_datagram(start, from, Via::Multicast, &foreign);

    let stats = engine.stats();
    assert_eq!(stats.dropped(DropReason::Own), own.len() as u64);
    assert_eq!(stats.dropped(DropReason::OtherDomain), 1);
    assert_eq!(stats.accepted, 0);
    assert_eq!(engine.poll_event(), None);
    assert_eq!(engine.nodes().count(), 0);
    assert_eq!(engine.endpoints().count(), 1);
}

#[test]
fn same_seeds_replay_exactly() {
    let run = || {
        let mut net = SimNet::new(13);
        net.set_loss(0.3);
        net.set_latency(Duration::from_millis(3));
        for n in 0..3 {
            net.add_node(config(n, 50 + n as u64, PERIOD, LEASE));
        }
        shared_topic(&mut net, 3);
        net.run_for(10 * PERIOD);
        (0..3)
            .map(|n| net.node(n).events.clone())
            .collect::<Vec<_>>()
    };
    let first_run = run();
    // At least two NodeDiscovered and six Matched per node.
    assert!(first_run.iter().all(|events| events.len() >= 8));
    assert_eq!(first_run, run());
}

#[test]
fn a_redeclared_endpoint_does_not_flap() {
    let mut net = network(14, 2, PERIOD, LEASE);
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    let pose_consumer = consumer::<Pose>(guid(1, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    net.add_local(1, pose_consumer.clone());
    net.run_for(Duration::from_millis(1500));

    let t = net.elapsed();
    net.remove_locals(0, &[pose_producer.guid]);
    net.run_for(Duration::from_millis(100));
    net.add_local(0, pose_producer.clone());
    net.run_for(5 * PERIOD);
    let pair = (pose_consumer.guid, pose_producer.guid);
    assert_eq!(count(&net, 1, t, unmatched(pair.0, pair.1)), 1);
    assert_eq!(count(&net, 1, t, matched(pair.0, pair.1)), 1);
    assert!(net.knows(1, pose_producer.guid));
}

#[test]
fn a_burst_of_withdrawals_does_not_silence_announcements() {
    // Lease 3 periods: three silent refreshes are enough to expire the producer at node 1.
    let lease = 3 * PERIOD;
    let mut net = SimNet::new(15);
    for n in 0..2 {
        net.add_node(config(n, 1500 + n as u64, PERIOD, lease));
    }
    let pose_producer = producer::<Pose>(guid(0, 1), "arm/pose");
    net.add_local(0, pose_producer.clone());
    net.add_local(1, consumer::<Pose>(guid(1, 1), "arm/pose"));
    // 7000 endpoints of clients with 64-bit participant ids come and go: 11 bytes per guid
    // in the `withdrawn` list, 77 kB in all.
    let template = consumer::<Scan>(guid(0, 2), "bulk");
    let bulk: Vec<Guid> = (0..7000u64)
        .map(|i| Guid {
            participant: u64::MAX - i,
            entity: 1,
        })
        .collect();
    for (i, g) in bulk.iter().enumerate() {
        let mut info = template.clone();
        info.guid = *g;
        info.topic = format!("bulk/{i}");
        net.add_local(0, info);
    }
    net.run_for(Duration::from_millis(500));
    let t = net.elapsed();
    net.remove_locals(0, &bulk);
    net.run_for(Duration::from_millis(50));

    let joined = net.elapsed();
    let late = net.add_node(config(2, 1502, PERIOD, lease));
    let late_consumer = consumer::<Pose>(guid(2, 1), "arm/pose");
    net.add_local(late, late_consumer.clone());
    net.run_for(5 * PERIOD);

    let at = first(
        &net,
        late,
        joined,
        matched(late_consumer.guid, pose_producer.guid),
    );
    assert!(
        at.is_some_and(|at| at <= joined + Duration::from_millis(20)),
        "late joiner matched at {at:?}"
    );
    assert_eq!(
        count(&net, 1, t, any_unmatched),
        0,
        "node 1 lost the producer"
    );
}

#[test]
fn a_near_datagram_sized_endpoint_and_pending_withdrawals_still_refresh() {
    use ndds_core::types::{Container, ContainerShape, Field, Format, TypeLayout};
    // A struct of 2300 fields: one endpoint of about 62 kB, close to the datagram limit.
    let fields = (0..2300)
        .map(|i| Field {
            name: format!("field_{i:05}_padding_bytes"),
            format: 0,
        })
        .collect();
    let layout = TypeLayout {
        formats: vec![Format::U8, Format::Named(0)],
        root: 1,
        containers: vec![Container {
            name: "Wide".to_owned(),
            shape: ContainerShape::Struct(fields),
        }],
    };
    let mut wide = producer::<Pose>(guid(0, 1), "wide");
    wide.type_desc = TypeDescription {
        name: "Wide".to_owned(),
        layout: Some(layout),
    };
    wide.fingerprint = wide.type_desc.fingerprint();
    assert!(postcard::to_allocvec(&wide).unwrap().len() > 60_000);

    let lease = 3 * PERIOD;
    let mut net = SimNet::new(16);
    for n in 0..2 {
        net.add_node(config(n, 1600 + n as u64, PERIOD, lease));
    }
    net.add_local(0, wide.clone());
    let reader = consumer::<Pose>(guid(1, 1), "wide");
    let mut reader = reader;
    reader.type_desc = wide.type_desc.clone();
    reader.fingerprint = wide.fingerprint;
    net.add_local(1, reader.clone());
    // 1000 short-lived endpoints leave 1000 guids on the withdrawal list (about 11 kB).
    let bulk: Vec<Guid> = (0..1000u64)
        .map(|i| Guid {
            participant: u64::MAX - i,
            entity: 1,
        })
        .collect();
    for g in &bulk {
        net.add_local(0, consumer::<Scan>(*g, "bulk"));
    }
    net.run_for(Duration::from_millis(300));
    let t = net.elapsed();
    net.remove_locals(0, &bulk);
    net.run_for(4 * lease);
    // Refreshes kept arriving: the wide producer never decayed at node 1.
    assert_eq!(count(&net, 1, t, unmatched(reader.guid, wide.guid)), 0);
    assert!(net.knows(1, wide.guid));
    assert!(bulk.iter().all(|g| !net.knows(1, *g)));
}

#[test]
fn forged_nodes_announcing_an_hour_long_lease_are_forgotten_within_a_minute() {
    // 500 Solicits from made-up nodes, each asking to be remembered for an hour: they are
    // kept for MAX_LEASE (60 s) at most, so a flood of them cannot hold the node table.
    use ndds_core::discovery::engine::MAX_LEASE;
    use ndds_core::wire::{Locator, Message, NodeInfo, Solicit};
    let mut net = network(21, 2, PERIOD, LEASE);
    for forged in 0..500u64 {
        let node = NodeInfo {
            hostname: "forged".into(),
            pid: 1,
            unicast: Locator {
                addr: [10, 9, 0, 1],
                port: 9000 + forged as u16,
            },
            lease_ms: 3_600_000,
            announce_period_ms: 1000,
            version: "0".into(),
        };
        let mut datagram = Vec::new();
        ndds_core::wire::encode(
            simnet::DOMAIN,
            0xf000 + forged,
            &Message::Solicit(Solicit { node }),
            &mut datagram,
        )
        .unwrap();
        net.inject(1, locator(0), &datagram);
    }
    assert_eq!(
        net.engine(1).nodes().count(),
        501,
        "the genuine node and the forged ones"
    );
    net.run_for(MAX_LEASE + MS * 10);
    assert_eq!(MAX_LEASE, Duration::from_secs(60));
    assert_eq!(
        net.engine(1).nodes().count(),
        1,
        "only the genuine node is left"
    );
    assert!(net.knows_node(1, net.engine(0).node_id()));
}

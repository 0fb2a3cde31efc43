//! Discovery without multicast, and mixed with it, over the simulated network: static peer
//! lists, nodes only unicast can reach, one-sided peer lists, and multicast that stops working
//! between nodes that know each other. Every timing assertion is in virtual time.

#[path = "support/fixtures.rs"]
mod fixtures;
#[path = "support/simnet.rs"]
mod simnet;

use std::time::Duration;

use ndds_core::discovery::{Event, LossReason};
use ndds_core::wire::MessageKind;

use fixtures::*;
use simnet::{Delivery, SimNet, config, with_peers};

const PERIOD: Duration = Duration::from_secs(1);
const LEASE: Duration = Duration::from_secs(5);
const MS: Duration = Duration::from_millis(1);
/// Reply jitter (10 ms) plus latency, with room: how fast a newcomer learns the domain.
const PROMPT: Duration = Duration::from_millis(20);

/// Node `i` of `n`, with multicast on or off and the peers `peers(i)`.
fn build(
    seed: u64,
    n: usize,
    multicast: impl Fn(usize) -> bool,
    peers: impl Fn(usize) -> Vec<usize>,
) -> SimNet {
    let mut net = SimNet::new(seed);
    for i in 0..n {
        let base = config(i, seed * 100 + i as u64, PERIOD, LEASE);
        net.add_node(with_peers(base, multicast(i), &peers(i)));
    }
    net
}

fn everyone(n: usize) -> Vec<usize> {
    (0..n).collect()
}

/// Asserts at every step of `duration` that every node of `nodes` sees every endpoint of
/// `nodes` and has every match, and that nobody lost a node meanwhile.
fn stays_whole(net: &mut SimNet, nodes: &[usize], duration: Duration) {
    let since = net.elapsed();
    net.run_for_checked(duration, |net| {
        for &n in nodes {
            assert!(
                sees_all(net, n, nodes) && match_set(net, n) == full_match_set(n, nodes),
                "node {n} lost sight of someone at {:?}",
                net.elapsed()
            );
        }
    });
    for &n in nodes {
        let lost_any = count(net, n, since, |e| matches!(e, Event::NodeLost { .. }));
        assert_eq!(lost_any, 0, "node {n} lost a node");
        assert_eq!(count(net, n, since, any_unmatched), 0, "node {n} flapped");
    }
}

/// Deliveries of `kind` from `from` to `to` since `since`, by (multicast, unicast).
fn deliveries(
    net: &SimNet,
    since: Duration,
    kind: MessageKind,
    from: usize,
    to: usize,
) -> (usize, usize) {
    let of: Vec<&Delivery> = net
        .deliveries
        .iter()
        .filter(|d| d.at >= since && d.kind == kind && d.from == from && d.to == to)
        .collect();
    let unicast = of.iter().filter(|d| d.unicast).count();
    (of.len() - unicast, unicast)
}

/// The last refresh (`Solicit` or `Announce`) that `to` received from `from`.
fn last_refresh(net: &SimNet, from: usize, to: usize) -> Duration {
    net.deliveries
        .iter()
        .rev()
        .find(|d| {
            d.from == from
                && d.to == to
                && matches!(d.kind, MessageKind::Announce | MessageKind::Solicit)
        })
        .expect("refreshes arrived")
        .at
}

/// The whole life of a 4-node domain: start-up, steady state, a withdrawal, a crash and a
/// `Bye`, with the same bounds whatever carries discovery.
fn lifecycle(mut net: SimNet) {
    let n = 4;
    let all = everyone(n);
    shared_topic(&mut net, n);
    let converged = net.run_until(PERIOD, |net| {
        (0..n).all(|i| sees_all(net, i, &all) && match_set(net, i) == full_match_set(i, &all))
    });
    assert!(
        converged.is_some_and(|at| at <= PROMPT),
        "converged at {converged:?}"
    );
    stays_whole(&mut net, &all, 3 * LEASE);

    // A withdrawal reaches everyone at once.
    let t = net.elapsed();
    net.remove_locals(0, &[guid(0, 1)]);
    net.run_for(Duration::from_millis(10));
    for i in 1..n {
        assert_eq!(
            first(&net, i, t, unmatched(guid(i, 2), guid(0, 1))),
            Some(t + MS),
            "node {i}"
        );
    }

    // A crashed node is forgotten exactly one lease after its last refresh.
    let crashed = net.engine(3).node_id();
    let t = net.elapsed();
    net.crash(3);
    net.run_for(LEASE + PERIOD);
    for i in 0..3 {
        let expired = last_refresh(&net, 3, i) + LEASE;
        assert!(expired + PERIOD.mul_f64(1.1) >= t + LEASE, "node {i}");
        assert_eq!(
            first(&net, i, t, lost(crashed, LossReason::Expired)),
            Some(expired),
            "node {i}"
        );
    }

    // A `Bye` is heard by everyone at once.
    let leaving = net.engine(2).node_id();
    let t = net.elapsed();
    net.close(2);
    net.run_for(Duration::from_millis(10));
    for i in 0..2 {
        assert_eq!(
            first(&net, i, t, lost(leaving, LossReason::Bye)),
            Some(t + MS)
        );
    }
}

#[test]
fn multicast_domain_lifecycle() {
    lifecycle(build(21, 4, |_| true, |_| Vec::new()));
}

#[test]
fn without_multicast_full_peer_lists_behave_like_multicast() {
    // Each node lists everyone, itself included, as one shared config file would.
    let net = build(22, 4, |_| false, |_| everyone(4));
    lifecycle(net);
}

#[test]
fn without_multicast_nothing_reaches_the_group() {
    let mut net = build(23, 3, |_| false, |_| everyone(3));
    shared_topic(&mut net, 3);
    net.run_for(2 * LEASE);
    net.remove_locals(1, &[guid(1, 1)]);
    net.close(0);
    net.run_for(LEASE);
    // SimNet fails any multicast transmit of a node with multicast off; none was delivered.
    assert!(!net.deliveries.is_empty());
    assert!(net.deliveries.iter().all(|d| d.unicast));
    for kind in [
        MessageKind::Solicit,
        MessageKind::Announce,
        MessageKind::Withdraw,
        MessageKind::Bye,
    ] {
        assert!(
            net.deliveries.iter().any(|d| d.kind == kind),
            "{kind:?} travelled by unicast"
        );
    }
}

#[test]
fn a_node_only_unicast_reaches_joins_a_multicast_domain() {
    // Nodes 0-2 use multicast and list nobody; node 3 has no multicast and lists them.
    let n = 4;
    let all = everyone(n);
    let mut net = build(
        24,
        n,
        |i| i < 3,
        |i| if i == 3 { vec![0, 1, 2] } else { Vec::new() },
    );
    shared_topic(&mut net, n);
    let converged = net.run_until(PERIOD, |net| {
        (0..n).all(|i| sees_all(net, i, &all) && match_set(net, i) == full_match_set(i, &all))
    });
    assert!(
        converged.is_some_and(|at| at <= PROMPT),
        "converged at {converged:?}"
    );
    stays_whole(&mut net, &all, 4 * LEASE);

    // Among themselves, nodes 0-2 refresh by multicast only; node 3 hears them by unicast.
    let since = net.elapsed() - 3 * LEASE;
    for (a, b) in [(0, 1), (1, 2), (2, 0)] {
        let (multicast, unicast) = deliveries(&net, since, MessageKind::Announce, a, b);
        assert!(
            multicast >= 13 && unicast == 0,
            "{a} → {b}: {multicast} + {unicast}"
        );
    }
    for a in 0..3 {
        let (multicast, unicast) = deliveries(&net, since, MessageKind::Announce, a, 3);
        assert!(
            multicast == 0 && unicast >= 13,
            "{a} → 3: {multicast} + {unicast}"
        );
    }

    // Withdrawals cross at once both ways.
    let t = net.elapsed();
    net.remove_locals(0, &[guid(0, 1)]);
    net.remove_locals(3, &[guid(3, 1)]);
    net.run_for(Duration::from_millis(10));
    assert_eq!(
        first(&net, 3, t, unmatched(guid(3, 2), guid(0, 1))),
        Some(t + MS)
    );
    for i in 0..3 {
        assert_eq!(
            first(&net, i, t, unmatched(guid(i, 2), guid(3, 1))),
            Some(t + MS)
        );
    }

    // Node 3 crashes: the multicast nodes forget it after its lease.
    let gone = net.engine(3).node_id();
    let t = net.elapsed();
    net.crash(3);
    net.run_for(LEASE + PERIOD);
    for i in 0..3 {
        assert_eq!(
            first(&net, i, t, lost(gone, LossReason::Expired)),
            Some(last_refresh(&net, 3, i) + LEASE)
        );
    }
}

#[test]
fn a_one_sided_peer_list_without_multicast_keeps_both_sides() {
    // A (0) lists B (1); B lists nobody. Neither has multicast.
    let mut net = build(
        25,
        2,
        |_| false,
        |i| if i == 0 { vec![1] } else { Vec::new() },
    );
    shared_topic(&mut net, 2);
    let both = [0, 1];
    let converged = net.run_until(2 * PERIOD, |net| {
        (0..2).all(|i| sees_all(net, i, &both) && match_set(net, i) == full_match_set(i, &both))
    });
    // B did not exist for A's first Solicit; A's second one (200 ms) introduces them.
    assert!(
        converged.is_some_and(|at| at <= Duration::from_millis(200) + PROMPT),
        "converged at {converged:?}"
    );
    let since = net.elapsed();
    stays_whole(&mut net, &both, 5 * LEASE);
    // B's refreshes reach A although B lists nobody: A reaches B only by unicast.
    let (multicast, unicast) = deliveries(&net, since, MessageKind::Announce, 1, 0);
    assert!(multicast == 0 && unicast >= 22, "B → A: {unicast}");

    // B's withdrawal and Bye reach A at once.
    let t = net.elapsed();
    net.remove_locals(1, &[guid(1, 1)]);
    net.run_for(Duration::from_millis(10));
    assert_eq!(
        first(&net, 0, t, unmatched(guid(0, 2), guid(1, 1))),
        Some(t + MS)
    );
    let b = net.engine(1).node_id();
    let t = net.elapsed();
    net.close(1);
    net.run_for(Duration::from_millis(10));
    assert_eq!(first(&net, 0, t, lost(b, LossReason::Bye)), Some(t + MS));
}

#[test]
fn a_configured_peer_gets_unicast_copies_even_when_multicast_reaches_it() {
    // All three use multicast; node 0 also lists node 1.
    let mut net = build(
        26,
        3,
        |_| true,
        |i| if i == 0 { vec![1] } else { Vec::new() },
    );
    shared_topic(&mut net, 3);
    net.run_for(2 * PERIOD);
    let since = net.elapsed();
    stays_whole(&mut net, &everyone(3), 2 * LEASE);

    let (multicast, unicast) = deliveries(&net, since, MessageKind::Announce, 0, 1);
    assert!(
        multicast >= 9 && unicast == multicast,
        "0 → 1: {multicast} + {unicast}"
    );
    let (multicast, unicast) = deliveries(&net, since, MessageKind::Announce, 0, 2);
    assert!(
        multicast >= 9 && unicast == 0,
        "0 → 2: {multicast} + {unicast}"
    );
    // The second copy is an ordinary refresh: one match per pair, never repeated.
    for i in 0..3 {
        for j in 0..3 {
            assert_eq!(
                count(&net, i, Duration::ZERO, matched(guid(i, 2), guid(j, 1))),
                1
            );
        }
    }
}

#[test]
fn multicast_failing_between_known_nodes_is_bridged_by_unicast() {
    // Both use multicast and list nobody; then multicast stops working for both, unicast
    // still does. Each starts unicast copies before the other forgets it.
    let mut net = build(27, 2, |_| true, |_| Vec::new());
    shared_topic(&mut net, 2);
    net.run_for(2 * PERIOD);
    let cut = net.elapsed();
    net.cut_multicast(&[0, 1]);
    stays_whole(&mut net, &[0, 1], 4 * LEASE);
    let (multicast, unicast) = deliveries(&net, cut, MessageKind::Announce, 0, 1);
    assert!(multicast == 0 && unicast >= 14, "0 → 1: {unicast}");

    // Multicast back: the unicast copies stop within half a lease and a period.
    net.heal();
    net.run_for(LEASE / 2 + 2 * PERIOD);
    let since = net.elapsed();
    stays_whole(&mut net, &[0, 1], LEASE);
    for (a, b) in [(0, 1), (1, 0)] {
        let (multicast, unicast) = deliveries(&net, since, MessageKind::Announce, a, b);
        assert!(
            multicast >= 4 && unicast == 0,
            "{a} → {b}: {multicast} + {unicast}"
        );
    }
}

#[test]
fn a_peer_that_is_down_at_start_is_found_when_it_comes_up() {
    // Multicast off; node 1 lists node 0 only and is down for a while.
    let mut net = build(
        28,
        2,
        |_| false,
        |i| if i == 1 { vec![0] } else { Vec::new() },
    );
    shared_topic(&mut net, 2);
    net.crash(1);
    net.run_for(3 * LEASE);
    assert_eq!(net.engine(0).nodes().count(), 0);
    let t = net.elapsed();
    net.restart(1, 2801);
    net.add_local(1, producer::<Pose>(guid(1, 1), "shared"));
    net.add_local(1, consumer::<Pose>(guid(1, 2), "shared"));
    let at = net.run_until(PERIOD, |net| {
        (0..2).all(|i| sees_all(net, i, &[0, 1]) && match_set(net, i) == full_match_set(i, &[0, 1]))
    });
    assert!(at.is_some_and(|at| at <= t + PROMPT), "found at {at:?}");
}

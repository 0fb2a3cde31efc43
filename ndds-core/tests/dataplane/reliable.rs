//! Reliable streams between participants: every sample exactly once and in order whatever
//! the faults; a partition longer than the reader liveness loses exactly one run, reported;
//! slow consumers pace their producer instead of losing samples.

use std::time::Duration;

use ndds_core::arbitration::Rules;
use ndds_core::participant::Event;
use proptest::prelude::*;

use crate::sim::{App, Item, Link, MTU, SimNet, WriterApp, covers, exactly, guid, stream_of};
use crate::{MS, best_effort_consumer, reliable_consumer, reliable_producer};

/// Random link faults: loss, jitter (reordering), duplication.
fn faulty_link() -> impl Strategy<Value = Link> {
    (0.0..0.25f64, 0u64..6, 0.0..0.1f64).prop_map(|(loss, jitter_ms, duplicate)| Link {
        latency: MS,
        jitter: MS * jitter_ms as u32,
        loss,
        duplicate,
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// One reliable producer, three reliable consumers on three other hosts over faulty
    /// links (one of them maybe cut off for a while, shorter than the reader liveness, and
    /// maybe slow to take its samples), samples from 100 B to several datagrams, matches told
    /// to either side first: each consumer takes every sample exactly once, in order and
    /// intact, and nothing is reported lost; no datagram exceeds the MTU.
    #[test]
    fn reliable_delivery_is_exactly_once_in_order_under_faults(
        seed in any::<u64>(),
        links in proptest::collection::vec(faulty_link(), 3),
        depth in 8usize..64,
        total in 60u64..150,
        interval_us in 0u64..2000,
        sizes in proptest::collection::vec(
            prop_oneof![Just(100usize), Just(1000), Just(3000), Just(9000)], 1..4),
        partition in proptest::option::of((0u64..300, 50u64..500)),
        slow in proptest::option::of((1u64..5, 1usize..4)),
        consumers_first in any::<bool>(),
    ) {
        let mut net = SimNet::new(seed, 4);
        net.consumers_first = consumers_first;
        net.add_producer(0, 1, reliable_producer(depth));
        for (i, link) in links.into_iter().enumerate() {
            let node = i + 1;
            net.set_link(0, node, link);
            // The last consumer may be slow, holding at most 8 samples.
            let (app, credit) = match slow {
                Some((every_ms, batch)) if node == 3 => {
                    (App::Slow { every: MS * every_ms as u32, batch }, 8)
                }
                _ => (App::Eager, 64),
            };
            net.add_consumer(node, 10, reliable_consumer(Some(credit)), app);
            net.connect((0, 1), (node, 10));
        }
        let mut writer = WriterApp::new(0, 1, total, Duration::from_micros(interval_us), 0);
        writer.sizes = sizes;
        net.add_writer(writer);
        let all = |n: &SimNet| (1..4).all(|c| n.consumer(c, 10).got.len() as u64 >= total);
        if let Some((at, span)) = partition {
            net.run_until(net.at_ms(at), all);
            net.cut(0, 3);
            net.run_for(MS * span as u32);
            net.heal(0, 3);
        }
        let done = net.run_until(net.at_ms(60_000), all);
        prop_assert!(done, "not delivered by {:?}: {:?}", net.elapsed(), net.stats);
        for node in 1..4 {
            let log = net.consumer(node, 10);
            prop_assert_eq!(exactly(&log.seqs_from(guid(0, 1)), 1, total), Ok(()));
            prop_assert!(log.got.iter().all(|g| g.intact));
            prop_assert_eq!(log.lost(), vec![]);
        }
        prop_assert_eq!(net.stats.too_big, 0);
        prop_assert!(net.stats.largest <= MTU);
        let silenced = net.nodes[0]
            .producer_events
            .iter()
            .any(|(_, e)| matches!(e, Event::ReaderSilenced { .. }));
        prop_assert!(!silenced);
    }
}

#[test]
fn a_partition_longer_than_the_reader_liveness_loses_one_reported_run() {
    // One sample every 5 ms for 4 s, window 32, liveness 1 s. Cut from 1 s to 3 s: the
    // window closes, the reader is silenced and the writer goes on, evicting what the
    // reader missed. After the partition the reader learns exactly one run as lost and
    // takes everything after it.
    let mut net = SimNet::new(11, 2);
    net.add_producer(0, 1, reliable_producer(32));
    net.add_consumer(1, 2, reliable_consumer(Some(64)), App::Eager);
    net.connect((0, 1), (1, 2));
    let writer = net.add_writer(WriterApp::new(0, 1, 800, 5 * MS, 200));
    net.run_until(net.at_ms(1_000), |_| false);
    net.cut(0, 1);
    net.run_until(net.at_ms(3_000), |_| false);
    net.heal(0, 1);
    let total = 800;
    let done = net.run_until(net.at_ms(10_000), |n| {
        n.writers[writer].finished() && n.consumer(1, 2).got.last().is_some_and(|g| g.seq == total)
    });
    assert!(done, "{:?}", net.stats);
    let log = net.consumer(1, 2);
    let stream = stream_of(log, guid(0, 1));
    let lost = covers(&stream, 1, total).expect("every seq once, in order");
    assert_eq!(lost.len(), 1, "one run lost: {lost:?}");
    let (from, to) = lost[0];
    // Written before the cut (seqs 1..=201, the last at 1 s) arrived; the lost run ends at
    // most a window before the first seq written after the partition.
    assert_eq!(from, 202, "lost from {from}");
    let written_by_heal = net.writers[writer]
        .written_at
        .iter()
        .filter(|at| **at < Duration::from_secs(3))
        .count() as u64;
    assert!(
        to + 32 >= written_by_heal && to <= written_by_heal + 1,
        "lost to {to}, {written_by_heal} written by the heal"
    );
    let silenced = net.nodes[0]
        .producer_events
        .iter()
        .filter(|(_, e)| matches!(e, Event::ReaderSilenced { reader, .. } if *reader == guid(1, 2)))
        .count();
    assert_eq!(silenced, 1);
    assert!(matches!(stream.last(), Some(Item::Sample(800))));
}

#[test]
fn a_slow_consumer_paces_its_producer_and_loses_nothing() {
    // The producer could write 300 samples in 150 ms; its consumer holds at most 8 and takes
    // 2 every 10 ms over a link losing 5 %: the writer waits for the window, the consumer
    // never holds more than its credit, and every sample arrives once, in order.
    let mut net = SimNet::new(5, 2);
    net.set_link(0, 1, Link::lossy(0.05));
    net.add_producer(0, 1, reliable_producer(16));
    let slow = App::Slow {
        every: 10 * MS,
        batch: 2,
    };
    net.add_consumer(1, 2, reliable_consumer(Some(8)), slow);
    net.connect((0, 1), (1, 2));
    let writer = net.add_writer(WriterApp::new(0, 1, 300, MS / 2, 500));
    let done = net.run_until(net.at_ms(30_000), |n| n.consumer(1, 2).got.len() == 300);
    assert!(done, "{:?}", net.stats);
    let log = net.consumer(1, 2);
    assert_eq!(exactly(&log.seqs_from(guid(0, 1)), 1, 300), Ok(()));
    assert_eq!(log.lost(), vec![]);
    assert!(log.max_pending <= 8, "held {}", log.max_pending);
    // 300 samples at 2 per 10 ms take 1.5 s; the writer spent most of it waiting.
    assert!(
        net.elapsed() >= Duration::from_millis(1_450),
        "{:?}",
        net.elapsed()
    );
    assert!(net.writers[writer].blocked_for >= Duration::from_secs(1));
    assert!(net.writers[writer].refused.is_empty());
    let events = &net.nodes[0].producer_events;
    assert!(
        events
            .iter()
            .any(|(_, e)| matches!(e, Event::WindowOpen { producer: 1 }))
    );
    assert!(
        !events
            .iter()
            .any(|(_, e)| matches!(e, Event::ReaderSilenced { .. }))
    );
}

#[test]
fn a_consumer_that_stops_taking_for_longer_than_the_liveness_is_not_silenced() {
    // The application takes nothing for 3 s (three reader liveness timeouts), then takes
    // everything: its reader kept answering heartbeats, so it held the window all along,
    // the producer waited, and nothing was lost.
    let mut net = SimNet::new(6, 2);
    net.add_producer(0, 1, reliable_producer(16));
    net.add_consumer(1, 2, reliable_consumer(Some(8)), App::Never);
    net.connect((0, 1), (1, 2));
    let writer = net.add_writer(WriterApp::new(0, 1, 100, MS, 100));
    net.run_until(net.at_ms(3_000), |_| false);
    assert_eq!(net.consumer(1, 2).max_pending, 8);
    net.nodes[1].consumers.get_mut(&2).expect("declared").app = App::Eager;
    let done = net.run_until(net.at_ms(10_000), |n| n.consumer(1, 2).got.len() == 100);
    assert!(done, "{:?}", net.stats);
    let log = net.consumer(1, 2);
    assert_eq!(exactly(&log.seqs_from(guid(0, 1)), 1, 100), Ok(()));
    assert_eq!(log.lost(), vec![]);
    assert!(net.writers[writer].blocked_for >= Duration::from_millis(2_900));
    let events = &net.nodes[0].producer_events;
    assert!(
        !events
            .iter()
            .any(|(_, e)| matches!(e, Event::ReaderSilenced { .. })),
        "{events:?}"
    );
}

#[test]
fn reliable_and_best_effort_consumers_of_one_participant_get_their_own_guarantees() {
    // A reliable producer and two consumers on one other host, over a link losing 20 % and
    // duplicating 10 %: the reliable one takes every sample once, in order; the best-effort
    // one takes a subset, in increasing order, never twice.
    let mut net = SimNet::new(8, 2);
    net.set_link(
        0,
        1,
        Link {
            duplicate: 0.1,
            jitter: 3 * MS,
            ..Link::lossy(0.2)
        },
    );
    net.add_producer(0, 1, reliable_producer(64));
    net.add_consumer(1, 2, reliable_consumer(None), App::Eager);
    net.add_consumer(1, 3, best_effort_consumer(Rules::default()), App::Eager);
    net.connect((0, 1), (1, 2));
    net.connect((0, 1), (1, 3));
    net.add_writer(WriterApp::new(0, 1, 400, MS, 300));
    let done = net.run_until(net.at_ms(20_000), |n| n.consumer(1, 2).got.len() == 400);
    assert!(done, "{:?}", net.stats);
    net.run_for(100 * MS);
    let reliable = net.consumer(1, 2);
    assert_eq!(exactly(&reliable.seqs_from(guid(0, 1)), 1, 400), Ok(()));
    let best_effort = net.consumer(1, 3).seqs_from(guid(0, 1));
    assert!(
        best_effort.windows(2).all(|w| w[0] < w[1]),
        "{best_effort:?}"
    );
    // About 80 % of the originals arrive (resends to the reliable consumer are addressed to
    // it alone).
    assert!(
        (240..=380).contains(&best_effort.len()),
        "{} of 400",
        best_effort.len()
    );
}

#[test]
fn a_slow_consumer_of_two_reliable_producers_takes_from_both_in_turn() {
    // Two producers of equal strength (both accepted) write 60 samples each, flat out, to a
    // consumer that holds at most 4 and takes 2 every 10 ms. Both streams always have
    // samples ready, so the consumer's credit must go round: neither producer waits for the
    // other to finish.
    let mut net = SimNet::new(23, 3);
    for node in 0..2 {
        net.add_producer(node, 1, reliable_producer(16));
    }
    let slow = App::Slow {
        every: 10 * MS,
        batch: 2,
    };
    net.add_consumer(2, 10, reliable_consumer(Some(4)), slow);
    for node in 0..2 {
        net.connect((node, 1), (2, 10));
        net.add_writer(WriterApp::new(node, 1, 60, MS / 10, 100));
    }
    let done = net.run_until(net.at_ms(30_000), |n| n.consumer(2, 10).got.len() == 120);
    assert!(done, "{:?}", net.stats);
    let log = net.consumer(2, 10);
    for node in 0..2 {
        assert_eq!(exactly(&log.seqs_from(guid(node, 1)), 1, 60), Ok(()));
    }
    assert_eq!(log.lost(), vec![]);
    assert!(log.max_pending <= 4, "held {}", log.max_pending);
    // In the first 40 samples taken, each producer has at least a third.
    let first = &log.got[..40];
    for node in 0..2 {
        let from = first.iter().filter(|g| g.writer == guid(node, 1)).count();
        assert!(from >= 13, "{from} of the first 40 from producer {node}");
    }
}

//! Late joiners across two simulated hosts: a consumer matched after 0, 1 or N samples were
//! written gets the kept ones first (a reliable consumer all of them, in order, over a lossy
//! link; a best-effort one the newest), then the live ones; a consumer matched from the
//! start gets nothing twice.

use std::time::Duration;

use ndds_core::arbitration::Rules;
use ndds_core::participant::ProducerSpec;
use ndds_core::reliability::WriterConfig;

use crate::sim::{App, Link, SimNet, WriterApp, exactly, guid};
use crate::{
    MS, best_effort_consumer, best_effort_producer, reliable_consumer, reliable_producer_with,
};

const PRODUCER: (usize, u32) = (0, 1);
const EARLY: (usize, u32) = (2, 3);
const LATE: (usize, u32) = (1, 2);
/// Samples written after the late joiner matched.
const LIVE: u64 = 20;

/// Writes `before` samples with only the early consumer matched, then matches the late one
/// and writes [`LIVE`] more, until both consumers have the last one.
fn late_join(net: &mut SimNet, spec: ProducerSpec, reliable: bool, before: u64) {
    let consumer = |reliable| match reliable {
        true => reliable_consumer(Some(64)),
        false => best_effort_consumer(Rules::default()),
    };
    net.add_producer(PRODUCER.0, PRODUCER.1, spec);
    net.add_consumer(EARLY.0, EARLY.1, consumer(reliable), App::Eager);
    net.connect(PRODUCER, EARLY);
    let writer = net.add_writer(WriterApp::new(PRODUCER.0, PRODUCER.1, before, MS, 200));
    net.run_for(100 * MS);
    assert_eq!(net.writers[writer].written(), before);
    net.add_consumer(LATE.0, LATE.1, consumer(reliable), App::Eager);
    net.connect(PRODUCER, LATE);
    // The kept samples leave at the match; the live ones from half a period later, so that
    // the network (which orders datagrams of one instant by their bytes) cannot put the
    // first live sample ahead of the kept newest, which would make that one old data.
    net.run_for(MS / 2);
    net.writers[writer].total = before + LIVE;
    let last = before + LIVE;
    let done = net.run_until(net.at_ms(10_000), |n| {
        [LATE, EARLY].iter().all(|c| {
            n.consumer(c.0, c.1)
                .got
                .last()
                .is_some_and(|g| g.seq == last)
        })
    });
    assert!(done, "{:?}", net.stats);
    net.run_for(200 * MS);
}

#[test]
fn a_reliable_late_joiner_gets_the_kept_samples_first_in_order() {
    for keep in [0usize, 1, 5] {
        for before in [0u64, 1, 12] {
            for consumers_first in [false, true] {
                let case =
                    format!("keep {keep}, {before} before, consumers first {consumers_first}");
                let mut net = SimNet::new(51 + before, 3);
                net.link = Link::lossy(0.1);
                net.consumers_first = consumers_first;
                let config = WriterConfig {
                    depth: 32,
                    late_joiners: keep,
                    ..WriterConfig::default()
                };
                late_join(&mut net, reliable_producer_with(config), true, before);
                let first = before - before.min(keep as u64) + 1;
                let late = net.consumer(LATE.0, LATE.1);
                let seqs = late.seqs_from(guid(PRODUCER.0, PRODUCER.1));
                assert_eq!(exactly(&seqs, first, before + LIVE), Ok(()), "{case}");
                assert_eq!(late.lost(), vec![], "{case}");
                assert!(late.got.iter().all(|g| g.intact), "{case}");
                let early = net.consumer(EARLY.0, EARLY.1);
                let seqs = early.seqs_from(guid(PRODUCER.0, PRODUCER.1));
                assert_eq!(exactly(&seqs, 1, before + LIVE), Ok(()), "{case}");
            }
        }
    }
}

#[test]
fn a_best_effort_late_joiner_gets_the_newest_sample() {
    for before in [0u64, 1, 12] {
        let mut net = SimNet::new(61, 3);
        let spec = ProducerSpec {
            late_joiners: 3,
            ..best_effort_producer(0, Duration::ZERO)
        };
        late_join(&mut net, spec, false, before);
        let late = net.consumer(LATE.0, LATE.1);
        let seqs = late.seqs_from(guid(PRODUCER.0, PRODUCER.1));
        let first = before.max(1);
        assert_eq!(
            exactly(&seqs, first, before + LIVE),
            Ok(()),
            "{before} before"
        );
        let early = net.consumer(EARLY.0, EARLY.1);
        let seqs = early.seqs_from(guid(PRODUCER.0, PRODUCER.1));
        assert_eq!(exactly(&seqs, 1, before + LIVE), Ok(()), "{before} before");
    }
}

#[test]
fn a_best_effort_producer_that_keeps_nothing_gives_a_late_joiner_only_live_samples() {
    let mut net = SimNet::new(62, 3);
    late_join(&mut net, best_effort_producer(0, Duration::ZERO), false, 12);
    let late = net.consumer(LATE.0, LATE.1);
    let seqs = late.seqs_from(guid(PRODUCER.0, PRODUCER.1));
    assert_eq!(exactly(&seqs, 13, 12 + LIVE), Ok(()));
}

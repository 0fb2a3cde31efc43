//! The consumer's rules across the network: arbitration between redundant producers by
//! strength and persistence (fail-over and fail-back), minimum separation, deadlines.

use std::time::Duration;

use ndds_core::arbitration::{Notification, Rules, SampleStatus};

use crate::sim::{App, Got, SimNet, WriterApp, guid};
use crate::{MS, best_effort_consumer, best_effort_producer};

const STRONG: (usize, u32) = (0, 1);
const WEAK: (usize, u32) = (1, 1);
const CONSUMER: (usize, u32) = (2, 7);

/// A strong producer (host 0) and a weak one (host 1), both writing every 10 ms for
/// `seconds`, and a best-effort consumer on host 2.
fn redundant(seed: u64, persistence: Duration, seconds: u64) -> SimNet {
    let mut net = SimNet::new(seed, 3);
    net.add_producer(STRONG.0, STRONG.1, best_effort_producer(10, persistence));
    net.add_producer(WEAK.0, WEAK.1, best_effort_producer(5, persistence));
    net.add_consumer(
        CONSUMER.0,
        CONSUMER.1,
        best_effort_consumer(Rules::default()),
        App::Eager,
    );
    net.connect(STRONG, CONSUMER);
    net.connect(WEAK, CONSUMER);
    let total = seconds * 100;
    net.add_writer(WriterApp::new(STRONG.0, STRONG.1, total, 10 * MS, 64));
    let mut weak = WriterApp::new(WEAK.0, WEAK.1, total, 10 * MS, 64);
    // Out of step with the strong one.
    weak.start = 5 * MS;
    net.add_writer(weak);
    net
}

fn from(got: &[Got], node: usize) -> impl Iterator<Item = &Got> {
    got.iter().filter(move |g| g.writer == guid(node, 1))
}

#[test]
fn a_weaker_producer_takes_over_after_the_persistence_and_the_stronger_takes_back() {
    let mut net = redundant(31, 200 * MS, 3);
    net.run_until(net.at_ms(1_000), |_| false);
    net.cut(STRONG.0, CONSUMER.0);
    net.run_until(net.at_ms(2_000), |_| false);
    net.heal(STRONG.0, CONSUMER.0);
    net.run_until(net.at_ms(3_100), |_| false);
    let got = &net.consumer(CONSUMER.0, CONSUMER.1).got;
    let strong = guid(STRONG.0, STRONG.1);
    let weak = guid(WEAK.0, WEAK.1);
    // Before the cut only the strong producer is delivered.
    let first_weak = from(got, WEAK.0).next().expect("the weak one took over");
    assert!(got.iter().take_while(|g| g.writer == strong).count() >= 99);
    // It takes over once the persistence of the last strong sample (arrived about 1 s) ran
    // out, at its next sample.
    assert_eq!(
        first_weak.status,
        SampleStatus::TookOver { previous: strong }
    );
    let at = first_weak.delivered;
    assert!(at >= 1_190 * MS && at <= 1_215 * MS, "took over at {at:?}");
    // The strong one takes back with its first sample after the partition.
    let back = got
        .iter()
        .find(|g| g.writer == strong && g.delivered > 1_500 * MS)
        .expect("the strong one took back");
    assert_eq!(back.status, SampleStatus::TookOver { previous: weak });
    assert!(
        back.delivered >= 2_000 * MS && back.delivered <= 2_012 * MS,
        "{back:?}"
    );
    // In between, every weak sample; after it, none.
    let during = from(got, WEAK.0)
        .filter(|g| g.delivered < back.delivered)
        .count();
    assert!((78..=82).contains(&during), "{during} weak samples");
    assert!(!from(got, WEAK.0).any(|g| g.delivered > back.delivered));
    let strong_after = from(got, STRONG.0)
        .filter(|g| g.delivered > back.delivered)
        .count();
    assert!(strong_after >= 98, "{strong_after}");
    assert!(got.iter().all(|g| g.intact));
}

/// Discovery says the strong producer is gone at `lost_at_ms`: a persistence of 10 s would
/// hold the weak producer off, the news lets it in at its next sample.
fn replaced_when_lost(seed: u64, lost_at_ms: u64) {
    let mut net = redundant(seed, 10_000 * MS, 2);
    net.run_until(net.at_ms(lost_at_ms), |_| false);
    net.disconnect(STRONG, CONSUMER);
    net.run_until(net.at_ms(2_100), |_| false);
    let log = net.consumer(CONSUMER.0, CONSUMER.1);
    let strong = guid(STRONG.0, STRONG.1);
    let lost: Vec<_> = log
        .notable()
        .into_iter()
        .filter(|(_, n)| matches!(n, Notification::ProducerLost { .. }))
        .collect();
    let at = Duration::from_millis(lost_at_ms);
    assert_eq!(
        lost,
        vec![(
            at,
            Notification::ProducerLost {
                writer: strong,
                was_current: true
            }
        )]
    );
    let first_weak = from(&log.got, WEAK.0)
        .next()
        .expect("the weak one took over");
    assert_eq!(
        first_weak.status,
        SampleStatus::TookOver { previous: strong }
    );
    assert!(first_weak.delivered <= at + 11 * MS, "{first_weak:?}");
    let weak = from(&log.got, WEAK.0).count();
    assert!(weak >= 98, "{weak} weak samples");
}

#[test]
fn a_lost_producer_is_replaced_at_the_next_sample_of_another() {
    // The news arrives 4 ms after the strong producer's last sample.
    replaced_when_lost(32, 1_005);
}

#[test]
fn a_lost_producers_last_sample_in_flight_does_not_put_it_back_in_charge() {
    // The news arrives while the strong producer's last sample (written at 1000 ms) is on
    // the way: it is delivered at 1001 ms, and must not hold the weak one off for 10 s.
    replaced_when_lost(32, 1_000);
}

#[test]
fn minimum_separation_delivers_the_newest_at_most_once_per_window() {
    // A sample every 10 ms for 1 s; the consumer wants at most one per 100 ms, and then
    // the newest.
    let mut net = SimNet::new(33, 2);
    net.add_producer(0, 1, best_effort_producer(0, Duration::ZERO));
    let rules = Rules {
        min_separation: 100 * MS,
        deadline: None,
        every_producer: false,
    };
    net.add_consumer(1, 2, best_effort_consumer(rules), App::Eager);
    net.connect((0, 1), (1, 2));
    let writer = net.add_writer(WriterApp::new(0, 1, 100, 10 * MS, 64));
    net.run_until(net.at_ms(1_200), |_| false);
    let got = &net.consumer(1, 2).got;
    assert!((10..=11).contains(&got.len()), "{} delivered", got.len());
    assert!(
        got.windows(2)
            .all(|w| w[1].delivered - w[0].delivered >= 100 * MS)
    );
    // Each is the newest that had arrived when it was handed out (1 ms latency).
    let written = &net.writers[writer].written_at;
    for g in got {
        let arrived = written.iter().filter(|at| **at + MS <= g.delivered).count() as u64;
        assert_eq!(g.seq, arrived, "{g:?}");
    }
    assert_eq!(got.last().map(|g| g.seq), Some(100));
    let counters = net.nodes[1].core.consumer_counters(2).expect("declared");
    assert_eq!(counters.arbiter.delivered, got.len() as u64);
    assert_eq!(counters.arbiter.accepted, 100);
    assert!(counters.arbiter.superseded >= 80);
}

#[test]
fn minimum_separation_never_delivers_an_older_sample_after_a_newer_one() {
    // Seqs 1..=11 every 10 ms: seq 1 is delivered at 1 ms, 2..=10 are held in turn, and
    // seq 11 arrives at 101 ms, exactly when the window ends (datagrams of an instant are
    // handled before its timers, as a driver whose timer fires late would).
    let mut net = SimNet::new(35, 2);
    net.add_producer(0, 1, best_effort_producer(0, Duration::ZERO));
    let rules = Rules {
        min_separation: 100 * MS,
        deadline: None,
        every_producer: false,
    };
    net.add_consumer(1, 2, best_effort_consumer(rules), App::Eager);
    net.connect((0, 1), (1, 2));
    net.add_writer(WriterApp::new(0, 1, 11, 10 * MS, 64));
    net.run_until(net.at_ms(500), |_| false);
    let seqs = net.consumer(1, 2).seqs_from(guid(0, 1));
    // Today: [1, 11, 10] (seq 10 at 201 ms).
    assert_eq!(seqs, vec![1, 11]);
}

#[test]
fn a_deadline_reports_silence_and_only_silence() {
    // Deadline 50 ms. Nothing until 120 ms, then a sample every 10 ms until 1 s, a pause
    // until 1.3 s, samples again until 1.6 s.
    let mut net = SimNet::new(34, 2);
    net.add_producer(0, 1, best_effort_producer(0, Duration::ZERO));
    let rules = Rules {
        min_separation: Duration::ZERO,
        deadline: Some(50 * MS),
        every_producer: false,
    };
    net.add_consumer(1, 2, best_effort_consumer(rules), App::Eager);
    net.connect((0, 1), (1, 2));
    let mut writer = WriterApp::new(0, 1, 1_000, 10 * MS, 64);
    writer.start = 120 * MS;
    let writer = net.add_writer(writer);
    net.run_until(net.at_ms(995), |_| false);
    net.writers[writer].active = false;
    net.run_until(net.at_ms(1_300), |_| false);
    net.writers[writer].active = true;
    net.run_until(net.at_ms(1_600), |_| false);
    let log = net.consumer(1, 2);
    let notes = log.notable();
    let never: Vec<_> = notes
        .iter()
        .filter(|(_, n)| matches!(n, Notification::NeverReceived { .. }))
        .map(|(at, _)| *at)
        .collect();
    assert_eq!(never, vec![50 * MS, 100 * MS]);
    let silent: Vec<_> = notes
        .iter()
        .filter_map(|(at, n)| match n {
            Notification::NoNewData { silent_for } => Some((*at, *silent_for)),
            _ => None,
        })
        .collect();
    // The last sample before the pause arrived at 991 ms: misses at 1041, 1091, ... 1291.
    let expected: Vec<_> = (1..=6)
        .map(|k| (991 * MS + 50 * MS * k, 50 * MS * k))
        .collect();
    assert_eq!(silent, expected);
    assert_eq!(notes.len(), 8, "{notes:?}");
    assert!(log.got.iter().any(|g| g.delivered > 1_300 * MS));
}

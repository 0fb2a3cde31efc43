//! The consumer's side of a match arrives late: the producer's daemon told it of the
//! consumer at once, but the consumer's daemon missed the producer's announcement (10 % of
//! the datagrams lost) and learns of it only from the next one, after the reader liveness.
//! Meanwhile the producer writes to a reader that cannot answer (its datagrams are held or
//! dropped as unmatched), silences it, and goes on at its own pace; once matched, the
//! consumer must pick up the stream: the first part reported lost, everything later
//! delivered exactly once.

use std::time::Duration;

use ndds_core::reliability::{ReaderConfig, WriterConfig};

use crate::sim::{App, Link, SimNet, WriterApp, covers, guid, stream_of};
use crate::{reliable_consumer, reliable_producer_with};

const PRODUCER: (usize, u32) = (0, 1);
const CONSUMER: (usize, u32) = (1, 10);

fn run(seed: u64, size: usize, loss: f64) {
    let mut net = SimNet::new(seed, 2);
    net.set_link(0, 1, Link::local(loss));
    let producer = reliable_producer_with(WriterConfig {
        depth: 1024,
        ..WriterConfig::default()
    });
    net.add_producer(PRODUCER.0, PRODUCER.1, producer);
    let mut consumer = reliable_consumer(None);
    consumer.reliable = Some(ReaderConfig {
        depth: 1024,
        ..ReaderConfig::default()
    });
    net.add_consumer(CONSUMER.0, CONSUMER.1, consumer, App::Eager);
    net.connect_producer_side(PRODUCER, CONSUMER);
    // 10 k samples/s for 2 s: half a second of it after the match.
    let total = 20_000;
    net.add_writer(WriterApp::new(
        PRODUCER.0,
        PRODUCER.1,
        total,
        Duration::from_micros(100),
        size,
    ));
    net.run_until(net.at_ms(1500), |_| false);
    let before = net.consumer(CONSUMER.0, CONSUMER.1).got.len();
    assert_eq!(before, 0, "delivered before it was matched");
    net.connect(PRODUCER, CONSUMER);
    let matched_at = net.elapsed();
    let done = net.run_until(net.at_ms(20_000), |n| {
        n.writers[0].finished()
            && n.consumer(CONSUMER.0, CONSUMER.1)
                .got
                .last()
                .is_some_and(|g| g.seq == total)
    });
    let log = net.consumer(CONSUMER.0, CONSUMER.1);
    let first = log.got.first().map(|g| g.delivered);
    assert!(
        done,
        "seed {seed}: matched at {matched_at:?}; {} delivered (first at {first:?}), written {}; \
         {:?}; {:?}",
        log.got.len(),
        net.writers[0].written(),
        net.stats,
        net.nodes[CONSUMER.0].core.consumer_counters(CONSUMER.1),
    );
    // Whatever it did not get is reported lost, once: the stream covers 1..=total.
    let stream = stream_of(log, guid(PRODUCER.0, PRODUCER.1));
    covers(&stream, 1, total).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
}

#[test]
fn a_reader_matched_after_its_silencing_picks_up_the_stream_of_large_samples() {
    for seed in 1..=2 {
        run(seed, 8192, 0.1);
    }
}

#[test]
fn a_reader_matched_after_its_silencing_picks_up_the_stream_of_small_samples() {
    for seed in 1..=2 {
        run(seed, 1024, 0.1);
    }
}

//! Reliable throughput through loss, in virtual time: a writer that could write one sample
//! every `interval` (its CPU's pace) over a link of 100 µs each way, with and without 10 %
//! of the datagrams lost. The protocol alone (retry times, heartbeats while blocked,
//! acknowledgements) decides how much of the lossless rate survives; what the real machine
//! adds (CPU, queues) is in `scripts/bench-loss.sh`.

use std::time::Duration;

use ndds_core::participant::BatchConfig;
use ndds_core::reliability::{ReaderConfig, WriterConfig};

use crate::sim::{App, Link, SimNet, WriterApp, exactly, guid};
use crate::{MS, reliable_consumer, reliable_producer_with};

/// One run: how long the consumer took to get all `total` samples, each exactly once.
fn run(seed: u64, loss: f64, size: usize, batch: bool, total: u64, interval: Duration) -> Duration {
    let mut net = SimNet::new(seed, 2);
    net.set_link(0, 1, Link::local(loss));
    let mut producer = reliable_producer_with(WriterConfig {
        depth: 1024,
        ..WriterConfig::default()
    });
    producer.batching = batch.then_some(BatchConfig {
        max_bytes: 65000,
        max_delay: MS,
    });
    net.add_producer(0, 1, producer);
    let mut consumer = reliable_consumer(None);
    consumer.reliable = Some(ReaderConfig {
        depth: 1024,
        ..ReaderConfig::default()
    });
    net.add_consumer(1, 10, consumer, App::Eager);
    net.connect((0, 1), (1, 10));
    net.add_writer(WriterApp::new(0, 1, total, interval, size));
    let start = net.elapsed();
    let done = net.run_until(net.at_ms(60_000), |n| {
        n.consumer(1, 10).got.len() as u64 >= total
    });
    assert!(
        done,
        "not delivered by {:?}: {:?}",
        net.elapsed(),
        net.stats
    );
    let log = net.consumer(1, 10);
    assert_eq!(exactly(&log.seqs_from(guid(0, 1)), 1, total), Ok(()));
    assert_eq!(log.lost(), vec![]);
    net.elapsed() - start
}

/// The lossless rate over the lossy one, for a few seeds (the smallest).
fn kept(size: usize, batch: bool, total: u64, interval: Duration) -> f64 {
    (1..=3)
        .map(|seed| {
            let clean = run(seed, 0.0, size, batch, total, interval);
            let lossy = run(seed, 0.1, size, batch, total, interval);
            clean.as_secs_f64() / lossy.as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// 64 B samples batched about 17 to a datagram, written at 1.6 M/s: a lost datagram is 17
/// samples to repair within the window of 1024 (0.6 ms of writing, three round trips).
/// With the earlier floors (1 ms before a request is repeated, 1 ms before the first
/// heartbeat of a blocked writer) this kept 0.36, and 1 KiB below 0.77.
#[test]
fn batched_small_samples_keep_most_of_their_rate_through_10_percent_loss() {
    let kept = kept(64, true, 30_000, Duration::from_nanos(600));
    assert!(kept >= 0.7, "kept {kept:.2} of the lossless rate");
}

/// 1 KiB samples, one per datagram, at 380 k/s.
#[test]
fn kilobyte_samples_keep_their_rate_through_10_percent_loss() {
    let kept = kept(1024, false, 20_000, Duration::from_nanos(2600));
    assert!(kept >= 0.9, "kept {kept:.2} of the lossless rate");
}

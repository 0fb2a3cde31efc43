//! What a consumer costs in memory while the application holds samples: 1024 queued samples
//! of 64 bytes must not pin a 64 KiB receive buffer each (64 MiB); received datagrams share
//! the receive buffer's regions, so they cost about their own size.
//!
//! The figure covers every thread of the process (both participants, the embedded daemon),
//! measured as the growth of live heap bytes while the samples are written and queued.

mod common;
mod counting;

use std::sync::atomic::Ordering;
use std::time::Duration;

use common::{eventually, participant, unique_config};
use counting::{LIVE_BYTES, turn};
use ndds_client::{ConsumerQos, ProducerQos, Reliability};

const SAMPLES: usize = 1024;
const SIZE: usize = 64;
const WAIT: Duration = Duration::from_secs(10);

/// Live heap growth while `SAMPLES` samples of `SIZE` bytes are written and held in a
/// consumer's queue.
fn held_bytes(producer_qos: ProducerQos, consumer_qos: ConsumerQos) -> i64 {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "m");
    let (writer_side, reader_side) = (participant(&config), participant(&config));
    let consumer = reader_side
        .consumer::<Vec<u8>>("memory", consumer_qos)
        .unwrap();
    let producer = writer_side
        .producer::<Vec<u8>>("memory", producer_qos)
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    assert!(consumer.wait_for_producers(1, WAIT));
    // One sample first, so buffers that exist once per endpoint are not counted.
    producer.write(&vec![0u8; SIZE - 2]).unwrap();
    consumer.recv_timeout(WAIT).unwrap();
    let before = LIVE_BYTES.load(Ordering::Relaxed);
    for i in 0..SAMPLES {
        producer.write(&vec![i as u8; SIZE - 2]).unwrap();
    }
    assert!(
        eventually(WAIT, || consumer.stats().delivered as usize > SAMPLES),
        "{:?}",
        consumer.stats()
    );
    // The samples written are live in the loop above only one at a time.
    let held = LIVE_BYTES.load(Ordering::Relaxed) - before;
    let mut taken = 0;
    while consumer.try_recv().is_ok() {
        taken += 1;
    }
    assert_eq!(taken, SAMPLES, "every sample was held");
    held
}

#[test]
fn a_consumer_holding_1024_small_samples_holds_about_their_size() {
    let qos = ConsumerQos {
        depth: SAMPLES,
        ..ConsumerQos::default()
    };
    let held = held_bytes(ProducerQos::default(), qos);
    eprintln!(
        "best effort: {SAMPLES} held samples of {SIZE} B: {held} bytes live ({} per sample)",
        held / SAMPLES as i64
    );
    // A 64 KiB buffer per sample would be 64 MiB; the regions cost a few hundred KiB.
    assert!(held < 2 << 20, "{held} bytes for {SAMPLES} samples");
}

#[test]
fn a_reliable_consumer_holding_1024_small_samples_holds_about_their_size() {
    let reliable = Reliability::Reliable {
        depth: SAMPLES as u32,
    };
    let consumer_qos = ConsumerQos {
        depth: SAMPLES,
        reliability: reliable,
        ..ConsumerQos::default()
    };
    let producer_qos = ProducerQos {
        reliability: reliable,
        ..ProducerQos::default()
    };
    let held = held_bytes(producer_qos, consumer_qos);
    eprintln!(
        "reliable: {SAMPLES} held samples of {SIZE} B, and the producer's history of them: {held} bytes live ({} per sample)",
        held / SAMPLES as i64
    );
    assert!(held < 2 << 20, "{held} bytes for {SAMPLES} samples");
}

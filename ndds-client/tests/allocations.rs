//! Steady-state publishing and delivery allocate nothing per sample: a counting global
//! allocator counts the allocations made on the threads a sample passes through (the writing
//! thread, the participant's I/O thread, the thread taking samples) while thousands of
//! samples flow, after a warm-up that lets every reused buffer reach its size.
//!
//! Only allocations made on the tracked threads are counted: the embedded daemon's threads
//! (discovery) and the participant's I/O thread do their own periodic work, not work per
//! sample.

mod counting;

mod common;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use common::{participant, unique_config};
use counting::{ALLOCATIONS, track, turn};
use ndds_client::{Batching, ConsumerQos, ProducerQos, Reliability};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct Pose {
    seq: u64,
    x: f64,
    y: f64,
    z: f64,
    flags: [u8; 16],
}

fn pose(seq: u64) -> Pose {
    Pose {
        seq,
        x: seq as f64,
        y: 0.5,
        z: -1.0,
        flags: [seq as u8; 16],
    }
}

const WARM_UP: u64 = 2_000;
const MEASURED: u64 = 10_000;
const WAIT: Duration = Duration::from_secs(10);

/// Writes `count` samples starting at `first`, never more than 32 ahead of `received`, so no
/// socket buffer overflows and the run is a steady flow.
fn write_paced(
    producer: &ndds_client::Producer<Pose>,
    first: u64,
    count: u64,
    received: &dyn Fn() -> u64,
) {
    for seq in first..first + count {
        producer.write(&pose(seq)).unwrap();
        let deadline = Instant::now() + WAIT;
        while received() + 32 < seq {
            assert!(Instant::now() < deadline, "samples stopped arriving");
            std::thread::yield_now();
        }
    }
}

/// A direct consumer (callback on the I/O thread) and a producer: counts allocations on
/// the writing thread and the I/O thread.
fn measure_direct(producer_qos: ProducerQos, consumer_qos: ConsumerQos) -> u64 {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let (writer_side, reader_side) = (participant(&config), participant(&config));
    let received = Arc::new(AtomicU64::new(0));
    let seen = received.clone();
    let consumer = reader_side
        .consumer::<Pose>("alloc", consumer_qos)
        .unwrap()
        .on_sample_direct(move |sample| {
            track(true);
            assert_eq!(sample.value, pose(sample.value.seq));
            seen.fetch_add(1, Ordering::Relaxed);
        })
        .unwrap();
    let producer = writer_side.producer::<Pose>("alloc", producer_qos).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    let received_now = || received.load(Ordering::Relaxed);
    write_paced(&producer, 1, WARM_UP, &received_now);
    producer.flush().unwrap();
    while received_now() < WARM_UP {
        std::thread::sleep(Duration::from_millis(1));
    }
    ALLOCATIONS.store(0, Ordering::Relaxed);
    track(true);
    write_paced(&producer, WARM_UP + 1, MEASURED, &received_now);
    producer.flush().unwrap();
    track(false);
    let deadline = Instant::now() + WAIT;
    while received_now() < WARM_UP + MEASURED {
        assert!(Instant::now() < deadline, "samples lost");
        std::thread::sleep(Duration::from_millis(1));
    }
    let allocations = ALLOCATIONS.load(Ordering::Relaxed);
    drop(consumer);
    allocations
}

#[test]
fn best_effort_publishing_and_direct_delivery_allocate_nothing_per_sample() {
    let allocations = measure_direct(ProducerQos::default(), ConsumerQos::default());
    eprintln!("best effort, direct delivery: {allocations} allocations for {MEASURED} samples");
    assert_eq!(allocations, 0);
}

#[test]
fn batched_publishing_allocates_nothing_per_sample() {
    let batching = Batching::On {
        max_delay: Duration::from_micros(200),
        max_bytes: 8192,
    };
    let allocations = measure_direct(
        ProducerQos {
            batching,
            ..ProducerQos::default()
        },
        ConsumerQos::default(),
    );
    eprintln!("batched, direct delivery: {allocations} allocations for {MEASURED} samples");
    assert_eq!(allocations, 0);
}

#[test]
fn a_queued_consumer_taking_with_a_blocking_recv_allocates_nothing_per_sample() {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let (writer_side, reader_side) = (participant(&config), participant(&config));
    let consumer = reader_side
        .consumer::<Pose>("alloc-queue", ConsumerQos::default())
        .unwrap();
    let producer = writer_side
        .producer::<Pose>("alloc-queue", ProducerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    let run = |first: u64, count: u64| {
        for seq in first..first + count {
            producer.write(&pose(seq)).unwrap();
            // A blocking take: the queue is usually empty when it starts, so it waits.
            let sample = consumer.recv_timeout(WAIT).unwrap();
            assert_eq!(sample.value, pose(seq));
        }
    };
    run(1, WARM_UP);
    ALLOCATIONS.store(0, Ordering::Relaxed);
    // The I/O thread is not tracked here (the direct tests cover it); this thread writes
    // and takes.
    track(true);
    run(WARM_UP + 1, MEASURED);
    track(false);
    let allocations = ALLOCATIONS.load(Ordering::Relaxed);
    eprintln!("queued consumer, recv_timeout: {allocations} allocations for {MEASURED} samples");
    assert_eq!(allocations, 0);
}

/// Reliable streams keep every sample until it is acknowledged. Samples are encoded into
/// pooled buffers, reused once the history lets go of them: a producer makes at most one
/// buffer per history slot (`depth + 2`) over its life, two allocations each (the buffer and
/// its shared handle), however many samples it writes, and only when more samples are
/// unacknowledged at once than ever before (an acknowledgement came late). The stream's
/// bookkeeping (heartbeats, acknowledgements, ordering) allocates nothing.
#[test]
fn reliable_publishing_and_delivery_allocate_at_most_one_buffer_per_history_slot() {
    const DEPTH: u32 = 64;
    let reliable = Reliability::Reliable { depth: DEPTH };
    let allocations = measure_direct(
        ProducerQos {
            reliability: reliable,
            ..ProducerQos::default()
        },
        ConsumerQos {
            reliability: reliable,
            ..ConsumerQos::default()
        },
    );
    eprintln!(
        "reliable (depth {DEPTH}), direct delivery: {allocations} allocations for {MEASURED} samples"
    );
    assert!(
        allocations <= 2 * (u64::from(DEPTH) + 2),
        "{allocations} allocations: more than the history's buffers"
    );
}

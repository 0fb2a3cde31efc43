//! How many threads a participant runs: one I/O thread, one session thread, and one thread
//! for all its callback consumers (the embedded daemon's threads come on top). Alone in its
//! test binary, so no other test starts threads meanwhile.

mod common;

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::{eventually, participant, unique_config};
use ndds_client::{ConsumerQos, ProducerQos};

const WAIT: Duration = Duration::from_secs(5);

/// Threads of this process.
fn threads() -> usize {
    std::fs::read_dir("/proc/self/task").map_or(0, |dir| dir.count())
}

#[test]
fn ten_callback_consumers_share_one_callback_thread() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let before = threads();
    let seen = Arc::new(Mutex::new(BTreeMap::<String, u64>::new()));
    let callbacks: Vec<_> = (0..10)
        .map(|i| {
            let seen = seen.clone();
            let topic = format!("cb/{i}");
            p.consumer::<u64>(&topic, ConsumerQos::default())
                .unwrap()
                .on_sample(move |sample| {
                    *seen.lock().unwrap().entry(topic.clone()).or_default() += sample.value;
                })
                .unwrap()
        })
        .collect();
    let during = threads();
    let producers: Vec<_> = (0..10)
        .map(|i| {
            p.producer::<u64>(&format!("cb/{i}"), ProducerQos::default())
                .unwrap()
        })
        .collect();
    for producer in &producers {
        assert!(producer.wait_for_consumers(1, WAIT));
        producer.write(&1).unwrap();
    }
    assert!(
        eventually(WAIT, || seen.lock().unwrap().len() == 10),
        "{:?}",
        seen.lock().unwrap()
    );
    let grew = during.saturating_sub(before);
    eprintln!("10 callback consumers: {before} threads before, {during} with them");
    assert_eq!(grew, 1, "10 callback consumers started {grew} threads");
    drop(callbacks);
}

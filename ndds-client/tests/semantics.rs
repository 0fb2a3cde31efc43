//! NDDS semantics through the SDK, with real daemons on loopback: hot stand-by between
//! producers of different strength, minimum separation, deadlines, polled consumers, and the
//! notifications consumers receive.

mod common;

use std::time::{Duration, Instant};

use common::{eventually, participant, unique_config};
use ndds_client::{
    ConsumerMode, ConsumerQos, Event, Notification, Participant, PollStatus, ProducerQos,
    RecvError, SampleStatus, TypeDescription,
};

const WAIT: Duration = Duration::from_secs(5);

/// Samples (writer strength, value) and notifications received within `window`.
fn collect(
    consumer: &ndds_client::Consumer<u64>,
    window: Duration,
) -> (Vec<(i32, u64, SampleStatus)>, Vec<Notification>) {
    let end = Instant::now() + window;
    let (mut samples, mut notes) = (Vec::new(), Vec::new());
    loop {
        let left = end.saturating_duration_since(Instant::now());
        match consumer.recv_event_timeout(left) {
            Ok(Event::Sample(s)) => samples.push((s.info.strength, s.value, s.info.status)),
            Ok(Event::Notification(n)) => notes.push(n),
            Err(RecvError::Timeout) => return (samples, notes),
            Err(err) => panic!("{err}"),
        }
    }
}

/// Writes `value` every `period` from a thread until `stop` is set.
fn publish(
    producer: ndds_client::Producer<u64>,
    value: u64,
    period: Duration,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<ndds_client::Producer<u64>> {
    std::thread::spawn(move || {
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            producer.write(&value).unwrap();
            std::thread::sleep(period);
        }
        producer
    })
}

fn strong_and_weak(p: &Participant, persistence: Duration) -> [ndds_client::Producer<u64>; 2] {
    [10, 5].map(|strength| {
        p.producer::<u64>(
            "standby",
            ProducerQos {
                strength,
                persistence,
                ..ProducerQos::default()
            },
        )
        .unwrap()
    })
}

#[test]
fn the_strongest_producer_wins_and_a_weaker_one_stands_by() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let (pa, pb, pc) = (
        participant(&config),
        participant(&config),
        participant(&config),
    );
    let consumer = pc
        .consumer::<u64>("standby", ConsumerQos::default())
        .unwrap();
    let [strong, _] = strong_and_weak(&pa, Duration::from_millis(300));
    let [_, weak] = strong_and_weak(&pb, Duration::from_millis(300));
    assert!(consumer.wait_for_producers(2, WAIT));
    assert!(strong.wait_for_consumers(1, WAIT) && weak.wait_for_consumers(1, WAIT));
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let period = Duration::from_millis(10);
    let strong = publish(strong, 10, period, stop.clone());
    assert_eq!(consumer.recv_timeout(WAIT).unwrap().info.strength, 10);
    let weak = publish(weak, 5, period, stop.clone());

    // While both publish, only the strong one is delivered.
    let (samples, _) = collect(&consumer, Duration::from_millis(400));
    assert!(samples.len() > 10, "{samples:?}");
    assert!(
        samples.iter().all(|(s, v, _)| *s == 10 && *v == 10),
        "{samples:?}"
    );
    assert!(consumer.stats().weaker > 10);

    // The strong producer is closed: the consumer hears it is lost and the weak one takes
    // over at once (discovery says so; no need to wait for the persistence).
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let (strong, weak) = (strong.join().unwrap(), weak.join().unwrap());
    drop(strong);
    let closed = Instant::now();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let weak = publish(weak, 5, period, stop.clone());
    let took_over = loop {
        match consumer.recv_event_timeout(WAIT).unwrap() {
            Event::Sample(s) if s.info.strength == 5 => break s,
            _ => {}
        }
    };
    let failover = closed.elapsed();
    eprintln!("failover after the strong producer closed: {failover:?}");
    assert!(matches!(
        took_over.info.status,
        SampleStatus::TookOver { .. }
    ));
    assert!(failover < Duration::from_millis(300), "{failover:?}");

    // The strong producer returns and wins again.
    let [strong, _] = strong_and_weak(&pa, Duration::from_millis(300));
    let strong = publish(strong, 10, period, stop.clone());
    let back = loop {
        match consumer.recv_event_timeout(WAIT).unwrap() {
            Event::Sample(s) if s.info.strength == 10 => break s,
            _ => {}
        }
    };
    assert!(matches!(back.info.status, SampleStatus::TookOver { .. }));
    let (samples, _) = collect(&consumer, Duration::from_millis(200));
    assert!(samples.iter().all(|(s, _, _)| *s == 10), "{samples:?}");
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    drop((strong.join(), weak.join()));
}

#[test]
fn a_silent_stronger_producer_yields_after_its_persistence() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let consumer = p
        .consumer::<u64>("standby", ConsumerQos::default())
        .unwrap();
    let [strong, weak] = strong_and_weak(&p, Duration::from_millis(200));
    assert!(strong.wait_for_consumers(1, WAIT) && weak.wait_for_consumers(1, WAIT));
    strong.write(&10).unwrap();
    let silent_since = Instant::now();
    // The weak producer keeps writing; it is refused until the strong sample is 200 ms old.
    let first_weak = loop {
        weak.write(&5).unwrap();
        if let Ok(s) = consumer.recv_timeout(Duration::from_millis(5))
            && s.value == 5
        {
            break silent_since.elapsed();
        }
        assert!(silent_since.elapsed() < WAIT);
    };
    eprintln!("weak producer accepted {first_weak:?} after the strong one fell silent");
    assert!(first_weak >= Duration::from_millis(195), "{first_weak:?}");
    assert!(first_weak < Duration::from_millis(400), "{first_weak:?}");
}

#[test]
fn minimum_separation_delivers_the_newest_sample_once_per_window() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let qos = ConsumerQos {
        min_separation: Duration::from_millis(100),
        ..ConsumerQos::default()
    };
    let consumer = p.consumer::<u64>("fast", qos).unwrap();
    let producer = p.producer::<u64>("fast", ProducerQos::default()).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    let start = Instant::now();
    let mut last = 0;
    while start.elapsed() < Duration::from_millis(450) {
        last += 1;
        producer.write(&last).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    let (samples, _) = collect(&consumer, Duration::from_millis(300));
    let values: Vec<u64> = samples.iter().map(|(_, v, _)| *v).collect();
    // About one per 100 ms over 450 ms (5 or 6), increasing, ending with the very last one.
    assert!((4..=7).contains(&values.len()), "{values:?}");
    assert!(values.windows(2).all(|w| w[0] < w[1]), "{values:?}");
    assert_eq!(values.last(), Some(&last));
    assert!(consumer.stats().superseded > 300, "{:?}", consumer.stats());
}

#[test]
fn deadlines_notify_never_received_then_no_new_data() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let qos = ConsumerQos {
        deadline: Some(Duration::from_millis(100)),
        ..ConsumerQos::default()
    };
    let consumer = p.consumer::<u64>("quiet", qos).unwrap();
    let (_, notes) = collect(&consumer, Duration::from_millis(350));
    let never = notes
        .iter()
        .filter(|n| matches!(n, Notification::NeverReceived { .. }))
        .count();
    assert!((2..=4).contains(&never), "{notes:?}");

    let producer = p.producer::<u64>("quiet", ProducerQos::default()).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    producer.write(&1).unwrap();
    let (samples, notes) = collect(&consumer, Duration::from_millis(350));
    assert_eq!(samples.len(), 1);
    let silent: Vec<Duration> = notes
        .iter()
        .filter_map(|n| match n {
            Notification::NoNewData { silent_for } => Some(*silent_for),
            _ => None,
        })
        .collect();
    assert!((2..=4).contains(&silent.len()), "{notes:?}");
    assert!(
        silent.windows(2).all(|w| w[0] < w[1]),
        "repeated while silent: {silent:?}"
    );
    assert!(consumer.stats().deadline_misses >= 4);
}

#[test]
fn a_polled_consumer_sees_the_latest_sample_and_its_status() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let qos = ConsumerQos {
        mode: ConsumerMode::Polled,
        deadline: Some(Duration::from_millis(100)),
        ..ConsumerQos::default()
    };
    let consumer = p.consumer::<u64>("polled", qos).unwrap();
    let polled = consumer.poll().unwrap();
    assert_eq!(
        (polled.sample, polled.status),
        (None, PollStatus::NeverReceived)
    );
    assert_eq!(
        consumer.recv().unwrap_err(),
        RecvError::WrongMode(ConsumerMode::Polled)
    );

    let producer = p.producer::<u64>("polled", ProducerQos::default()).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    for value in 1..=3 {
        producer.write(&value).unwrap();
    }
    assert!(eventually(WAIT, || consumer.stats().delivered == 3));
    let polled = consumer.poll().unwrap();
    assert_eq!(polled.status, PollStatus::Fresh);
    assert_eq!(polled.sample.map(|s| s.value), Some(3), "the latest only");
    assert_eq!(consumer.poll().unwrap().status, PollStatus::Unchanged);
    std::thread::sleep(Duration::from_millis(150));
    let stale = consumer.poll().unwrap();
    assert_eq!(stale.status, PollStatus::NoNewData);
    assert_eq!(
        stale.sample.map(|s| s.value),
        Some(3),
        "still the latest value"
    );
    let notes = consumer.take_notifications().unwrap();
    assert!(
        notes
            .iter()
            .any(|n| matches!(n, Notification::NoNewData { .. })),
        "{notes:?}"
    );
}

#[test]
fn incompatible_producers_and_undecodable_samples_are_notified() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let consumer = p.consumer::<u64>("typed", ConsumerQos::default()).unwrap();
    let _other = p
        .producer::<String>("typed", ProducerQos::default())
        .unwrap();
    let note = consumer.recv_event_timeout(WAIT).unwrap();
    match note {
        Event::Notification(Notification::Incompatible {
            type_name,
            local_type,
            fingerprint,
            local_fingerprint,
            ..
        }) => {
            assert!(type_name.contains("String"), "{type_name}");
            assert_eq!(local_type, "u64");
            assert_eq!(fingerprint, TypeDescription::of::<String>().fingerprint());
            assert_eq!(
                local_fingerprint,
                TypeDescription::of::<u64>().fingerprint()
            );
        }
        other => panic!("expected an incompatibility, got {other:?}"),
    }

    let raw = p
        .raw_producer(
            "typed",
            TypeDescription::of::<u64>(),
            ProducerQos::default(),
        )
        .unwrap();
    assert!(raw.wait_for_consumers(1, WAIT));
    raw.write_bytes(&[0xff; 11]).unwrap(); // an overlong varint: not a u64
    match consumer.recv_event_timeout(WAIT).unwrap() {
        Event::Notification(Notification::DeserializationError { seq, .. }) => assert_eq!(seq, 1),
        other => panic!("expected a deserialization error, got {other:?}"),
    }
    assert_eq!(consumer.stats().decode_errors, 1);
}

#[test]
fn a_lost_producer_is_notified() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let q = participant(&config);
    let consumer = p.consumer::<u64>("lost", ConsumerQos::default()).unwrap();
    let producer = q.producer::<u64>("lost", ProducerQos::default()).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    producer.write(&1).unwrap();
    let writer = consumer.recv_timeout(WAIT).unwrap().info.writer;
    drop(producer);
    match consumer.recv_event_timeout(WAIT).unwrap() {
        Event::Notification(Notification::ProducerLost {
            writer: lost,
            was_current,
        }) => {
            assert_eq!(lost, writer);
            assert!(was_current);
        }
        other => panic!("expected producer lost, got {other:?}"),
    }
}

//! NDDS semantics through the SDK, with real daemons on loopback: hot stand-by between
//! producers of different strength, minimum separation, deadlines, polled consumers, and the
//! notifications consumers receive.
//!
//! These tests run real threads on a machine other work shares, so they check behaviour and
//! never a tight wall-clock window. The timing of each rule is proven exactly in virtual time
//! in ndds-core (`src/arbitration/tests.rs`; discovery in `tests/simnet.rs`). A bound here is
//! either generous (it happens within [`WAIT`]) or one that load cannot break: measured from
//! before its cause ("not accepted before the persistence ran out since the strong sample was
//! written"), or derived from the rule itself ("at most one delivery per window" over the
//! whole measured span).

mod common;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use common::{eventually, participant, unique_config};
use ndds_client::{
    Consumer, ConsumerMode, ConsumerQos, Event, Notification, Participant, PollStatus, Producer,
    ProducerQos, RecvError, SampleStatus, TypeDescription,
};

const WAIT: Duration = Duration::from_secs(5);

/// Events received until `done` holds for them or `limit` passes (the caller asserts `done`).
fn events_until(
    consumer: &Consumer<u64>,
    limit: Duration,
    mut done: impl FnMut(&[Event<u64>]) -> bool,
) -> Vec<Event<u64>> {
    let end = Instant::now() + limit;
    let mut events = Vec::new();
    while !done(&events) {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        match consumer.recv_event_timeout(left.min(Duration::from_millis(10))) {
            Ok(event) => events.push(event),
            Err(RecvError::Timeout) => {}
            Err(err) => panic!("{err}"),
        }
    }
    events
}

/// The (writer strength, value, status) of the samples among `events`.
fn samples(events: &[Event<u64>]) -> Vec<(i32, u64, SampleStatus)> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Sample(s) => Some((s.info.strength, s.value, s.info.status)),
            Event::Notification(_) => None,
        })
        .collect()
}

/// The samples received until the consumer has refused `more` further samples of weaker
/// producers (asserted, within [`WAIT`]).
fn while_refusing_weaker(consumer: &Consumer<u64>, more: u64) -> Vec<(i32, u64, SampleStatus)> {
    let target = consumer.stats().weaker + more;
    let events = events_until(consumer, WAIT, |_| consumer.stats().weaker >= target);
    assert!(consumer.stats().weaker >= target, "{:?}", consumer.stats());
    samples(&events)
}

/// Writes `value` every `period` from a thread until `stop` is set.
fn publish(
    producer: Producer<u64>,
    value: u64,
    period: Duration,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<Producer<u64>> {
    std::thread::spawn(move || {
        while !stop.load(Ordering::Relaxed) {
            producer.write(&value).unwrap();
            std::thread::sleep(period);
        }
        producer
    })
}

fn strong_and_weak(p: &Participant, persistence: Duration) -> [Producer<u64>; 2] {
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

/// A sample of `strength` among `events`: its index and status.
fn first_of(events: &[Event<u64>], strength: i32) -> Option<(usize, SampleStatus)> {
    events.iter().enumerate().find_map(|(i, e)| match e {
        Event::Sample(s) if s.info.strength == strength => Some((i, s.info.status)),
        _ => None,
    })
}

#[test]
fn the_strongest_producer_wins_and_a_weaker_one_stands_by() {
    // Longer than the whole test: the weak producer can take over only because the strong one
    // is lost, never because its persistence ran out.
    let persistence = Duration::from_secs(600);
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
    let [strong, _] = strong_and_weak(&pa, persistence);
    let [_, weak] = strong_and_weak(&pb, persistence);
    assert!(consumer.wait_for_producers(2, WAIT));
    assert!(strong.wait_for_consumers(1, WAIT) && weak.wait_for_consumers(1, WAIT));
    let (strong_writer, weak_writer) = (strong.guid(), weak.guid());
    let stop = Arc::new(AtomicBool::new(false));
    let period = Duration::from_millis(10);
    let strong = publish(strong, 10, period, stop.clone());
    assert_eq!(consumer.recv_timeout(WAIT).unwrap().info.strength, 10);
    let weak = publish(weak, 5, period, stop.clone());

    // While both publish, only the strong one is delivered.
    let samples = while_refusing_weaker(&consumer, 10);
    assert!(
        samples.iter().all(|(s, v, _)| *s == 10 && *v == 10),
        "{samples:?}"
    );

    // The strong producer is closed: the consumer hears it is lost, and that alone lets the
    // weak one take over (its persistence would hold it off for minutes).
    stop.store(true, Ordering::Relaxed);
    let (strong, weak) = (strong.join().unwrap(), weak.join().unwrap());
    drop(strong);
    let closed = Instant::now();
    let stop = Arc::new(AtomicBool::new(false));
    let weak = publish(weak, 5, period, stop.clone());
    let events = events_until(&consumer, WAIT, |events| first_of(events, 5).is_some());
    eprintln!(
        "failover after the strong producer closed: {:?}",
        closed.elapsed()
    );
    let (took_over, status) = first_of(&events, 5).expect("the weak producer takes over");
    assert_eq!(
        status,
        SampleStatus::TookOver {
            previous: strong_writer
        }
    );
    let lost = events.iter().position(|e| {
        *e == Event::Notification(Notification::ProducerLost {
            writer: strong_writer,
            was_current: true,
        })
    });
    assert!(
        lost.is_some_and(|lost| lost < took_over),
        "lost before the takeover: {events:?}"
    );

    // The strong producer returns and wins again, and the weak one is refused once more.
    let [strong, _] = strong_and_weak(&pa, persistence);
    let strong = publish(strong, 10, period, stop.clone());
    let events = events_until(&consumer, WAIT, |events| first_of(events, 10).is_some());
    let (_, status) = first_of(&events, 10).expect("the strong producer is back");
    assert_eq!(
        status,
        SampleStatus::TookOver {
            previous: weak_writer
        }
    );
    let samples = while_refusing_weaker(&consumer, 10);
    assert!(samples.iter().all(|(s, _, _)| *s == 10), "{samples:?}");
    stop.store(true, Ordering::Relaxed);
    drop((strong.join(), weak.join()));
}

#[test]
fn a_silent_stronger_producer_yields_after_its_persistence() {
    let persistence = Duration::from_millis(200);
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let consumer = p
        .consumer::<u64>("standby", ConsumerQos::default())
        .unwrap();
    let [strong, weak] = strong_and_weak(&p, persistence);
    assert!(strong.wait_for_consumers(1, WAIT) && weak.wait_for_consumers(1, WAIT));
    let written = Instant::now();
    strong.write(&10).unwrap();
    assert_eq!(consumer.recv_timeout(WAIT).unwrap().value, 10);
    // The weak producer keeps writing; it is refused until the strong sample is `persistence`
    // old (counted from its arrival, which came after `written`).
    let took_over = loop {
        weak.write(&5).unwrap();
        if let Ok(s) = consumer.recv_timeout(Duration::from_millis(5)) {
            break s;
        }
        assert!(
            written.elapsed() < WAIT,
            "the weak producer never took over"
        );
    };
    let after = written.elapsed();
    eprintln!("weak producer accepted {after:?} after the strong one wrote its last sample");
    assert_eq!(took_over.value, 5);
    assert_eq!(
        took_over.info.status,
        SampleStatus::TookOver {
            previous: strong.guid()
        }
    );
    assert!(
        after >= persistence,
        "accepted before the persistence ran out: {after:?}"
    );
}

#[test]
fn minimum_separation_delivers_the_newest_sample_once_per_window() {
    let window = Duration::from_millis(100);
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let qos = ConsumerQos {
        min_separation: window,
        ..ConsumerQos::default()
    };
    let consumer = p.consumer::<u64>("fast", qos).unwrap();
    let producer = p.producer::<u64>("fast", ProducerQos::default()).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    let start = Instant::now();
    let last = 300;
    for value in 1..=last {
        producer.write(&value).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    let events = events_until(&consumer, WAIT, |events| {
        samples(events).iter().any(|(_, v, _)| *v == last)
    });
    let span = start.elapsed();
    let values: Vec<u64> = samples(&events).iter().map(|(_, v, _)| *v).collect();
    // The newest sample always comes through, in order, after the first one at once.
    assert_eq!(values.last(), Some(&last), "{values:?}");
    assert!(values.len() >= 2, "{values:?}");
    assert!(values.windows(2).all(|w| w[0] < w[1]), "{values:?}");
    // Deliveries are at least a window apart, however late the threads ran: over the whole
    // span, no more than one per window (about 4 in an unloaded run; 300 without the rule).
    let windows = span.as_millis() / window.as_millis() + 1;
    assert!(
        values.len() as u128 <= windows,
        "{} deliveries in {span:?}: {values:?}",
        values.len()
    );
    // What was not delivered was superseded; nothing is still held.
    let stats = consumer.stats();
    assert!(stats.superseded > 0, "{stats:?}");
    assert_eq!(stats.delivered, values.len() as u64, "{stats:?}");
    assert_eq!(
        stats.accepted,
        stats.delivered + stats.superseded,
        "{stats:?}"
    );
}

/// The `k`-th duration (from 1) is at least `k` deadlines: a deadline notification is never
/// raised before its time, and never twice within one deadline.
fn one_deadline_apart_at_least(durations: &[Duration], deadline: Duration) -> bool {
    durations
        .iter()
        .zip(1u32..)
        .all(|(d, k)| *d >= deadline * k)
}

#[test]
fn deadlines_notify_never_received_then_no_new_data() {
    let deadline = Duration::from_millis(100);
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let qos = ConsumerQos {
        deadline: Some(deadline),
        ..ConsumerQos::default()
    };
    let created = Instant::now();
    let consumer = p.consumer::<u64>("quiet", qos).unwrap();
    let never = |events: &[Event<u64>]| -> Vec<Duration> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Notification(Notification::NeverReceived { waited }) => Some(*waited),
                _ => None,
            })
            .collect()
    };
    let events = events_until(&consumer, WAIT, |events| never(events).len() >= 2);
    let waited = never(&events);
    assert_eq!(waited.len(), events.len(), "{events:?}");
    assert!(waited.len() >= 2, "{events:?}");
    assert!(one_deadline_apart_at_least(&waited, deadline), "{waited:?}");
    let bound = created.elapsed().as_millis() / deadline.as_millis();
    assert!(waited.len() as u128 <= bound, "{waited:?}");

    let producer = p.producer::<u64>("quiet", ProducerQos::default()).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    let written = Instant::now();
    producer.write(&1).unwrap();
    let no_new_data = |events: &[Event<u64>]| -> Vec<Duration> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Notification(Notification::NoNewData { silent_for }) => Some(*silent_for),
                _ => None,
            })
            .collect()
    };
    let events = events_until(&consumer, WAIT, |events| no_new_data(events).len() >= 2);
    // Perhaps more "never received" until the sample arrived; after it, "no new data" only.
    let first = events
        .iter()
        .position(|e| matches!(e, Event::Sample(_)))
        .expect("the sample");
    assert_eq!(samples(&events).len(), 1, "{events:?}");
    assert!(
        events[..first]
            .iter()
            .all(|e| matches!(e, Event::Notification(Notification::NeverReceived { .. }))),
        "{events:?}"
    );
    let silent = no_new_data(&events[first + 1..]);
    assert_eq!(silent.len(), events.len() - first - 1, "{events:?}");
    assert!(silent.len() >= 2, "{events:?}");
    assert!(one_deadline_apart_at_least(&silent, deadline), "{silent:?}");
    let bound = written.elapsed().as_millis() / deadline.as_millis();
    assert!(silent.len() as u128 <= bound, "{silent:?}");
    assert!(consumer.stats().deadline_misses >= 4);
}

#[test]
fn a_polled_consumer_sees_the_latest_sample_and_its_status() {
    let deadline = Duration::from_millis(100);
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let qos = ConsumerQos {
        mode: ConsumerMode::Polled,
        deadline: Some(deadline),
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
    let written = Instant::now();
    for value in 1..=3 {
        producer.write(&value).unwrap();
    }
    assert!(eventually(WAIT, || consumer.stats().delivered == 3));
    let polled = consumer.poll().unwrap();
    assert_eq!(polled.status, PollStatus::Fresh);
    assert_eq!(polled.sample.map(|s| s.value), Some(3), "the latest only");
    // Unchanged until the deadline passes (which a stalled thread may let happen by now).
    match consumer.poll().unwrap().status {
        PollStatus::Unchanged => {}
        PollStatus::NoNewData => assert!(written.elapsed() >= deadline),
        other => panic!("after a fresh poll: {other:?}"),
    }
    let stale = loop {
        let polled = consumer.poll().unwrap();
        match polled.status {
            PollStatus::NoNewData => break polled,
            PollStatus::Unchanged => assert!(written.elapsed() < WAIT, "never stale"),
            other => panic!("while no sample comes: {other:?}"),
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    assert!(
        written.elapsed() >= deadline,
        "stale before the deadline: {:?}",
        written.elapsed()
    );
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

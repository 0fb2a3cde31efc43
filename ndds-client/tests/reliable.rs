//! Reliable streams through the SDK with real daemons on loopback: ordering and completeness
//! under a slow consumer, flow control (blocking with a timeout, or dropping the oldest with a
//! `samples lost` status), matching rules, and large reliable samples.

mod common;

use std::time::{Duration, Instant};

use common::{participant, sibling, unique_config};
use ndds_client::{
    Consumer, ConsumerQos, Event, Notification, Producer, ProducerQos, RecvError, Reliability,
    WhenFull, WriteError,
};

const WAIT: Duration = Duration::from_secs(5);

fn reliable(depth: u32) -> Reliability {
    Reliability::Reliable { depth }
}

/// Two participants on one daemon, a reliable consumer of `topic` on one (queue `queue`,
/// reordering depth `depth`) and a reliable producer (history `depth`, and `producer`'s other
/// settings) on the other, matched. The participants and the daemon's directory live as long
/// as the returned guard.
fn reliable_pair(
    topic: &str,
    queue: usize,
    depth: u32,
    producer: ProducerQos,
) -> (impl Sized, Consumer<u64>, Producer<u64>) {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let (writer_side, reader_side) = (participant(&config), participant(&config));
    let consumer = reader_side
        .consumer::<u64>(
            topic,
            ConsumerQos {
                depth: queue,
                reliability: reliable(depth),
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let producer = writer_side
        .producer::<u64>(
            topic,
            ProducerQos {
                reliability: reliable(depth),
                ..producer
            },
        )
        .unwrap();
    // Both sides matched: a consumer whose match comes after the writes holds them for it
    // and gets them all, which is no test of falling behind.
    assert!(producer.wait_for_consumers(1, WAIT));
    assert!(consumer.wait_for_producers(1, WAIT));
    ((dir, writer_side, reader_side), consumer, producer)
}

#[test]
fn a_slow_reliable_consumer_gets_every_sample_in_order_and_slows_its_producer() {
    let (_hosts, consumer, producer) = reliable_pair(
        "cmd",
        4,
        16,
        ProducerQos {
            write_timeout: Duration::from_secs(10),
            ..ProducerQos::default()
        },
    );
    const COUNT: u64 = 600;
    let writer = std::thread::spawn(move || {
        for i in 1..=COUNT {
            producer.write(&i).unwrap();
        }
        producer
    });
    let mut got = Vec::new();
    while got.len() < COUNT as usize {
        match consumer.recv_event_timeout(WAIT).unwrap() {
            Event::Sample(sample) => got.push(sample.value),
            Event::Notification(n) => panic!("unexpected notification {n:?}"),
        }
        if got.len() % 50 == 0 {
            // A consumer that stops now and then: the producer must wait, not drop.
            std::thread::sleep(Duration::from_millis(30));
        }
    }
    let _producer = writer.join().unwrap();
    assert_eq!(got, (1..=COUNT).collect::<Vec<_>>());
    let stats = consumer.stats();
    assert_eq!(stats.overflow, 0, "nothing dropped at the queue");
}

#[test]
fn a_consumer_that_takes_nothing_blocks_its_producer_until_the_timeout() {
    let (_hosts, consumer, producer) = reliable_pair(
        "cmd",
        4,
        8,
        ProducerQos {
            write_timeout: Duration::from_millis(300),
            ..ProducerQos::default()
        },
    );
    // The window (8) fills once the consumer's queue (4) is full and nothing is taken.
    let mut written = 0u64;
    let blocked = loop {
        let started = Instant::now();
        match producer.write(&(written + 1)) {
            Ok(()) => written += 1,
            Err(err) => break (err, started.elapsed()),
        }
        assert!(written <= 64, "the producer never blocked");
    };
    let (err, waited) = blocked;
    match err {
        WriteError::WouldBlock { unacknowledged, .. } => assert_eq!(unacknowledged, 8),
        other => panic!("expected WouldBlock, got {other}"),
    }
    assert!(waited >= Duration::from_millis(250), "waited {waited:?}");
    assert!(written >= 8, "wrote {written} before blocking");
    // Taking samples opens the window again; every sample written arrives once, in order.
    let mut got = Vec::new();
    for i in written + 1..=written + 20 {
        while producer.write(&i).is_err() {
            got.push(consumer.recv_timeout(WAIT).unwrap().value);
        }
    }
    while let Ok(sample) = consumer.recv_timeout(Duration::from_millis(300)) {
        got.push(sample.value);
    }
    assert_eq!(got, (1..=written + 20).collect::<Vec<_>>());
}

#[test]
fn a_producer_that_drops_the_oldest_never_waits_and_reports_samples_lost() {
    let (_hosts, consumer, producer) = reliable_pair(
        "state",
        4,
        8,
        ProducerQos {
            when_full: WhenFull::DropOldest,
            write_timeout: Duration::from_secs(10),
            ..ProducerQos::default()
        },
    );
    const COUNT: u64 = 200;
    let started = Instant::now();
    for i in 1..=COUNT {
        producer.write(&i).unwrap();
    }
    assert!(started.elapsed() < Duration::from_secs(5), "writes waited");
    // The consumer has fallen behind once its stream has dropped samples it had no room for
    // (the producer's history, the newest 8, cannot repair them now). Without this wait, a
    // consumer whose receive thread was held up while the writes went out reads the queued
    // datagrams only while the loop below takes samples, keeps up, and loses nothing.
    let deadline = Instant::now() + WAIT;
    while consumer.stats().reliable.out_of_window == 0 {
        assert!(
            Instant::now() < deadline,
            "no loss seen: {:?}",
            consumer.stats()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    // Every seq is accounted for exactly once, in order: delivered, or inside a lost run.
    let mut next = 1u64;
    let mut lost_runs = 0;
    let mut trace = Vec::new();
    while next <= COUNT {
        let event = consumer.recv_event_timeout(WAIT).unwrap();
        trace.push(format!("{event:?}").chars().take(120).collect::<String>());
        match event {
            Event::Sample(sample) => {
                assert_eq!(sample.info.seq, next, "in order, no duplicate");
                assert_eq!(sample.value, next);
                next += 1;
            }
            Event::Notification(Notification::SamplesLost { writer, from, to }) => {
                assert_eq!(writer, producer.guid());
                assert_eq!(from, next, "a lost run starts where delivery stopped");
                assert!(to > from);
                lost_runs += 1;
                next = to;
            }
            Event::Notification(other) => panic!("unexpected {other:?}"),
        }
    }
    assert!(
        lost_runs >= 1,
        "a consumer that fell behind must be told: {:?} {trace:#?}",
        consumer.stats()
    );
    assert_eq!(next, COUNT + 1);
}

#[test]
fn a_reliable_consumer_does_not_match_a_best_effort_producer() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let consumer = p
        .consumer::<u64>(
            "mixed",
            ConsumerQos {
                reliability: reliable(16),
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let producer = p.producer::<u64>("mixed", ProducerQos::default()).unwrap();
    // Both sides see the other as incompatible, and the consumer is told why.
    let reason = match consumer.recv_event_timeout(WAIT) {
        Ok(Event::Notification(Notification::Incompatible { reason, .. })) => reason,
        Ok(other) => panic!("unexpected {other:?}"),
        Err(err) => panic!("no incompatibility reported: {err}"),
    };
    assert_eq!(reason, ndds_client::Incompatibility::Reliability);
    assert!(common::eventually(WAIT, || consumer.incompatible().len() == 1));
    assert!(common::eventually(WAIT, || producer.incompatible().len() == 1));
    assert!(producer.matched().is_empty() && consumer.matched().is_empty());
    producer.write(&1).unwrap();
    let err = consumer
        .recv_timeout(Duration::from_millis(200))
        .unwrap_err();
    assert!(
        matches!(&err, RecvError::TimeoutUnmatched(unmatched)
            if unmatched.producers[0].mismatch == ndds_client::Mismatch::Reliability),
        "{err:?}"
    );
    assert!(
        err.to_string()
            .contains("the producer is best-effort, this consumer requests reliable"),
        "{err}"
    );
    // A best-effort consumer of a reliable producer matches: it takes what arrives.
    let reliable_producer = p
        .producer::<u64>(
            "offered",
            ProducerQos {
                reliability: reliable(16),
                ..ProducerQos::default()
            },
        )
        .unwrap();
    let best_effort = p
        .consumer::<u64>("offered", ConsumerQos::default())
        .unwrap();
    assert!(reliable_producer.wait_for_consumers(1, WAIT));
    reliable_producer.write(&5).unwrap();
    assert_eq!(best_effort.recv_timeout(WAIT).unwrap().value, 5);
}

#[test]
fn large_reliable_samples_cross_between_two_daemons_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let host_a = unique_config(dir.path(), "host-a");
    let host_b = sibling(&host_a, dir.path(), "host-b");
    let (writer_side, reader_side) = (participant(&host_a), participant(&host_b));
    let consumer = reader_side
        .consumer::<Vec<u8>>(
            "frames",
            ConsumerQos {
                depth: 2,
                reliability: reliable(4),
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let producer = writer_side
        .producer::<Vec<u8>>(
            "frames",
            ProducerQos {
                reliability: reliable(4),
                write_timeout: Duration::from_secs(20),
                ..ProducerQos::default()
            },
        )
        .unwrap();
    assert!(producer.wait_for_consumers(1, Duration::from_secs(10)));
    let frame = |i: u32| -> Vec<u8> {
        let len = 3_000_000 + i as usize * 1000;
        (0..len).map(|b| (b as u32 ^ i) as u8).collect()
    };
    let writer = std::thread::spawn(move || {
        for i in 0..6 {
            producer.write(&frame(i)).unwrap();
        }
        producer
    });
    for i in 0..6 {
        let sample = consumer.recv_timeout(Duration::from_secs(20)).unwrap();
        assert_eq!(sample.info.seq, u64::from(i) + 1);
        assert!(sample.value == frame(i), "frame {i} intact");
    }
    let _producer = writer.join().unwrap();
}

#[test]
fn a_relay_in_a_direct_callback_is_told_at_once_when_its_window_is_full() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let (relay_side, edge) = (participant(&config), participant(&config));
    // The far end takes nothing: the relay's reliable window (4) fills.
    let stuck = edge
        .consumer::<u64>(
            "out",
            ConsumerQos {
                depth: 1,
                reliability: reliable(4),
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let relay_out = relay_side
        .producer::<u64>(
            "out",
            ProducerQos {
                reliability: reliable(4),
                write_timeout: Duration::from_secs(30),
                ..ProducerQos::default()
            },
        )
        .unwrap();
    assert!(relay_out.wait_for_consumers(1, WAIT));
    let (tx, results) = std::sync::mpsc::channel();
    let _relay = relay_side
        .consumer::<u64>("in", ConsumerQos::default())
        .unwrap()
        .on_sample_direct(move |sample| {
            let started = Instant::now();
            let result = relay_out.write(&sample.value);
            let _ = tx.send((result.map_err(|e| e.to_string()), started.elapsed()));
        })
        .unwrap();
    let source = edge.producer::<u64>("in", ProducerQos::default()).unwrap();
    assert!(source.wait_for_consumers(1, WAIT));
    let mut blocked = None;
    for i in 1..=20 {
        source.write(&i).unwrap();
        let (result, took) = results.recv_timeout(WAIT).unwrap();
        if let Err(message) = result {
            blocked = Some((i, message, took));
            break;
        }
    }
    let (at, message, took) = blocked.expect("the window filled");
    assert!(message.contains("blocked"), "{message}");
    assert!(
        took < Duration::from_secs(1),
        "waited {took:?} on the I/O thread"
    );
    assert!(
        at > 4,
        "the window holds 4 samples and the consumer's queue 1; blocked at {at}"
    );
    drop(stuck);
}

/// A reliable consumer's queued samples are acknowledged already: notifications (here a
/// deadline missed again and again while the application does not read) never push one out.
#[test]
fn notifications_never_push_acknowledged_samples_out_of_a_full_queue() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let (writer_side, reader_side) = (participant(&config), participant(&config));
    let consumer = reader_side
        .consumer::<u64>(
            "full-queue",
            ConsumerQos {
                depth: 4,
                reliability: reliable(16),
                deadline: Some(Duration::from_millis(20)),
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let producer = writer_side
        .producer::<u64>(
            "full-queue",
            ProducerQos {
                reliability: reliable(16),
                ..ProducerQos::default()
            },
        )
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    for n in 1..=4 {
        producer.write(&n).unwrap();
    }
    let deadline = Instant::now() + WAIT;
    while consumer.stats().delivered < 4 {
        assert!(Instant::now() < deadline, "{:?}", consumer.stats());
        std::thread::sleep(Duration::from_millis(5));
    }
    // Deadlines pass while nobody reads: "no new data", every 20 ms, into a full queue.
    std::thread::sleep(Duration::from_millis(400));
    let mut samples = Vec::new();
    let mut notifications = 0;
    while let Ok(event) = consumer.try_recv_event() {
        match event {
            Event::Sample(sample) => samples.push(sample.value),
            Event::Notification(_) => notifications += 1,
        }
    }
    assert_eq!(samples, [1, 2, 3, 4], "{notifications} notifications");
    assert!(
        notifications >= 5,
        "the deadline was reported: {notifications}"
    );
    assert_eq!(consumer.stats().overflow, 0);
}

/// Late joiners get the last values: a producer keeping 3 samples for late joiners wrote
/// 5 before anyone listened; a reliable consumer that joins gets 3, 4, 5 in order and then
/// what follows, a best-effort one gets 5 and then what follows.
#[test]
fn late_joiners_get_the_kept_samples_reliable_in_order_best_effort_the_newest() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let (writer_side, reader_side) = (participant(&config), participant(&config));
    for (reliability, expected) in [
        (reliable(16), vec![3_u64, 4, 5, 6]),
        (Reliability::BestEffort, vec![5, 6]),
    ] {
        let topic = format!("latched/{}", expected.len());
        let producer = writer_side
            .producer::<u64>(
                &topic,
                ProducerQos {
                    reliability,
                    late_joiners: 3,
                    ..ProducerQos::default()
                },
            )
            .unwrap();
        for n in 1..=5 {
            producer.write(&n).unwrap();
        }
        let consumer = reader_side
            .consumer::<u64>(
                &topic,
                ConsumerQos {
                    reliability,
                    ..ConsumerQos::default()
                },
            )
            .unwrap();
        assert!(producer.wait_for_consumers(1, WAIT));
        let mut got = Vec::new();
        while got.len() < expected.len() - 1 {
            got.push(consumer.recv_timeout(WAIT).expect("the kept samples").value);
        }
        producer.write(&6).unwrap();
        got.push(consumer.recv_timeout(WAIT).expect("the next sample").value);
        assert_eq!(got, expected, "{reliability:?}");
        assert!(consumer.recv_timeout(Duration::from_millis(200)).is_err());
    }
}

#[test]
fn an_async_write_waits_for_the_window_without_blocking_its_thread() {
    let (_hosts, consumer, producer) = reliable_pair("async-cmd", 4, 8, ProducerQos::default());
    const COUNT: u64 = 200;
    // One runtime thread: if a write blocked it, the reader task below could not run.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .unwrap();
    let got = runtime.block_on(async move {
        let reader = tokio::task::spawn_blocking(move || {
            let mut got = Vec::new();
            while got.len() < COUNT as usize {
                got.push(consumer.recv_timeout(WAIT).unwrap().value);
                if got.len() % 40 == 0 {
                    // Stops now and then, so the window fills and the writer must wait.
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
            got
        });
        let ticks = tokio::spawn(async {
            // Runs on the same thread as the writer: counts while the writer waits.
            let mut ticks = 0u32;
            for _ in 0..100 {
                tokio::time::sleep(Duration::from_millis(2)).await;
                ticks += 1;
            }
            ticks
        });
        for i in 1..=COUNT {
            tokio::time::timeout(WAIT, producer.write_async(&i))
                .await
                .expect("the window opened")
                .unwrap();
        }
        assert_eq!(
            ticks.await.unwrap(),
            100,
            "the runtime's thread was never blocked"
        );
        reader.await.unwrap()
    });
    assert_eq!(got, (1..=COUNT).collect::<Vec<_>>());
}

/// A kept sample too large for one datagram (fragmented) reaches every reliable consumer that
/// joins later, each on a participant of its own, however many joined before it.
#[test]
fn late_joiners_get_a_kept_fragmented_sample() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let writer_side = participant(&config);
    let producer = writer_side
        .producer::<Vec<u8>>(
            "latched/large",
            ProducerQos {
                reliability: reliable(16),
                late_joiners: 1,
                ..ProducerQos::default()
            },
        )
        .unwrap();
    let sample: Vec<u8> = (0..40_000u32).map(|i| (i % 251) as u8).collect();
    producer.write(&sample).unwrap();
    for joiner in 0..8 {
        let reader_side = participant(&config);
        let consumer = reader_side
            .consumer::<Vec<u8>>(
                "latched/large",
                ConsumerQos {
                    reliability: reliable(4),
                    ..ConsumerQos::default()
                },
            )
            .unwrap();
        let got = consumer
            .recv_timeout(WAIT)
            .unwrap_or_else(|e| panic!("joiner {joiner}: the kept sample: {e}"));
        assert_eq!(got.value, sample, "joiner {joiner}");
    }
}

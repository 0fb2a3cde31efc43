//! Publish/subscribe through the SDK with real daemons (embedded, in this process) on
//! loopback: one daemon shared by two participants, and two daemons standing for two hosts.

mod common;

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::{eventually, participant, sibling, unique_config};
use ndds_client::{
    Batching, Consumer, ConsumerQos, DaemonConfig, EmbeddedPolicy, Event, Notification,
    Participant, Producer, ProducerQos, RecvError, TypeDescription,
};
use serde::{Deserialize, Serialize};

const WAIT: Duration = Duration::from_secs(5);

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Pose {
    x: f64,
    y: f64,
    frame: String,
    tags: BTreeMap<String, u32>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct OtherPose {
    x: f32,
}

fn pose(i: u32) -> Pose {
    Pose {
        x: f64::from(i),
        y: -f64::from(i),
        frame: format!("frame-{i}"),
        tags: BTreeMap::from([("i".to_owned(), i)]),
    }
}

#[test]
fn typed_samples_flow_between_participants_of_one_daemon() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let writer_side = participant(&config);
    let reader_side = participant(&config);
    let consumer = reader_side
        .consumer::<Pose>("arm/pose", ConsumerQos::default())
        .unwrap();
    let producer = writer_side
        .producer::<Pose>("arm/pose", ProducerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    for i in 1..=3 {
        producer.write(&pose(i)).unwrap();
    }
    for i in 1..=3 {
        let sample = consumer.recv_timeout(WAIT).unwrap();
        assert_eq!(sample.value, pose(i));
        assert_eq!(sample.info.seq, u64::from(i));
        assert_eq!(sample.info.writer.participant, writer_side.id());
    }
    assert_eq!(consumer.try_recv().unwrap_err(), RecvError::Empty);
    assert_eq!(
        consumer
            .recv_timeout(Duration::from_millis(50))
            .unwrap_err(),
        RecvError::Timeout
    );
    assert_eq!(consumer.matched().len(), 1);
}

/// `try_recv_event` is the non-blocking form of `recv_event`: it gives the queued samples and
/// notifications in the order they were queued, and `Empty` when none is left, never waiting.
#[test]
fn try_recv_event_takes_samples_and_notifications_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let writer_side = participant(&config);
    let reader_side = participant(&config);
    let consumer = reader_side
        .consumer::<u32>("events", ConsumerQos::default())
        .unwrap();
    assert_eq!(consumer.try_recv_event().unwrap_err(), RecvError::Empty);
    let producer = writer_side
        .producer::<u32>("events", ProducerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    producer.write(&7).unwrap();
    let writer = producer.guid();
    drop(producer); // the consumer is told its producer is gone

    // The sample travels over UDP, the loss through the daemon: either may come first (when
    // the loss comes first, the producer was not yet the consumer's current one).
    let mut events = Vec::new();
    assert!(
        eventually(WAIT, || {
            events.extend(std::iter::from_fn(|| consumer.try_recv_event().ok()));
            events.len() >= 2
        }),
        "{events:?}"
    );
    assert_eq!(events.len(), 2, "{events:?}");
    let sample = events.iter().find_map(|e| match e {
        Event::Sample(sample) => Some(sample),
        _ => None,
    });
    let lost = events.iter().find_map(|e| match e {
        Event::Notification(Notification::ProducerLost { writer, .. }) => Some(*writer),
        _ => None,
    });
    let sample = sample.unwrap_or_else(|| panic!("no sample: {events:?}"));
    assert_eq!((sample.value, sample.info.writer), (7, writer));
    assert_eq!(lost, Some(writer), "{events:?}");
    assert_eq!(consumer.try_recv_event().unwrap_err(), RecvError::Empty);
}

#[test]
fn samples_cross_between_two_daemons() {
    let dir = tempfile::tempdir().unwrap();
    let host_a = unique_config(dir.path(), "host-a");
    let host_b = sibling(&host_a, dir.path(), "host-b");
    let producer_side = participant(&host_a);
    let consumer_side = participant(&host_b);
    assert_ne!(
        producer_side.daemon().node,
        consumer_side.daemon().node,
        "two daemons"
    );
    let producer = producer_side
        .producer::<Pose>("arm/pose", ProducerQos::default())
        .unwrap();
    let consumer = consumer_side
        .consumer::<Pose>("arm/pose", ConsumerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    assert!(consumer.wait_for_producers(1, WAIT));
    producer.write(&pose(7)).unwrap();
    assert_eq!(consumer.recv_timeout(WAIT).unwrap().value, pose(7));

    // Daemon B sees both endpoints, the one on daemon A as remote.
    let graph = consumer_side.graph().unwrap();
    let on_topic: Vec<_> = graph
        .endpoints
        .iter()
        .filter(|e| e.info.topic == "arm/pose")
        .collect();
    assert_eq!(on_topic.len(), 2);
    assert!(
        on_topic
            .iter()
            .any(|e| e.node == producer_side.daemon().node)
    );
    assert!(
        graph
            .nodes
            .iter()
            .any(|n| n.node == producer_side.daemon().node)
    );
}

#[test]
fn closing_an_endpoint_unmatches_it_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let host_a = unique_config(dir.path(), "host-a");
    let host_b = sibling(&host_a, dir.path(), "host-b");
    let a = participant(&host_a);
    let b = participant(&host_b);
    let producer = a.producer::<u64>("count", ProducerQos::default()).unwrap();
    let consumer = b.consumer::<u64>("count", ConsumerQos::default()).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    drop(consumer);
    // Far below the 1 s lease: the withdrawal is announced, not left to decay.
    assert!(eventually(Duration::from_millis(500), || producer
        .matched()
        .is_empty()));
}

#[test]
fn different_types_on_one_topic_are_incompatible_on_both_sides() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let producer = p
        .producer::<Pose>("shared", ProducerQos::default())
        .unwrap();
    let consumer = p
        .consumer::<OtherPose>("shared", ConsumerQos::default())
        .unwrap();
    assert!(eventually(WAIT, || !producer.incompatible().is_empty()
        && !consumer.incompatible().is_empty()));
    assert!(producer.matched().is_empty());
    let seen_by_consumer = &consumer.incompatible()[0];
    assert_eq!(
        seen_by_consumer.fingerprint,
        TypeDescription::of::<Pose>().fingerprint()
    );
    assert!(seen_by_consumer.type_desc.name.ends_with("Pose"));
    producer.write(&pose(1)).unwrap();
    let err = consumer
        .recv_timeout(Duration::from_millis(200))
        .unwrap_err();
    assert!(
        matches!(&err, RecvError::TimeoutUnmatched(unmatched) if unmatched.producers.len() == 1),
        "{err:?}"
    );
}

#[test]
fn slow_consumer_keeps_the_newest_samples() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let consumer = p
        .consumer::<u32>(
            "fast",
            ConsumerQos {
                depth: 4,
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let producer = p.producer::<u32>("fast", ProducerQos::default()).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    for i in 0..20 {
        producer.write(&i).unwrap();
    }
    assert!(
        eventually(WAIT, || consumer.stats().received == 20),
        "{:?}",
        consumer.stats()
    );
    let kept: Vec<u32> = std::iter::from_fn(|| consumer.try_recv().ok().map(|s| s.value)).collect();
    assert_eq!(kept, vec![16, 17, 18, 19]);
    assert_eq!(consumer.stats().overflow, 16);
}

#[test]
fn undecodable_samples_are_skipped_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let consumer = p
        .consumer::<String>("text", ConsumerQos::default())
        .unwrap();
    let raw = p
        .raw_producer(
            "text",
            TypeDescription::of::<String>(),
            ProducerQos::default(),
        )
        .unwrap();
    assert!(raw.wait_for_consumers(1, WAIT));
    raw.write_bytes(&[0xff, 0xff, 0xff]).unwrap(); // claims a huge string: does not decode
    let good = postcard::to_allocvec(&"fine".to_owned()).unwrap();
    raw.write_bytes(&good).unwrap();
    assert_eq!(consumer.recv_timeout(WAIT).unwrap().value, "fine");
    assert_eq!(consumer.stats().decode_errors, 1);
}

#[test]
fn callback_and_stream_forms_deliver() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let producer = p.producer::<u32>("ticks", ProducerQos::default()).unwrap();

    let seen = Arc::new(Mutex::new(Vec::new()));
    let sink = seen.clone();
    let callback = p
        .consumer::<u32>("ticks", ConsumerQos::default())
        .unwrap()
        .on_sample(move |sample| sink.lock().unwrap().push(sample.value))
        .unwrap();
    let streamed = p.consumer::<u32>("ticks", ConsumerQos::default()).unwrap();
    assert!(producer.wait_for_consumers(2, WAIT));
    for i in 0..5 {
        producer.write(&i).unwrap();
    }
    assert!(eventually(WAIT, || seen.lock().unwrap().len() == 5));
    assert_eq!(*seen.lock().unwrap(), vec![0, 1, 2, 3, 4]);

    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let values: Vec<u32> = runtime.block_on(async {
        use futures_util::StreamExt;
        streamed
            .stream()
            .unwrap()
            .take(5)
            .map(|s| s.value)
            .collect()
            .await
    });
    assert_eq!(values, vec![0, 1, 2, 3, 4]);

    drop(callback);
    assert!(eventually(WAIT, || producer.matched().len() == 1));
}

#[test]
fn no_daemon_and_no_embedding_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let err = Participant::builder()
        .socket(dir.path().join("nobody.sock"))
        .embedded(EmbeddedPolicy::Never)
        .connect()
        .unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("no ndds daemon") && text.contains("nobody.sock"),
        "{text}"
    );
}

#[test]
fn participants_share_one_embedded_daemon_which_lives_until_stopped() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let first = participant(&config);
    let second = participant(&config);
    assert_eq!(first.daemon().node, second.daemon().node);
    let node = first.daemon().node;
    drop(first);
    drop(second);
    // Still serving (other processes may use it): a new participant finds the same daemon.
    assert!(config.socket.exists());
    let third = participant(&config);
    assert_eq!(third.daemon().node, node);
    assert!(ndds_client::stop_embedded_daemon(&config.socket));
    assert!(!config.socket.exists(), "socket removed on stop");
    assert!(eventually(WAIT, || !third.is_connected()));
    assert!(!ndds_client::stop_embedded_daemon(&config.socket));
}

#[test]
fn large_samples_cross_in_fragments_and_oversized_ones_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let producer = p
        .producer::<Vec<u8>>("big", ProducerQos::default())
        .unwrap();
    // Over the limit: refused whether or not a consumer is matched.
    let oversized = vec![7u8; ndds_client::DEFAULT_MAX_SAMPLE + 1];
    let err = producer.write(&oversized).unwrap_err();
    assert!(
        matches!(err, ndds_client::WriteError::TooLarge { .. }),
        "{err}"
    );
    let consumer = p
        .consumer::<Vec<u8>>("big", ConsumerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    // Larger than one datagram: cut into fragments and put back together.
    let big: Vec<u8> = (0..200_000u32).map(|i| (i % 251) as u8).collect();
    producer.write(&big).unwrap();
    assert_eq!(consumer.recv_timeout(WAIT).unwrap().value, big);
    producer.write(&vec![1, 2, 3]).unwrap();
    assert_eq!(consumer.recv_timeout(WAIT).unwrap().value, vec![1, 2, 3]);
}

#[test]
fn the_maximum_sample_size_is_configurable_on_both_sides() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let small = |bytes| {
        Participant::builder()
            .embedded(EmbeddedPolicy::Auto)
            .embedded_config(config.clone())
            .max_sample_size(bytes)
            .connect()
    };
    let err = small(10).unwrap_err();
    assert!(err.to_string().contains("outside"), "{err}");
    let writer_side = participant(&config);
    let reader_side = small(100_000).unwrap();
    let consumer = reader_side
        .consumer::<Vec<u8>>("big", ConsumerQos::default())
        .unwrap();
    let producer = writer_side
        .producer::<Vec<u8>>("big", ProducerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    // Sent (the writer allows 16 MiB) but refused piece by piece by the reader.
    producer.write(&vec![9u8; 300_000]).unwrap();
    assert!(eventually(WAIT, || reader_side.stats().fragments_refused > 0));
    assert_eq!(
        consumer
            .recv_timeout(Duration::from_millis(200))
            .unwrap_err(),
        RecvError::Timeout
    );
    // Within both limits: delivered.
    producer.write(&vec![8u8; 90_000]).unwrap();
    assert_eq!(
        consumer.recv_timeout(WAIT).unwrap().value,
        vec![8u8; 90_000]
    );
    // The writer's own limit.
    let limited = reader_side
        .producer::<Vec<u8>>("big", ProducerQos::default())
        .unwrap();
    let err = limited.write(&vec![0u8; 200_000]).unwrap_err();
    assert!(
        matches!(err, ndds_client::WriteError::TooLarge { max: 100_000, .. }),
        "{err}"
    );
}

#[test]
fn samples_written_from_two_threads_leave_in_the_order_they_were_written() {
    // A best-effort consumer judges a sample older than its writer's last one as old data
    // and drops it, so the datagrams of one producer must leave in the order the core
    // numbered them also when two threads write it at once. (Each thread takes its datagrams
    // from the core under its lock and sends them after releasing it: see
    // `batches_flushed_by_the_io_thread_and_by_the_writer_leave_in_order` for the case where
    // this was seen.)
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let (_writer_side, _reader_side, producer, consumer) =
        ordered_pair(&config, "order/two-threads", ProducerQos::default());
    const PER_THREAD: u64 = 50_000;
    std::thread::scope(|scope| {
        for thread in 0..2 {
            let producer = &producer;
            scope.spawn(move || {
                // Both writers on one CPU: the scheduler then switches between them at any
                // point, also between one taking its datagram from the core and sending it.
                pin_to_first_cpu();
                for i in 0..PER_THREAD {
                    producer.write(&(thread * PER_THREAD + i)).unwrap();
                }
            });
        }
    });
    assert_none_overtaken(&consumer);
}

#[test]
fn batches_flushed_by_the_io_thread_and_by_the_writer_leave_in_order() {
    // A batching producer's datagrams are taken from the core by two threads: the writer's
    // (a batch that filled up) and the participant's I/O thread (a batch whose delay ran out,
    // heartbeats). With every thread of both participants on one CPU, the scheduler switches
    // between them also between one taking its datagram from the core and sending it; a
    // datagram that overtook an earlier one makes the best-effort consumer drop the earlier
    // one's samples as old data. (Before datagrams left through one ordered queue, this
    // failed in 1 of 2 runs, with 736 old samples.)
    pin_to_first_cpu(); // before the participants: their threads inherit it
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let batched = ProducerQos {
        batching: Batching::On {
            max_delay: Duration::from_micros(50),
            max_bytes: 4096,
        },
        ..ProducerQos::default()
    };
    let (_writer_side, _reader_side, producer, consumer) =
        ordered_pair(&config, "order/batches", batched);
    for i in 0..300_000u64 {
        producer.write(&i).unwrap();
    }
    assert_none_overtaken(&consumer);
}

/// A producer and a best-effort consumer of `topic` (deep enough to hold every sample), in
/// two participants, matched both ways.
fn ordered_pair(
    config: &DaemonConfig,
    topic: &str,
    qos: ProducerQos,
) -> (Participant, Participant, Producer<u64>, Consumer<u64>) {
    let (writer_side, reader_side) = (participant(config), participant(config));
    let consumer = reader_side
        .consumer::<u64>(
            topic,
            ConsumerQos {
                depth: 1 << 16,
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let producer = writer_side.producer::<u64>(topic, qos).unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    assert!(consumer.wait_for_producers(1, WAIT));
    (writer_side, reader_side, producer, consumer)
}

/// Waits until nothing more arrives (loopback may drop datagrams when the socket's buffer is
/// full; it does not reorder), then checks that none was judged old data.
fn assert_none_overtaken(consumer: &Consumer<u64>) {
    let received = || consumer.stats().received;
    let mut last = received();
    while eventually(Duration::from_millis(300), || received() != last) {
        last = received();
    }
    let stats = consumer.stats();
    assert!(stats.received > 0, "{stats:?}");
    assert_eq!(stats.old_data, 0, "samples overtaken on the way: {stats:?}");
}

/// Runs the calling thread on the first CPU it may use.
fn pin_to_first_cpu() {
    // SAFETY: `set` is a plain bit set owned here; 0 names the calling thread.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        assert_eq!(
            libc::sched_getaffinity(0, size_of::<libc::cpu_set_t>(), &mut set),
            0
        );
        let first = (0..libc::CPU_SETSIZE as usize)
            .find(|cpu| libc::CPU_ISSET(*cpu, &set))
            .expect("some CPU");
        libc::CPU_ZERO(&mut set);
        libc::CPU_SET(first, &mut set);
        assert_eq!(
            libc::sched_setaffinity(0, size_of::<libc::cpu_set_t>(), &set),
            0
        );
    }
}

//! A participant survives a restart of its daemon: it reconnects on its own, declares its
//! endpoints again, and samples flow again.

mod common;

use std::time::{Duration, Instant};

use common::{eventually, sibling, unique_config};
use ndds_client::{ConsumerQos, EmbeddedPolicy, Participant, ProducerQos};
use ndds_daemon::EmbeddedDaemon;

const WAIT: Duration = Duration::from_secs(10);

fn connect(config: &ndds_client::DaemonConfig) -> Participant {
    Participant::builder()
        .socket(&config.socket)
        .embedded(EmbeddedPolicy::Never)
        .name("reconnect-test")
        .connect()
        .unwrap()
}

#[test]
fn a_participant_reconnects_to_a_restarted_daemon_and_declares_again() {
    let dir = tempfile::tempdir().unwrap();
    let host_a = unique_config(dir.path(), "a");
    let host_b = sibling(&host_a, dir.path(), "b");
    let _daemon_a = EmbeddedDaemon::start(host_a.clone()).unwrap();
    let mut daemon_b = EmbeddedDaemon::start(host_b.clone()).unwrap();
    let (pa, pb) = (connect(&host_a), connect(&host_b));
    let producer = pa
        .producer::<u64>("restart", ProducerQos::default())
        .unwrap();
    let consumer = pb
        .consumer::<u64>("restart", ConsumerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, WAIT));
    producer.write(&1).unwrap();
    assert_eq!(consumer.recv_timeout(WAIT).unwrap().value, 1);

    // The consumer's daemon goes away; its participant notices and keeps trying.
    daemon_b.stop();
    assert!(eventually(WAIT, || !pb.is_connected()));
    let restarted = Instant::now();
    let _daemon_b2 = EmbeddedDaemon::start(host_b.clone()).unwrap();
    assert!(eventually(WAIT, || pb.is_connected()), "reconnected");
    let graph = pb.graph().unwrap();
    assert!(
        graph
            .endpoints
            .iter()
            .any(|e| e.info.topic == "restart" && e.info.guid.participant == pb.id()),
        "the consumer is declared again under the same participant id"
    );
    let mut value = 1;
    let resumed = loop {
        value += 1;
        producer.write(&value).unwrap();
        if let Ok(sample) = consumer.recv_timeout(Duration::from_millis(20)) {
            break (sample.value, restarted.elapsed());
        }
        assert!(restarted.elapsed() < WAIT, "samples never resumed");
    };
    eprintln!("samples resumed {:?} after the daemon restarted", resumed.1);
    assert_eq!(consumer.matched().len(), 1);
}

#[test]
fn matches_a_new_daemon_does_not_confirm_are_dropped_after_the_grace_period() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let mut daemon = EmbeddedDaemon::start(config.clone()).unwrap();
    let (p, q) = (connect(&config), connect(&config));
    let consumer = p.consumer::<u64>("gone", ConsumerQos::default()).unwrap();
    let producer = q.producer::<u64>("gone", ProducerQos::default()).unwrap();
    assert!(consumer.wait_for_producers(1, WAIT));
    // Both sessions end with the daemon; the producer's process then leaves for good while
    // the daemon is down, so the new daemon never hears of it.
    daemon.stop();
    assert!(eventually(WAIT, || !p.is_connected()));
    drop(producer);
    drop(q);
    let _again = EmbeddedDaemon::start(config.clone()).unwrap();
    assert!(eventually(WAIT, || p.is_connected()));
    assert_eq!(
        consumer.matched().len(),
        1,
        "kept while the new daemon rediscovers"
    );
    assert!(
        eventually(ndds_client::RECONNECT_GRACE + WAIT, || consumer
            .matched()
            .is_empty()),
        "dropped after the grace period"
    );
}

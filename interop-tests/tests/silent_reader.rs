//! A reliable consumer that stops answering (its process stopped with SIGSTOP while its
//! daemon keeps it matched) no longer holds its producer up: after the reader liveness (1 s)
//! the producer's writes go back to their normal latency, and when the consumer resumes it
//! learns what it missed as lost. A real daemon and a real consumer process on loopback; the
//! bounds are generous (the rule itself is proven in virtual time in ndds-core).

use std::time::{Duration, Instant};

use interop_tests::{ClientProcess, TestDomain};
use ndds_client::{EmbeddedPolicy, Participant, ProducerQos, Reliability};
use serde::{Deserialize, Serialize};

const TOPIC: &str = "silent";
const WAIT: Duration = Duration::from_secs(10);

/// The test node's sample type (matched by its stable name and structure).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Telemetry {
    seq: u64,
    position: [f64; 3],
    label: String,
    value: i64,
}

fn sample(seq: u64) -> Telemetry {
    Telemetry {
        seq,
        position: [seq as f64, 0.5, -1.0],
        label: format!("sample {seq}"),
        value: 0,
    }
}

#[test]
fn a_stopped_reliable_consumer_stops_holding_up_its_producer() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let consumer = ClientProcess::test_node(
        &domain.socket("a"),
        &[
            "consume",
            "--topic",
            TOPIC,
            "--reliable",
            "16",
            "--depth",
            "16",
            "--count",
            "1000000",
            "--timeout",
            "60",
            "--events",
        ],
    );
    consumer.event("ready", WAIT).expect("consumer ready");
    let participant = Participant::builder()
        .socket(domain.socket("a"))
        .embedded(EmbeddedPolicy::Never)
        .connect()
        .expect("participant");
    let producer = participant
        .producer::<Telemetry>(
            TOPIC,
            ProducerQos {
                reliability: Reliability::Reliable { depth: 16 },
                write_timeout: Duration::from_secs(30),
                ..ProducerQos::default()
            },
        )
        .expect("producer");
    assert!(producer.wait_for_consumers(1, WAIT));
    let mut seq = 0;
    for _ in 0..20 {
        seq += 1;
        producer.write(&sample(seq)).expect("write");
        std::thread::sleep(Duration::from_millis(2));
    }
    consumer.event("sample", WAIT).expect("samples flow");

    consumer.stop();
    let stopped = Instant::now();
    let (mut longest_early, mut longest_late) = (Duration::ZERO, Duration::ZERO);
    while stopped.elapsed() < Duration::from_secs(6) {
        seq += 1;
        let started = Instant::now();
        producer.write(&sample(seq)).expect("no write times out");
        let took = started.elapsed();
        if started.duration_since(stopped) < Duration::from_secs(3) {
            longest_early = longest_early.max(took);
        } else {
            longest_late = longest_late.max(took);
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    consumer.resume();
    eprintln!(
        "{seq} samples written; longest write in the 3 s after the consumer stopped: \
         {longest_early:?}, in the 3 s after that: {longest_late:?}"
    );
    // The window (16) filled while the consumer was stopped: the producer waited for it,
    // up to the liveness, not for the whole write timeout.
    assert!(
        longest_early >= Duration::from_millis(300),
        "the window never closed: {longest_early:?}"
    );
    assert!(
        longest_early < Duration::from_secs(5),
        "waited about the write timeout: {longest_early:?}"
    );
    assert!(
        longest_late < Duration::from_millis(500),
        "writes are back to normal: {longest_late:?}"
    );
    // Back, the consumer learns what it missed as lost.
    let lost = consumer
        .event("notification", Duration::from_secs(20))
        .expect("a notification after resuming");
    assert_eq!(lost["kind"], "SamplesLost", "{lost}");
}

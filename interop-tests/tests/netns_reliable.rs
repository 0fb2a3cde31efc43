//! Reliable streams and large samples across hosts: a reliable stream through 20 % loss
//! delivers every sample in order, and a 16 MiB sample crosses hosts best-effort and reliable
//! (also through loss). Real daemons and test nodes on hosts simulated with network namespaces
//! (needs root, `ip` and `nft`); loss is dropped by nftables on the receiving host.

mod support;

use std::time::{Duration, Instant};

use interop_tests::ClientProcess;
use interop_tests::netns::Cluster;
use serde_json::Value;
use support::{exclusive, field, node, notifications, read_until, samples};

const A: usize = 0;
const B: usize = 1;

/// The largest payload of a `blob` sample that stays within the default 16 MiB sample limit
/// once encoded (sequence number, value and length prefix take a few bytes).
const SIXTEEN_MIB_PAYLOAD: usize = 16 * 1024 * 1024 - 32;

/// Reads `consumer`'s lines until its `done` line (or `timeout`); returns every line.
fn until_done(consumer: &ClientProcess, timeout: Duration) -> Vec<Value> {
    let (done, mut lines) = read_until(consumer, timeout, |l| l["event"] == "done");
    let done = done.unwrap_or_else(|| panic!("the consumer did not finish: {lines:?}"));
    lines.push(done);
    lines
}

#[test]
fn a_reliable_stream_through_20_percent_loss_delivers_everything_in_order() {
    if support::skipped() {
        return;
    }
    const COUNT: u64 = 2000;
    let _turn = exclusive();
    let cluster = Cluster::new(2);
    cluster.network().drop_incoming(B, 20);
    let consumer = node(
        &cluster,
        B,
        &[
            "consume",
            "--topic",
            "commands",
            "--reliable",
            "256",
            "--count",
            &COUNT.to_string(),
            "--timeout",
            "30",
            "--events",
        ],
    );
    let started = Instant::now();
    let _producer = node(
        &cluster,
        A,
        &[
            "produce",
            "--topic",
            "commands",
            "--reliable",
            "256",
            "--rate",
            "2000",
            "--count",
            &COUNT.to_string(),
            "--wait-consumers",
            "1",
            "--wait-timeout",
            "30",
            "--linger",
            "60",
        ],
    );
    let lines = until_done(&consumer, Duration::from_secs(90));
    let elapsed = started.elapsed();
    let seqs: Vec<u64> = samples(&lines).iter().map(|s| field(s, "seq")).collect();
    let dropped = cluster.host(B).dropped_packets();
    eprintln!(
        "{} samples in {elapsed:?} through 20 % loss; {dropped} datagrams dropped at the receiver",
        seqs.len()
    );
    assert_eq!(seqs, (1..=COUNT).collect::<Vec<_>>(), "all, in order, once");
    assert!(notifications(&lines, "SamplesLost").is_empty());
    assert!(dropped > COUNT / 10, "the loss was real: {dropped} dropped");
}

/// A single 16 MiB sample from host A to host B with the given extra producer and consumer
/// arguments; returns its `sample` line and the time from the write to its arrival.
fn sixteen_mib(cluster: &Cluster, topic: &str, extra: &[&str]) -> (Value, Duration) {
    let mut consume = vec![
        "--type",
        "blob",
        "consume",
        "--topic",
        topic,
        "--count",
        "1",
        "--timeout",
        "60",
        "--events",
    ];
    consume.extend_from_slice(extra);
    let consumer = node(cluster, B, &consume);
    let payload = SIXTEEN_MIB_PAYLOAD.to_string();
    let mut produce = vec![
        "--type",
        "blob",
        "produce",
        "--topic",
        topic,
        "--payload",
        &payload,
        "--count",
        "1",
        "--rate",
        "1",
        "--wait-consumers",
        "1",
        "--wait-timeout",
        "30",
        "--linger",
        "60",
    ];
    produce.extend_from_slice(extra);
    let producer = node(cluster, A, &produce);
    producer
        .event("matched", Duration::from_secs(30))
        .expect("the producer matched the consumer");
    let written = Instant::now();
    let lines = until_done(&consumer, Duration::from_secs(90));
    let took = written.elapsed();
    let got = samples(&lines);
    assert_eq!(got.len(), 1, "{lines:?}");
    (got[0].clone(), took)
}

#[test]
fn a_16_mib_sample_crosses_hosts_best_effort_and_reliable() {
    if support::skipped() {
        return;
    }
    let _turn = exclusive();
    let cluster = Cluster::new(2);
    let check = |sample: &Value| {
        assert_eq!(field(sample, "seq"), 1);
        assert_eq!(field(sample, "len"), SIXTEEN_MIB_PAYLOAD as u64);
        assert_eq!(sample["intact"], true, "every byte as written");
    };
    let (sample, took) = sixteen_mib(&cluster, "frames/best-effort", &[]);
    eprintln!("best effort: 16 MiB in {took:?}");
    check(&sample);
    let (sample, took) = sixteen_mib(&cluster, "frames/reliable", &["--reliable", "4"]);
    eprintln!("reliable: 16 MiB in {took:?}");
    check(&sample);
    // Through 10 % loss, every lost piece is asked for again until the sample is whole.
    cluster.network().drop_incoming(B, 10);
    let (sample, took) = sixteen_mib(&cluster, "frames/reliable-lossy", &["--reliable", "4"]);
    let dropped = cluster.host(B).dropped_packets();
    eprintln!("reliable through 10 % loss: 16 MiB in {took:?}, {dropped} datagrams dropped");
    check(&sample);
    assert!(dropped > 500, "the loss was real: {dropped} dropped");
}

/// An outage longer than the lease: discovery drops the producer (`ProducerLost`), and when
/// the hosts can reach each other again the reliable consumer resumes the same producer's
/// stream and gets `SamplesLost { from, to }` for exactly what it missed: every sample seq
/// is either delivered once or inside a reported loss, never both, never neither.
#[test]
fn after_an_outage_longer_than_the_lease_a_reliable_consumer_reports_exactly_what_it_missed() {
    if support::skipped() {
        return;
    }
    const COUNT: u64 = 700;
    let _turn = exclusive();
    let cluster = Cluster::new(2);
    let consumer = node(
        &cluster,
        B,
        &[
            "consume",
            "--topic",
            "outage",
            "--reliable",
            "64",
            "--count",
            "1000000",
            "--timeout",
            "20",
            "--duration",
            "30",
            "--events",
        ],
    );
    let producer = node(
        &cluster,
        A,
        &[
            "produce",
            "--topic",
            "outage",
            "--reliable",
            "64",
            "--rate",
            "100",
            "--count",
            &COUNT.to_string(),
            "--wait-consumers",
            "1",
            "--wait-timeout",
            "30",
            "--linger",
            "5",
        ],
    );
    producer
        .event("matched", Duration::from_secs(30))
        .expect("matched");
    let (first, mut lines) = read_until(&consumer, Duration::from_secs(30), |l| {
        l["event"] == "sample" && field(l, "seq") >= 100
    });
    lines.push(first.expect("samples flow"));
    // Three seconds apart: three leases.
    cluster.network().partition(&[A], &[B]);
    let (lost, rest) = read_until(&consumer, Duration::from_secs(20), |l| {
        l["event"] == "notification" && l["kind"] == "ProducerLost"
    });
    lines.extend(rest);
    lines.push(lost.expect("discovery lost the producer"));
    std::thread::sleep(Duration::from_secs(2));
    cluster.network().heal();
    let (last, rest) = read_until(&consumer, Duration::from_secs(40), |l| {
        l["event"] == "sample" && field(l, "seq") == COUNT
    });
    lines.extend(rest);
    lines.push(last.expect("the stream resumed to the end"));
    let delivered: Vec<u64> = samples(&lines).iter().map(|s| field(s, "seq")).collect();
    let losses: Vec<(u64, u64)> = notifications(&lines, "SamplesLost")
        .iter()
        .map(|n| (field(n, "from"), field(n, "to")))
        .collect();
    eprintln!(
        "{} samples delivered, losses reported: {losses:?}",
        delivered.len()
    );
    assert!(!losses.is_empty(), "the outage's samples are reported lost");
    let mut covered: Vec<u64> = delivered.clone();
    for (from, to) in &losses {
        covered.extend(*from..*to);
    }
    covered.sort_unstable();
    assert_eq!(
        covered,
        (1..=COUNT).collect::<Vec<_>>(),
        "each seq delivered once or reported lost, none both"
    );
    let mut sorted = delivered.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, delivered, "in order");
}

//! Recording across hosts through loss: a best-effort stream from host A recorded on host B,
//! which drops 10 % of what arrives (nftables). The recorder counts every sequence number that
//! never arrived, in its summary and in the file's metadata, so what it wrote plus what it
//! says it lost is what was sent.

mod support;

use std::time::Duration;

use interop_tests::netns::Cluster;
use support::{exclusive, node};

const A: usize = 0;
const B: usize = 1;

#[test]
fn a_recording_through_loss_counts_every_lost_sample() {
    if support::skipped() {
        return;
    }
    const COUNT: u64 = 1000;
    let _turn = exclusive();
    let cluster = Cluster::new(2);
    cluster.network().drop_incoming(B, 10);
    let bag = cluster.domain().path("lossy.mcap");
    let bag_text = bag.display().to_string();
    let recorder = cluster.host(B).exec(interop_tests::binary("ndds"));
    let mut recorder = recorder;
    recorder.args([
        "--socket",
        &cluster.socket(B).display().to_string(),
        "record",
        "telemetry",
        "-o",
        &bag_text,
        "--duration",
        "8",
        "--summary-json",
    ]);
    let recording = std::thread::spawn(move || {
        interop_tests::process::run_command(recorder, Duration::from_secs(30))
    });
    // The producer waits for the recorder's consumer, then writes 1000 samples at 500 Hz.
    let _producer = node(
        &cluster,
        A,
        &[
            "produce",
            "--topic",
            "telemetry",
            "--rate",
            "500",
            "--count",
            &COUNT.to_string(),
            "--wait-consumers",
            "1",
            "--wait-timeout",
            "10",
            "--linger",
            "10",
        ],
    );
    let out = recording.join().expect("the recorder's thread");
    assert_eq!(out.code, Some(0), "ndds record: {}", out.stderr);
    let summary: serde_json::Value = serde_json::from_str(out.stdout.trim()).expect("summary");
    let dropped = cluster.host(B).dropped_packets();
    // What the file holds, read back here: the producer's sequence numbers.
    let mut reader = ndds_bag::BagReader::open(&bag).unwrap();
    let mut seqs = Vec::new();
    while let Some(message) = reader.next_message().unwrap() {
        seqs.push(u64::from(message.sequence));
    }
    let info = ndds_bag::BagInfo::read(&bag).unwrap();
    let lost = info.topics["telemetry"].lost;
    let (first, last) = (seqs[0], *seqs.last().unwrap());
    println!(
        "recording through 10 % loss: {} recorded, {} counted lost (gaps), seqs {first}..={last}, \
         {dropped} datagrams dropped by nft; summary {summary}",
        seqs.len(),
        lost.gaps
    );
    assert!(dropped > 0, "the loss was applied");
    assert!(lost.gaps > 0, "some samples were lost and counted");
    assert!(
        seqs.windows(2).all(|w| w[0] < w[1]),
        "in order, no duplicates"
    );
    // Recorded plus counted lost covers every seq from the first heard to the last heard.
    assert_eq!(seqs.len() as u64 + lost.gaps, last - first + 1);
    assert_eq!(summary["lost"], lost.total(), "summary and file agree");
    assert_eq!(lost.overflow, 0);
    // Only the edges can be unaccounted for (lost before the first or after the last heard).
    assert!(last - first + 1 >= COUNT - 20, "{first}..={last}");
}

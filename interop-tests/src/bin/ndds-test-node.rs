//! `ndds-test-node`: a small control program for the interop tests. It connects to the
//! daemon named by `NDDS_SOCKET`, and produces or consumes `Telemetry` samples, reporting
//! what happens as JSON lines on stdout (`{"event": ...}`).

use std::time::{Duration, Instant};

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use ndds_client::{ConsumerQos, Participant, ProducerQos, RecvError};
use serde::{Deserialize, Serialize};
use serde_json::json;

/// The sample type of the interop tests.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Telemetry {
    seq: u64,
    position: [f64; 3],
    label: String,
}

#[derive(Debug, Parser)]
struct Cli {
    #[command(subcommand)]
    role: Role,
}

#[derive(Debug, Subcommand)]
enum Role {
    /// Write `Telemetry` samples at a rate.
    Produce {
        #[arg(long)]
        topic: String,
        #[arg(long, default_value_t = 100.0)]
        rate: f64,
        /// Stop after this many samples (default: run until killed).
        #[arg(long)]
        count: Option<u64>,
        /// Before writing, wait until this many consumers are matched (reported as a
        /// `matched` event; exits with an error after `--wait-timeout`).
        #[arg(long, default_value_t = 0)]
        wait_consumers: usize,
        /// Seconds `--wait-consumers` may take.
        #[arg(long, default_value_t = 10.0)]
        wait_timeout: f64,
    },
    /// Read `Telemetry` samples and print each one.
    Consume {
        #[arg(long)]
        topic: String,
        /// Stop after this many samples.
        #[arg(long, default_value_t = 10)]
        count: u64,
        /// Give up after this many seconds without a sample.
        #[arg(long, default_value_t = 10.0)]
        timeout: f64,
    },
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let participant = Participant::connect().context("connect to the test daemon")?;
    match cli.role {
        Role::Produce {
            topic,
            rate,
            count,
            wait_consumers,
            wait_timeout,
        } => {
            let wait = (wait_consumers, Duration::from_secs_f64(wait_timeout));
            produce(&participant, &topic, rate, count, wait)
        }
        Role::Consume {
            topic,
            count,
            timeout,
        } => consume(&participant, &topic, count, timeout),
    }
}

fn emit(value: serde_json::Value) {
    println!("{value}");
}

fn produce(
    participant: &Participant,
    topic: &str,
    rate: f64,
    count: Option<u64>,
    (wait_consumers, wait_timeout): (usize, Duration),
) -> anyhow::Result<()> {
    let producer = participant.producer::<Telemetry>(topic, ProducerQos::default())?;
    emit(json!({"event": "ready", "pid": std::process::id()}));
    if wait_consumers > 0 {
        let waited = Instant::now();
        anyhow::ensure!(
            producer.wait_for_consumers(wait_consumers, wait_timeout),
            "fewer than {wait_consumers} consumers matched within {wait_timeout:?}"
        );
        emit(json!({
            "event": "matched",
            "consumers": producer.matched().len(),
            "waited_ms": waited.elapsed().as_secs_f64() * 1000.0,
        }));
    }
    let period = Duration::from_secs_f64(1.0 / rate.max(0.001));
    let start = Instant::now();
    let mut seq = 0;
    while count.is_none_or(|count| seq < count) {
        seq += 1;
        let sample = Telemetry {
            seq,
            position: [seq as f64, 0.5, -1.0],
            label: format!("sample {seq}"),
        };
        producer.write(&sample)?;
        let due = start + period.mul_f64(seq as f64);
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
    }
    emit(json!({"event": "done", "sent": seq}));
    Ok(())
}

fn consume(participant: &Participant, topic: &str, count: u64, timeout: f64) -> anyhow::Result<()> {
    let declared = Instant::now();
    let consumer = participant.consumer::<Telemetry>(topic, ConsumerQos::default())?;
    emit(json!({"event": "ready", "pid": std::process::id()}));
    let mut received = 0;
    while received < count {
        match consumer.recv_timeout(Duration::from_secs_f64(timeout)) {
            Ok(sample) => {
                received += 1;
                let mut line = json!({
                    "event": "sample",
                    "seq": sample.value.seq,
                    "position": sample.value.position,
                    "label": sample.value.label,
                    "writer_pid_participant": sample.info.writer.participant,
                });
                if received == 1 {
                    line["since_declare_ms"] = json!(declared.elapsed().as_secs_f64() * 1000.0);
                }
                emit(line);
            }
            Err(RecvError::Timeout) => break,
            Err(err) => return Err(err.into()),
        }
    }
    emit(json!({"event": "done", "received": received}));
    Ok(())
}

//! The quickstart: a producer of a changing value and a consumer printing it, in one program.
//!
//! ```text
//! cargo run -p ndds-client --example quickstart            # runs 60 s
//! cargo run -p ndds-client --example quickstart -- 0       # runs until Ctrl-C
//! ```
//!
//! With no daemon running it starts an embedded one (on loopback), so a second terminal can
//! watch it: `cargo run -p ndds-cli -- topics`, `cargo run -p ndds-cli -- echo demo/wave`.

use std::time::{Duration, Instant};

use ndds_client::{ConsumerQos, Participant, ProducerQos};
use serde::{Deserialize, Serialize};

/// The sample type: a sine wave with its time and a label.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Wave {
    t: f64,
    value: f64,
    label: String,
}

const TOPIC: &str = "demo/wave";
const RATE_HZ: f64 = 10.0;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seconds: u64 = match std::env::args().nth(1) {
        Some(arg) => arg
            .parse()
            .map_err(|_| format!("seconds expected, got {arg:?}"))?,
        None => 60,
    };
    let participant = Participant::connect()?;
    let daemon = participant.daemon();
    println!(
        "connected to the daemon of domain {} on {} (pid {})",
        daemon.domain, daemon.hostname, daemon.pid
    );
    println!("in another terminal: cargo run -p ndds-cli -- topics");
    println!("                     cargo run -p ndds-cli -- echo {TOPIC}");

    let created = Instant::now();
    let consumer = participant.consumer::<Wave>(TOPIC, ConsumerQos::default())?;
    let printer = consumer.on_sample(move |sample| {
        let age = sample
            .info
            .reception_timestamp
            .duration_since(sample.info.source_timestamp)
            .unwrap_or_default();
        let first = if sample.info.seq == 1 {
            format!(
                "  (first sample {:.1} ms after the consumer was created)",
                created.elapsed().as_secs_f64() * 1e3
            )
        } else {
            String::new()
        };
        println!(
            "#{:<4} t={:6.2}s value={:+.3} {}  latency {:?}{first}",
            sample.info.seq, sample.value.t, sample.value.value, sample.value.label, age
        );
    })?;

    let producer = participant.producer::<Wave>(TOPIC, ProducerQos::default())?;
    producer.wait_for_consumers(1, Duration::from_secs(2));
    let start = Instant::now();
    let period = Duration::from_secs_f64(1.0 / RATE_HZ);
    for i in 0u64.. {
        let t = i as f64 / RATE_HZ;
        if seconds > 0 && t >= seconds as f64 {
            break;
        }
        let value = (t * std::f64::consts::TAU / 5.0).sin();
        let label = if value >= 0.0 { "up" } else { "down" };
        producer.write(&Wave {
            t,
            value,
            label: label.to_owned(),
        })?;
        std::thread::sleep(
            (start + period.mul_f64((i + 1) as f64)).saturating_duration_since(Instant::now()),
        );
    }
    drop(printer);
    println!("done: {} samples written", producer.written());
    // Say goodbye to the domain now rather than leaving a stale socket behind.
    ndds_client::stop_embedded_daemons();
    Ok(())
}

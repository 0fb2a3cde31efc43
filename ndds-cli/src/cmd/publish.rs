//! `ndds pub TOPIC JSON`: publish a value, once or at a rate.

use std::time::{Duration, Instant};

use anyhow::Context as _;
use ndds_client::{ProducerQos, TypeDescription};
use ndds_core::dynamic;

use crate::builtin;
use crate::cmd::echo::wait_for_type;
use crate::connect::{DaemonArgs, connect};

/// Options of `ndds pub`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Topic name.
    topic: String,
    /// The value, as JSON (the format `ndds echo` prints).
    value: String,
    /// Publish at this rate in Hz (default: once, unless --count is given).
    #[arg(long)]
    rate: Option<f64>,
    /// Number of samples [default: 1 without --rate, unlimited with it].
    #[arg(long)]
    count: Option<u64>,
    /// Use a built-in type instead of the topic's type from discovery.
    #[arg(long = "type", value_name = "TYPE")]
    type_name: Option<String>,
    /// Choose among incompatible types on the topic by fingerprint.
    #[arg(long)]
    fingerprint: Option<String>,
    /// Seconds to wait for a matching consumer before the first sample.
    #[arg(long, default_value_t = 2.0)]
    wait: f64,
    /// Producer strength.
    #[arg(long, default_value_t = 0)]
    strength: i32,
}

/// Runs `ndds pub`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let value: serde_json::Value =
        serde_json::from_str(&args.value).context("the value is not valid JSON")?;
    let participant = connect(daemon)?;
    let desc = match &args.type_name {
        Some(name) => builtin::describe(name).with_context(|| {
            format!(
                "unknown built-in type {name:?} (built-in: {})",
                builtin::list()
            )
        })?,
        None => wait_for_type(&args.topic, args.fingerprint.as_deref(), 0.0, || {
            Ok(participant.graph()?)
        })
        .context("pass --type to publish a built-in type on a new topic")?,
    };
    let payload = encode(&desc, &value)?;
    let qos = ProducerQos {
        strength: args.strength,
        ..ProducerQos::default()
    };
    let producer = participant.raw_producer(&args.topic, desc, qos)?;
    if !producer.wait_for_consumers(1, Duration::from_secs_f64(args.wait.max(0.0))) {
        eprintln!(
            "ndds: no consumer of {:?} matched yet; publishing anyway",
            args.topic
        );
    }
    let count = args
        .count
        .unwrap_or(if args.rate.is_some() { u64::MAX } else { 1 });
    let period = match args.rate {
        Some(hz) if hz > 0.0 && hz.is_finite() => Duration::from_secs_f64(1.0 / hz),
        Some(hz) => anyhow::bail!("--rate must be a positive number of Hz, got {hz}"),
        None => Duration::ZERO,
    };
    let start = Instant::now();
    for i in 0..count {
        if i > 0 {
            let due = start + period.mul_f64(i as f64);
            std::thread::sleep(due.saturating_duration_since(Instant::now()));
        }
        producer.write_bytes(&payload)?;
    }
    eprintln!(
        "ndds: published {} sample(s) on {:?}",
        producer.written(),
        args.topic
    );
    Ok(())
}

fn encode(desc: &TypeDescription, value: &serde_json::Value) -> anyhow::Result<Vec<u8>> {
    let layout = desc.layout.as_ref().with_context(|| {
        format!(
            "type {} is opaque (not traceable): it cannot be built from JSON",
            desc.name
        )
    })?;
    dynamic::encode_json(layout, value)
        .with_context(|| format!("the value does not fit type {}", desc.name))
}

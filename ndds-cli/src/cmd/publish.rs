//! `ndds pub TOPIC JSON`: publish a value, once or at a rate.

use std::time::{Duration, Instant};

use anyhow::Context as _;
use ndds_client::{ProducerQos, RawProducer, Reliability, TypeDescription};
use ndds_core::dynamic;
use ndds_core::types::fingerprint_hex;

use crate::builtin;
use crate::cmd::echo::wait_for_type;
use crate::connect::{DaemonArgs, connect};
use crate::seconds;

/// Options of `ndds pub`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Topic name.
    topic: String,
    /// The value, as JSON (the format `ndds echo` prints).
    value: String,
    /// Publish at this rate in Hz (default: once, unless --count is given).
    #[arg(long, value_parser = seconds::parse_rate, value_name = "HZ")]
    rate: Option<Duration>,
    /// Number of samples [default: 1 without --rate, unlimited with it].
    #[arg(long)]
    count: Option<u64>,
    /// Use a built-in type instead of the topic's type from discovery.
    #[arg(long = "type", value_name = "TYPE")]
    type_name: Option<String>,
    /// Choose among incompatible types on the topic by fingerprint.
    #[arg(long)]
    fingerprint: Option<String>,
    /// Seconds to wait for a matching consumer before the first sample (`inf`: no limit).
    #[arg(long, value_parser = seconds::parse, default_value = "2")]
    wait: Duration,
    /// Producer strength.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    strength: i32,
    /// Publish reliably (needed by reliable consumers, e.g. a runtime's `cs/NAME/configure`):
    /// losses are repaired, and `ndds pub` waits (up to --wait, at least 1 s) until every
    /// consumer has acknowledged before it exits.
    #[arg(long)]
    reliable: bool,
}

/// Runs `ndds pub`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    // Everything that can be checked without the daemon is checked first.
    let value: serde_json::Value =
        serde_json::from_str(&args.value).context("the value is not valid JSON")?;
    let builtin = match &args.type_name {
        Some(name) => Some(builtin::describe(name).with_context(|| {
            format!(
                "unknown built-in type {name:?} (built-in: {})",
                builtin::list()
            )
        })?),
        None => None,
    };
    if let Some(desc) = &builtin {
        encode(desc, &value)?;
    }
    let participant = connect(daemon)?;
    let desc = match builtin {
        Some(desc) => desc,
        None => wait_for_type(
            &args.topic,
            args.fingerprint.as_deref(),
            Duration::ZERO,
            || Ok(participant.graph()?),
        )
        .map_err(|err| {
            anyhow::anyhow!("{err}; pass --type to publish a built-in type on a new topic")
        })?,
    };
    let payload = encode(&desc, &value)?;
    let qos = ProducerQos {
        strength: args.strength,
        reliability: if args.reliable {
            Reliability::Reliable { depth: 64 }
        } else {
            Reliability::BestEffort
        },
        ..ProducerQos::default()
    };
    let producer = participant.raw_producer(&args.topic, desc, qos)?;
    if !producer.wait_for_consumers(1, args.wait) {
        warn_unmatched(&producer, &args.topic, !args.wait.is_zero());
    }
    let count = args
        .count
        .unwrap_or(if args.rate.is_some() { u64::MAX } else { 1 });
    let period = args.rate.unwrap_or(Duration::ZERO);
    let start = Instant::now();
    for i in 0..count {
        if i > 0 {
            let due =
                start.checked_add(period.saturating_mul(u32::try_from(i).unwrap_or(u32::MAX)));
            if let Some(due) = due {
                std::thread::sleep(due.saturating_duration_since(Instant::now()));
            }
        }
        producer.write_bytes(&payload)?;
    }
    if args.reliable && !producer.wait_for_acknowledgments(args.wait.max(Duration::from_secs(1))) {
        eprintln!("ndds: not every consumer acknowledged every sample before the wait ended");
    }
    eprintln!(
        "ndds: published {} sample(s) on {:?}",
        producer.written(),
        args.topic
    );
    Ok(())
}

/// Says why nothing matched: consumers of another type, or none (when a wait was asked for).
fn warn_unmatched(producer: &RawProducer, topic: &str, waited: bool) {
    let ours = producer.type_description();
    let others = producer.incompatible();
    if let Some(other) = others.first()
        && other.fingerprint == ours.fingerprint()
    {
        eprintln!(
            "ndds: consumers of {topic:?} request reliable delivery: pass --reliable to reach them"
        );
    } else if let Some(other) = others.first() {
        eprintln!(
            "ndds: consumers of {topic:?} expect type {} ({}), not {} ({}): they will not \
             receive these samples",
            other.type_desc.name,
            fingerprint_hex(other.fingerprint),
            ours.name,
            fingerprint_hex(ours.fingerprint()),
        );
    } else if waited {
        eprintln!("ndds: no consumer of {topic:?} matched yet; publishing anyway");
    }
}

/// Encodes the JSON value as a sample of `desc`; a CSMat is also checked for consistency
/// (data length, field counts), which the layout alone cannot express.
fn encode(desc: &TypeDescription, value: &serde_json::Value) -> anyhow::Result<Vec<u8>> {
    let layout = desc.layout.as_ref().with_context(|| {
        format!(
            "type {} is opaque (not traceable): it cannot be built from JSON",
            desc.name
        )
    })?;
    let expanded;
    let value = if builtin::is_csmat(desc) {
        expanded = csmat_shorthand(value)?;
        &expanded
    } else {
        value
    };
    let payload = dynamic::encode_json(layout, value)
        .with_context(|| format!("the value does not fit type {}", desc.name))?;
    if builtin::is_csmat(desc) {
        builtin::check_csmat(&payload)?;
    }
    Ok(payload)
}

/// A CSMat may be given as a number (1 × 1), a list (a column) or a list of rows, or as the
/// full object (`name`, `rows`, `cols`, `data` row-major, and optionally `row_fields`,
/// `col_fields`).
fn csmat_shorthand(value: &serde_json::Value) -> anyhow::Result<serde_json::Value> {
    use serde_json::{Value, json};
    let number = |v: &Value| {
        v.as_f64()
            .with_context(|| format!("{v} is not a number (a CSMat holds numbers)"))
    };
    let (rows, cols, data) = match value {
        Value::Object(map) => {
            let mut map = map.clone();
            map.entry("name").or_insert_with(|| json!(""));
            map.entry("row_fields").or_insert_with(|| json!([]));
            map.entry("col_fields").or_insert_with(|| json!([]));
            return Ok(Value::Object(map));
        }
        Value::Number(_) => (1, 1, vec![number(value)?]),
        Value::Array(items) if items.iter().all(Value::is_array) && !items.is_empty() => {
            let cols = items[0].as_array().map_or(0, Vec::len);
            let mut data = Vec::new();
            for row in items {
                let row = row.as_array().map_or(&[][..], Vec::as_slice);
                anyhow::ensure!(
                    row.len() == cols,
                    "every row of a CSMat needs {cols} values, like the first"
                );
                for v in row {
                    data.push(number(v)?);
                }
            }
            (items.len(), cols, data)
        }
        Value::Array(items) => {
            let data = items
                .iter()
                .map(number)
                .collect::<anyhow::Result<Vec<_>>>()?;
            (data.len(), 1, data)
        }
        other => anyhow::bail!("{other} is not a CSMat: give a number, a list, rows or an object"),
    };
    Ok(json!({
        "name": "", "rows": rows, "cols": cols, "data": data,
        "row_fields": [], "col_fields": []
    }))
}

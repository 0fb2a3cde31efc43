//! `ndds pub TOPIC JSON`: publish a value, once or at a rate, and say whether anybody took it.
//!
//! - A runtime's configure topic (`cs/NAME/configure`) and a state machine's events topic
//!   (`fsm/NAME/events`) are commands: the value goes through the system's command port, and
//!   `ndds pub` prints what the system did or fails with its reason.
//! - On any other topic, the producer's reliability follows the consumers (reliable when one
//!   asks for it), and nothing is sent when no consumer can take the sample: none matched, they
//!   expect another type, or (for a CSMat a runtime subscribes) another shape. `--force`
//!   publishes all the same.

use std::time::{Duration, Instant};

use anyhow::Context as _;
use ndds_client::ports::PortUser;
use ndds_client::{Participant, ProducerQos, RawProducer, Reliability, TypeDescription};
use ndds_core::dynamic;
use ndds_core::ipc::Graph;
use ndds_core::types::fingerprint_hex;
use ndds_core::wire::{EndpointKind, EndpointQos};
use ndds_runtime::fsm::{CommandReply, Stimulus};
use ndds_runtime::{CsMat, RuntimeCommand, command_port};

use crate::builtin;
use crate::cmd::echo::wait_for_type;
use crate::cmd::fsm;
use crate::connect::{DaemonArgs, connect};
use crate::seconds;

/// Options of `ndds pub`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Topic name.
    topic: String,
    /// The value, as JSON (the format `ndds echo` prints); a string needs its quotes:
    /// '"JointPD"'.
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
    /// Seconds to wait for a consumer that can take the sample, and for commands and
    /// acknowledgments (`inf`: no limit).
    #[arg(long, value_parser = seconds::parse, default_value = "2")]
    wait: Duration,
    /// Producer strength.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    strength: i32,
    /// Publish reliably (the default when a consumer of the topic asks for it): losses are
    /// repaired, and `ndds pub` waits (up to --wait, at least 1 s) until every consumer has
    /// acknowledged, failing if one did not.
    #[arg(long, conflicts_with = "best_effort")]
    reliable: bool,
    /// Publish a plain topic best-effort even where its consumers ask for reliable delivery
    /// (they cannot take it, so this needs --force); a command topic is not affected.
    #[arg(long)]
    best_effort: bool,
    /// Fire and forget: publish as a plain sample even on a command topic, and even when no
    /// consumer can take it (none matched, another type, another shape).
    #[arg(long)]
    force: bool,
}

/// Runs `ndds pub`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    // Everything that can be checked without the daemon is checked first.
    let value = parse_json(&args.value)?;
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
    if !args.force
        && let Some(reply) = command(&participant, args, &value)?
    {
        return match reply {
            Ok(done) => {
                for line in done.lines() {
                    eprintln!("ndds: {line}");
                }
                Ok(())
            }
            Err(refused) => anyhow::bail!("{refused}"),
        };
    }
    let desc = match builtin {
        Some(desc) => desc,
        None => wait_for_type(
            &args.topic,
            args.fingerprint.as_deref(),
            Duration::ZERO,
            || Ok(participant.graph()?),
        )
        .map_err(|err| {
            if let Some(system) = runtime_of(&args.topic).or_else(|| machine_of(&args.topic)) {
                anyhow::anyhow!(
                    "no system `{system}` runs in this domain to take {:?} (nothing owns its \
                     command port); `ndds topics` lists what runs",
                    args.topic
                )
            } else {
                anyhow::anyhow!("{err}; pass --type to publish a built-in type on a new topic")
            }
        })?,
    };
    let payload = encode(&desc, &value)?;
    let graph = participant.graph()?;
    let reliable =
        args.reliable || (!args.best_effort && consumers_want_reliable(&graph, &args.topic, &desc));
    let qos = ProducerQos {
        strength: args.strength,
        reliability: if reliable {
            Reliability::Reliable { depth: 64 }
        } else {
            Reliability::BestEffort
        },
        ..ProducerQos::default()
    };
    let producer = participant.raw_producer(&args.topic, desc.clone(), qos)?;
    if !producer.wait_for_consumers(1, args.wait) {
        let why = unmatched(&producer, &args.topic, args.wait);
        anyhow::ensure!(
            args.force,
            "{why}; nothing was sent (--force publishes anyway)"
        );
        eprintln!("ndds: {why}; publishing anyway (--force)");
    } else if builtin::is_csmat(&desc) && !args.force {
        let refusals = shape_refusals(&participant, &producer, &args.topic, &payload, args.wait);
        anyhow::ensure!(
            refusals.is_empty(),
            "{}; nothing was sent (--force publishes anyway)",
            refusals.join("; ")
        );
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
    let consumers = producer.matched().len();
    if reliable {
        let wait = args.wait.max(Duration::from_secs(1));
        anyhow::ensure!(
            producer.wait_for_acknowledgments(wait),
            "published {} sample(s) on {:?}, but not every one of its {consumers} consumer(s) \
             acknowledged them within {wait:?}",
            producer.written(),
            args.topic
        );
        eprintln!(
            "ndds: published {} sample(s) on {:?}; {consumers} consumer(s) acknowledged receiving \
             them{}",
            producer.written(),
            args.topic,
            if args.force {
                " (with --force, what a system did with them is not asked)"
            } else {
                ""
            }
        );
    } else {
        eprintln!(
            "ndds: published {} sample(s) on {:?} to {consumers} consumer(s) (best-effort: \
             delivery is not confirmed)",
            producer.written(),
            args.topic
        );
    }
    Ok(())
}

/// The value as JSON; a bare word is most often a string whose quotes the shell ate.
fn parse_json(text: &str) -> anyhow::Result<serde_json::Value> {
    serde_json::from_str(text).map_err(|err| {
        let word = !text.is_empty()
            && text
                .chars()
                .all(|c| c.is_alphanumeric() || "_-.=/:".contains(c));
        if word {
            anyhow::anyhow!(
                "the value is not valid JSON ({err}): a JSON string needs quotes, and the shell \
                 removes one pair, so write '\"{text}\"'"
            )
        } else {
            anyhow::anyhow!("the value is not valid JSON: {err}")
        }
    })
}

/// A command topic whose system owns a command port: sends the value through the port and
/// returns the system's answer. `None` when the topic is no command topic, or no system owns
/// its port (then it is published as a plain sample).
fn command(
    participant: &Participant,
    args: &Args,
    value: &serde_json::Value,
) -> anyhow::Result<Option<CommandReply>> {
    let topic = args.topic.as_str();
    let once = || {
        anyhow::ensure!(
            args.rate.is_none() && args.count.is_none_or(|c| c == 1),
            "{topic:?} is a command topic: a command is sent once (--force publishes samples \
             instead)"
        );
        Ok(())
    };
    if let Some(system) = runtime_of(topic)
        && owned(participant, &command_port(system))?
    {
        once()?;
        let name = value.as_str().with_context(|| {
            format!("{topic:?} takes a configuration name as a JSON string, like '\"JointPD\"'")
        })?;
        let user = PortUser::<RuntimeCommand, CommandReply>::declare(
            participant,
            &command_port(system),
            "ndds",
        )?;
        let reply = user
            .send(&RuntimeCommand::Configure(name.to_owned()), args.wait)
            .with_context(|| format!("system `{system}` did not answer"))?;
        return Ok(Some(reply));
    }
    if let Some(machine) = machine_of(topic)
        && owned(participant, &ndds_runtime::fsm::command_port(machine))?
    {
        once()?;
        let stimulus = match value {
            serde_json::Value::String(text) => Stimulus::parse(text),
            other => serde_json::from_value(other.clone()).with_context(|| {
                format!(
                    "{topic:?} takes a stimulus: '\"NAME\"', '\"NAME=VALUE\"' or \
                     '{{\"name\": \"NAME\", \"value\": null}}'"
                )
            })?,
        };
        return fsm::command(participant, machine, &[stimulus], args.wait).map(Some);
    }
    Ok(None)
}

/// The runtime whose configure topic (`cs/NAME/configure`) `topic` is.
fn runtime_of(topic: &str) -> Option<&str> {
    topic.strip_prefix("cs/")?.strip_suffix("/configure")
}

/// The machine whose events topic (`fsm/NAME/events`) `topic` is.
fn machine_of(topic: &str) -> Option<&str> {
    topic.strip_prefix("fsm/")?.strip_suffix("/events")
}

/// Whether some process in the domain owns `port`.
fn owned(participant: &Participant, port: &str) -> anyhow::Result<bool> {
    Ok(!ndds_client::ports::owners_elsewhere(participant, port)?.is_empty())
}

/// Whether a consumer of `topic` with this type asks for reliable delivery.
fn consumers_want_reliable(graph: &Graph, topic: &str, desc: &TypeDescription) -> bool {
    graph.endpoints.iter().any(|e| {
        e.info.topic == topic
            && e.info.fingerprint == desc.fingerprint()
            && matches!(
                e.info.qos,
                EndpointQos::Consumer(q) if matches!(q.reliability, Reliability::Reliable { .. })
            )
    })
}

/// Why no consumer matched: consumers of another type, ones asking for reliable delivery, or
/// none at all.
fn unmatched(producer: &RawProducer, topic: &str, waited: Duration) -> String {
    let ours = producer.type_description();
    let others = producer.incompatible();
    let consumers: Vec<_> = others
        .iter()
        .filter(|o| o.qos.kind() == EndpointKind::Consumer)
        .collect();
    if consumers
        .iter()
        .any(|o| o.fingerprint == ours.fingerprint())
    {
        return format!(
            "consumers of {topic:?} request reliable delivery, which --best-effort does not offer"
        );
    }
    if let Some(other) = consumers.first() {
        return format!(
            "consumers of {topic:?} expect type {} ({}), not {} ({}): they cannot take this sample",
            other.type_desc.shape(),
            fingerprint_hex(other.fingerprint),
            ours.shape(),
            fingerprint_hex(ours.fingerprint()),
        );
    }
    format!("no consumer of {topic:?} matched within {waited:?}")
}

/// For a CSMat: asks each runtime that consumes it (the command port owned by the consumer's
/// process) whether it takes this sample's shape; returns the refusals.
fn shape_refusals(
    participant: &Participant,
    producer: &RawProducer,
    topic: &str,
    payload: &[u8],
    wait: Duration,
) -> Vec<String> {
    let mut sample = CsMat::zeros("", 0, 0);
    if sample.decode_into(payload).is_err() {
        return Vec::new();
    }
    let Ok(graph) = participant.graph() else {
        return Vec::new();
    };
    let mut refusals = Vec::new();
    let mut asked = Vec::new();
    for consumer in producer.matched() {
        let host = graph
            .endpoints
            .iter()
            .find(|e| e.info.guid == consumer.guid)
            .map(|e| e.hostname.clone());
        let ports = graph.endpoints.iter().filter(|e| {
            e.info.pid == consumer.pid
                && Some(&e.hostname) == host.as_ref()
                && e.info.qos.kind() == EndpointKind::Producer
                && e.info.topic.starts_with("port/cs.")
                && e.info.topic.ends_with("/owner")
        });
        for owner in ports {
            let port = &owner.info.topic["port/".len()..owner.info.topic.len() - "/owner".len()];
            if asked.iter().any(|a| a == port) {
                continue;
            }
            asked.push(port.to_owned());
            let check = RuntimeCommand::CheckSample {
                topic: topic.to_owned(),
                sample: sample.clone(),
            };
            let answer =
                PortUser::<RuntimeCommand, CommandReply>::declare(participant, port, "ndds")
                    .and_then(|user| user.send(&check, wait));
            match answer {
                Ok(Err(refused)) => refusals.push(refused),
                Ok(Ok(_)) => {}
                Err(err) => eprintln!("ndds: the shape was not checked with `{port}`: {err}"),
            }
        }
    }
    refusals
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

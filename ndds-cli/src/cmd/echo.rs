//! `ndds echo TOPIC`: print a topic's samples, decoded with the type carried in discovery.
//! CSMat samples print as labelled tables unless `--json` is given.

use std::time::{Duration, SystemTime};

use ndds_client::runtime::CsMat;
use ndds_client::{ConsumerQos, RawSample, TypeDescription};
use ndds_core::dynamic;
use serde_json::{Value, json};

use crate::builtin;
use crate::connect::{DaemonArgs, connect};
use crate::seconds;
use crate::{outln, render};

/// Options of `ndds echo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Topic name.
    topic: String,
    /// Stop after this many samples.
    #[arg(long)]
    count: Option<u64>,
    /// One JSON object per sample (value and metadata).
    #[arg(long)]
    json: bool,
    /// Choose among incompatible types on the topic by fingerprint.
    #[arg(long)]
    fingerprint: Option<String>,
    /// Seconds to wait for the topic to appear (`inf`: no limit; 0: fail at once).
    #[arg(long, value_parser = seconds::parse, default_value = "0")]
    wait: Duration,
}

/// Runs `ndds echo`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let participant = connect(daemon)?;
    let desc = wait_for_type(&args.topic, args.fingerprint.as_deref(), args.wait, || {
        Ok(participant.graph()?)
    })?;
    let consumer = participant.raw_consumer(
        &args.topic,
        desc.clone(),
        ConsumerQos {
            depth: 1024,
            ..ConsumerQos::default()
        },
    )?;
    // A CSMat topic decodes every sample into this one matrix.
    let mut table = (!args.json && builtin::is_csmat(&desc)).then(|| CsMat::zeros("", 0, 0));
    let mut printed = 0u64;
    while args.count.is_none_or(|count| printed < count) {
        let sample = consumer.recv_raw()?;
        let text = match table.as_mut() {
            Some(mat) => mat
                .decode_into(&sample.payload)
                .map(|()| csmat_table(&args.topic, &sample, mat))
                .map_err(anyhow::Error::from),
            None => {
                decode(&desc, &sample).map(|value| line(args.json, &args.topic, &sample, value))
            }
        };
        match text {
            // A closed pipe (`ndds echo TOPIC | head`) ends the command quietly (see `out`).
            Ok(text) => outln!("{text}")?,
            Err(err) => eprintln!(
                "ndds: sample {} from {} skipped: {err}",
                sample.info.seq, sample.info.writer
            ),
        }
        printed += 1;
    }
    Ok(())
}

/// A CSMat sample: a header line `topic  name  (rows x cols)  [writer #seq]`, the labelled
/// table, and an empty line.
fn csmat_table(topic: &str, sample: &RawSample, mat: &CsMat) -> String {
    let (rows, cols) = mat.shape();
    format!(
        "{topic}  {}  ({rows} x {cols})  [{} #{}]\n{mat}\n",
        mat.name(),
        sample.info.writer,
        sample.info.seq
    )
}

/// Resolves the topic's type, retrying until `wait` seconds have passed.
pub fn wait_for_type(
    topic: &str,
    fingerprint: Option<&str>,
    wait: Duration,
    mut graph: impl FnMut() -> anyhow::Result<ndds_client::Graph>,
) -> anyhow::Result<TypeDescription> {
    let deadline = seconds::deadline(wait);
    loop {
        match render::topic_type(&graph()?, topic, fingerprint) {
            Ok(desc) => return Ok(desc),
            Err(err) if seconds::passed(deadline) => return Err(err),
            Err(_) => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

/// The sample's value as JSON; for an opaque type, `{"opaque_hex": "..."}` so it cannot be
/// mistaken for a string value.
pub fn decode(desc: &TypeDescription, sample: &RawSample) -> anyhow::Result<Value> {
    match &desc.layout {
        Some(layout) => Ok(dynamic::decode_json(layout, &sample.payload)?),
        None => {
            let hex: String = sample.payload.iter().map(|b| format!("{b:02x}")).collect();
            Ok(json!({ "opaque_hex": hex }))
        }
    }
}

fn line(as_json: bool, topic: &str, sample: &RawSample, value: Value) -> String {
    let info = &sample.info;
    if as_json {
        json!({
            "topic": topic,
            "writer": info.writer.to_string(),
            "seq": info.seq,
            "source_timestamp": seconds(info.source_timestamp),
            "reception_timestamp": seconds(info.reception_timestamp),
            "value": value,
        })
        .to_string()
    } else {
        format!("[{} #{}] {value}", info.writer, info.seq)
    }
}

fn seconds(time: SystemTime) -> f64 {
    time.duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

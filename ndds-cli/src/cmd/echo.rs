//! `ndds echo TOPIC`: print a topic's samples, decoded with the type carried in discovery.
//! CSMat samples print as labelled tables unless `--json` or `--field` is given.
//!
//! `--rate HZ` prints at most HZ samples a second, the newest of each window ([`throttle`]);
//! `--field PATH` prints one value of each sample ([`field`]).

mod field;
mod throttle;

use std::time::{Duration, Instant, SystemTime};

use ndds_client::{ConsumerQos, RawConsumer, RawEvent, RawSample, RecvError, TypeDescription};
use ndds_core::dynamic;
use ndds_runtime::CsMat;
use serde_json::{Value, json};

use self::field::FieldPath;
use self::throttle::Throttle;
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
    /// Print at most this many samples per second: the newest of each 1/HZ window.
    #[arg(long, value_name = "HZ", value_parser = seconds::parse_rate)]
    rate: Option<Duration>,
    /// Print only this field of each sample: `data`, `pose.x`, `data[1]`.
    #[arg(long, value_name = "PATH", value_parser = FieldPath::parse)]
    field: Option<FieldPath>,
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
    let mut printer = Printer {
        args,
        // A CSMat topic decodes every sample into this one matrix.
        table: (!args.json && args.field.is_none() && builtin::is_csmat(&desc))
            .then(|| CsMat::zeros("", 0, 0)),
        desc,
    };
    let mut printed = 0u64;
    let mut throttle = args.rate.map(Throttle::new);
    while args.count.is_none_or(|count| printed < count) {
        let sample = match throttle.as_mut() {
            Some(throttle) => next_due(&consumer, throttle)?,
            None => consumer.recv_raw()?,
        };
        printer.print(&sample)?;
        printed += 1;
    }
    Ok(())
}

/// Waits for the throttle's next due sample, feeding it what arrives meanwhile.
fn next_due(
    consumer: &RawConsumer,
    throttle: &mut Throttle<RawSample>,
) -> anyhow::Result<RawSample> {
    loop {
        let arrived = match throttle.poll_timeout() {
            None => Some(consumer.recv_raw()?),
            Some(due) => {
                let wait = due.saturating_duration_since(Instant::now());
                match consumer.recv_raw_event_timeout(wait) {
                    Ok(RawEvent::Sample(sample)) => Some(sample),
                    Ok(RawEvent::Notification(_)) | Err(RecvError::Timeout) => None,
                    Err(err) => return Err(err.into()),
                }
            }
        };
        let now = Instant::now();
        let due = throttle.poll_due(now);
        if let Some(sample) = arrived {
            throttle.handle_sample(now, sample);
        }
        if let Some(sample) = due {
            return Ok(sample);
        }
    }
}

/// How samples are printed: as a CSMat table, a line of text, or a JSON object.
struct Printer<'a> {
    args: &'a Args,
    desc: TypeDescription,
    table: Option<CsMat>,
}

impl Printer<'_> {
    /// Prints one sample; an undecodable one is reported on stderr and skipped, a `--field`
    /// it does not have ends the command.
    fn print(&mut self, sample: &RawSample) -> anyhow::Result<()> {
        let topic = &self.args.topic;
        let text = match self.table.as_mut() {
            Some(mat) => match mat.decode_into(&sample.payload) {
                Ok(()) => csmat_table(topic, sample, mat),
                Err(err) => {
                    skipped(sample, &err);
                    return Ok(());
                }
            },
            None => match decode(&self.desc, sample) {
                Ok(value) => self.line(sample, value)?,
                Err(err) => {
                    skipped(sample, &err);
                    return Ok(());
                }
            },
        };
        // A closed pipe (`ndds echo TOPIC | head`) ends the command quietly (see `out`).
        outln!("{text}")?;
        Ok(())
    }

    /// A decoded sample as one line: `[writer #seq] value`, only the value of `--field`, or
    /// a JSON object with the metadata (and the field's path).
    fn line(&self, sample: &RawSample, value: Value) -> anyhow::Result<String> {
        let info = &sample.info;
        let value = match &self.args.field {
            Some(path) => path
                .select(&value)
                .map_err(|err| anyhow::anyhow!("--field {}: {err}", path.as_str()))?
                .clone(),
            None => value,
        };
        if !self.args.json {
            return Ok(match self.args.field {
                Some(_) => value.to_string(),
                None => format!("[{} #{}] {value}", info.writer, info.seq),
            });
        }
        let mut object = json!({
            "topic": self.args.topic,
            "writer": info.writer.to_string(),
            "seq": info.seq,
            "source_timestamp": seconds(info.source_timestamp),
            "reception_timestamp": seconds(info.reception_timestamp),
            "value": value,
        });
        if let Some(path) = &self.args.field {
            object["field"] = json!(path.as_str());
        }
        Ok(object.to_string())
    }
}

/// Reports an undecodable sample on stderr.
fn skipped(sample: &RawSample, err: &dyn std::fmt::Display) {
    eprintln!(
        "ndds: sample {} from {} skipped: {err}",
        sample.info.seq, sample.info.writer
    );
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

fn seconds(time: SystemTime) -> f64 {
    time.duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

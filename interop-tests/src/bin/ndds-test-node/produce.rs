//! `produce`: one producer per topic, writing at a rate (or only declared, `--rate 0`), and
//! reporting consumers of another type as `incompatible` lines.

use std::collections::HashSet;
use std::time::{Duration, Instant};

use ndds_client::{Guid, Participant, Producer, ProducerQos, Reliability};
use serde_json::json;

use crate::report::{self, emit};
use crate::samples::TestSample;

/// How often the producers' incompatible consumers are looked at.
const CHECK_EVERY: Duration = Duration::from_millis(50);

/// Options of `produce`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Topic name; with `--topics N`, the prefix of `TOPIC/0` ... `TOPIC/N-1`.
    #[arg(long)]
    pub topic: String,
    /// Declare one producer on each of N topics `TOPIC/i` instead of one on `TOPIC`.
    #[arg(long)]
    pub topics: Option<usize>,
    /// Samples per second and producer; 0 declares the producers and writes nothing.
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
    /// Stop after this many samples (default: run until killed or `--max-seconds`).
    #[arg(long)]
    pub count: Option<u64>,
    /// Arbitration strength.
    #[arg(long, default_value_t = 0)]
    pub strength: i32,
    /// Persistence in milliseconds (default: the SDK's).
    #[arg(long)]
    pub persistence_ms: Option<u64>,
    /// Written in every sample, so consumers can tell producers apart.
    #[arg(long, default_value_t = 0)]
    pub value: i64,
    /// Before writing, wait until each producer has this many consumers (reported as a
    /// `matched` event; exits with an error after `--wait-timeout`).
    #[arg(long, default_value_t = 0)]
    pub wait_consumers: usize,
    /// Seconds `--wait-consumers` may take.
    #[arg(long, default_value_t = 10.0)]
    pub wait_timeout: f64,
    /// Offer reliability with a history of this many samples.
    #[arg(long)]
    pub reliable: Option<u32>,
    /// How long a reliable write may wait for a full window, in seconds.
    #[arg(long, default_value_t = 30.0)]
    pub write_timeout: f64,
    /// Seconds to stay after the last write (a reliable producer repairs meanwhile).
    #[arg(long, default_value_t = 0.0)]
    pub linger: f64,
    /// Payload bytes of each sample (`--type blob`).
    #[arg(long, default_value_t = 0)]
    pub payload: usize,
    /// Exit after this many seconds whatever happens (an orphaned node never lingers).
    #[arg(long, default_value_t = 300.0)]
    pub max_seconds: f64,
}

impl Args {
    /// The topic names to declare.
    pub fn topic_names(&self) -> Vec<String> {
        topic_names(&self.topic, self.topics)
    }

    fn qos(&self) -> ProducerQos {
        let mut qos = ProducerQos {
            strength: self.strength,
            ..ProducerQos::default()
        };
        if let Some(ms) = self.persistence_ms {
            qos.persistence = Duration::from_millis(ms);
        }
        if let Some(depth) = self.reliable {
            qos.reliability = Reliability::Reliable { depth };
        }
        qos.write_timeout = Duration::from_secs_f64(self.write_timeout.max(0.0));
        qos
    }
}

/// `TOPIC`, or `TOPIC/0` ... `TOPIC/N-1`.
pub fn topic_names(topic: &str, topics: Option<usize>) -> Vec<String> {
    match topics {
        None => vec![topic.to_owned()],
        Some(n) => (0..n).map(|i| format!("{topic}/{i}")).collect(),
    }
}

/// Runs `produce` with samples of type `T`.
pub fn run<T: TestSample>(participant: &Participant, args: &Args) -> anyhow::Result<()> {
    let started = Instant::now();
    let max = Duration::from_secs_f64(args.max_seconds.max(0.0));
    let producers = args
        .topic_names()
        .iter()
        .map(|topic| participant.producer::<T>(topic, args.qos()))
        .collect::<Result<Vec<_>, _>>()?;
    emit(json!({
        "event": "ready",
        "pid": std::process::id(),
        "participant": participant.id(),
        "producers": producers.len(),
        "strength": args.strength,
    }));
    if args.wait_consumers > 0 {
        wait_for_consumers(&producers, args)?;
    }
    let mut incompatible = Incompatible::default();
    let period = (args.rate > 0.0).then(|| Duration::from_secs_f64(1.0 / args.rate));
    let mut seq = 0;
    let mut next_check = Instant::now();
    while args.count.is_none_or(|count| seq < count) && started.elapsed() < max {
        if Instant::now() >= next_check {
            incompatible.report(&producers);
            next_check = Instant::now() + CHECK_EVERY;
        }
        let Some(period) = period else {
            std::thread::sleep(CHECK_EVERY);
            continue;
        };
        seq += 1;
        let sample = T::make(seq, args.value, args.payload);
        for producer in &producers {
            producer.write(&sample)?;
        }
        let due = started + period.mul_f64(seq as f64);
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
    }
    emit(
        json!({"event": "done", "sent": seq, "elapsed_ms": started.elapsed().as_secs_f64() * 1000.0}),
    );
    // A reliable producer stays until its consumers have everything (or `--linger` passes):
    // its history is what repairs their losses.
    let linger = Instant::now() + Duration::from_secs_f64(args.linger.max(0.0));
    while Instant::now() < linger && started.elapsed() < max {
        std::thread::sleep(CHECK_EVERY);
    }
    emit(json!({"event": "stats", "stats": report::stats(&participant.stats())}));
    Ok(())
}

fn wait_for_consumers<T: TestSample>(producers: &[Producer<T>], args: &Args) -> anyhow::Result<()> {
    let waited = Instant::now();
    let timeout = Duration::from_secs_f64(args.wait_timeout);
    for producer in producers {
        let left = timeout.saturating_sub(waited.elapsed());
        anyhow::ensure!(
            producer.wait_for_consumers(args.wait_consumers, left),
            "fewer than {} consumers of {} matched within {timeout:?}",
            args.wait_consumers,
            producer.topic()
        );
    }
    emit(json!({
        "event": "matched",
        "consumers": producers.iter().map(|p| p.matched().len()).sum::<usize>(),
        "waited_ms": waited.elapsed().as_secs_f64() * 1000.0,
    }));
    Ok(())
}

/// The incompatible consumers already reported.
#[derive(Default)]
struct Incompatible {
    reported: HashSet<(String, Guid)>,
}

impl Incompatible {
    fn report<T: TestSample>(&mut self, producers: &[Producer<T>]) {
        for producer in producers {
            for other in producer.incompatible() {
                if self
                    .reported
                    .insert((producer.topic().to_owned(), other.guid))
                {
                    let local_type = &producer.type_description().name;
                    emit(report::incompatible(producer.topic(), local_type, &other));
                }
            }
        }
    }
}

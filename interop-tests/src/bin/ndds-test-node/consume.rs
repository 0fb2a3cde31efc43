//! `consume`: one consumer per topic (a thread each), printing every sample with its status
//! and, with `--events`, every notification.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use ndds_client::{Consumer, ConsumerQos, Event, Participant, Reliability};
use serde_json::json;

use crate::produce::topic_names;
use crate::report::{self, emit};
use crate::samples::TestSample;

/// Options of `consume`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Topic name; with `--topics N`, the prefix of `TOPIC/0` ... `TOPIC/N-1`.
    #[arg(long)]
    pub topic: String,
    /// Declare one consumer on each of N topics `TOPIC/i` instead of one on `TOPIC`.
    #[arg(long)]
    pub topics: Option<usize>,
    /// Stop after this many samples (per consumer).
    #[arg(long, default_value_t = 10)]
    pub count: u64,
    /// Give up after this many seconds without a sample (with `--events`: without a sample
    /// or a notification).
    #[arg(long, default_value_t = 10.0)]
    pub timeout: f64,
    /// Stop after this many seconds whatever happens (default: 300).
    #[arg(long, default_value_t = 300.0)]
    pub duration: f64,
    /// The consumer's deadline in milliseconds ("no new data" when silent this long).
    #[arg(long)]
    pub deadline_ms: Option<u64>,
    /// Also print every notification (`{"event":"notification","kind":...}`).
    #[arg(long)]
    pub events: bool,
    /// Queue depth of each consumer.
    #[arg(long, default_value_t = 64)]
    pub depth: usize,
    /// Request reliability, holding up to this many out-of-order samples per producer.
    #[arg(long)]
    pub reliable: Option<u32>,
}

impl Args {
    fn qos(&self) -> ConsumerQos {
        ConsumerQos {
            deadline: self.deadline_ms.map(Duration::from_millis),
            depth: self.depth,
            reliability: self.reliable.map_or(Reliability::BestEffort, |depth| {
                Reliability::Reliable { depth }
            }),
            ..ConsumerQos::default()
        }
    }
}

/// What the consumers received in all.
#[derive(Default)]
struct Totals {
    samples: AtomicU64,
    notifications: AtomicU64,
}

/// Runs `consume` with samples of type `T`.
pub fn run<T: TestSample>(participant: &Participant, args: &Args) -> anyhow::Result<()> {
    let declared = Instant::now();
    let consumers = topic_names(&args.topic, args.topics)
        .iter()
        .map(|topic| participant.consumer::<T>(topic, args.qos()))
        .collect::<Result<Vec<_>, _>>()?;
    emit(json!({
        "event": "ready",
        "pid": std::process::id(),
        "participant": participant.id(),
        "consumers": consumers.len(),
    }));
    let totals = Totals::default();
    let results: Vec<anyhow::Result<()>> = std::thread::scope(|scope| {
        let threads: Vec<_> = consumers
            .iter()
            .map(|consumer| scope.spawn(|| receive(consumer, args, declared, &totals)))
            .collect();
        threads
            .into_iter()
            .map(|t| {
                t.join()
                    .unwrap_or_else(|_| Err(anyhow::anyhow!("panicked")))
            })
            .collect()
    });
    emit(json!({
        "event": "done",
        "received": totals.samples.load(Ordering::Relaxed),
        "notifications": totals.notifications.load(Ordering::Relaxed),
        "stats": report::stats(&participant.stats()),
    }));
    results.into_iter().collect()
}

/// Receives on one consumer until its count, its timeout or the duration is reached.
fn receive<T: TestSample>(
    consumer: &Consumer<T>,
    args: &Args,
    declared: Instant,
    totals: &Totals,
) -> anyhow::Result<()> {
    let topic = consumer.topic();
    let end = declared + Duration::from_secs_f64(args.duration.max(0.0));
    let timeout = Duration::from_secs_f64(args.timeout);
    let mut received = 0;
    while received < args.count {
        let wait = timeout.min(end.saturating_duration_since(Instant::now()));
        if wait.is_zero() {
            break;
        }
        let event = if args.events {
            consumer.recv_event_timeout(wait)
        } else {
            consumer.recv_timeout(wait).map(Event::Sample)
        };
        match event {
            Ok(Event::Sample(sample)) => {
                received += 1;
                totals.samples.fetch_add(1, Ordering::Relaxed);
                let mut line = report::sample(topic, sample.value.fields(), &sample.info);
                if received == 1 {
                    line["since_declare_ms"] = json!(declared.elapsed().as_secs_f64() * 1000.0);
                }
                emit(line);
            }
            Ok(Event::Notification(notification)) => {
                totals.notifications.fetch_add(1, Ordering::Relaxed);
                emit(report::notification(topic, &notification));
            }
            // Silent for `--timeout`, or the duration is over.
            Err(err) if err.is_timeout() => break,
            Err(err) => return Err(err.into()),
        }
    }
    Ok(())
}

//! What the studio watches, on threads of its own, and hands to every page: the daemon's graph
//! (polled every second), each topic's rate, each running system's description and habitat
//! statistics, each state machine's state, and the plotted topics' points; and the commands a
//! page sends (switch a configuration, set a parameter, send stimuli), through the system's
//! own ports so their answers come back.
//!
//! Pages never slow the hub down: messages go out on a broadcast channel, and a page that
//! falls behind misses messages rather than holding them up (the next network message, once a
//! second, carries the whole picture again).

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use ndds_client::ports::{CommandReply, PortUser};
use ndds_client::{
    ConsumerQos, DirectConsumer, Graph, Guid, Participant, Reliability, TypeDescription,
};
use ndds_core::types::builtin;
use ndds_runtime::describe::SystemDescription;
use ndds_runtime::fsm::{MachineState, Stimulus};
use ndds_runtime::{CsMat, HabitatStats, RuntimeCommand};
use serde_json::json;
use tokio::sync::broadcast;

use crate::network;
use crate::plot::{self, Decimator};

/// A message for the pages (JSON text).
pub type Message = Arc<str>;

/// How long commands wait for the system's answer.
const COMMAND_TIMEOUT: Duration = Duration::from_secs(5);

/// Plot buckets: 20 ms (at most 100 points per second per field).
const BUCKET_S: f64 = 0.02;

/// The studio's watcher (see the module's documentation).
pub struct Hub {
    participant: Participant,
    tx: broadcast::Sender<Message>,
    latest: Mutex<Latest>,
    plots: Mutex<BTreeMap<String, PlotTopic>>,
    ports: Mutex<HashMap<String, Arc<dyn std::any::Any + Send + Sync>>>,
    /// Measure each user topic's rate (a consumer per topic).
    rates: bool,
    /// The Foxglove WebSocket protocol's channels and subscriptions.
    foxglove: Arc<crate::foxglove::Bridge>,
    stop: AtomicBool,
}

/// The last message of each kind, for a page that connects now.
#[derive(Default)]
struct Latest {
    network: Option<Message>,
    descriptions: BTreeMap<String, Message>,
    machines: BTreeMap<String, Message>,
    stats: BTreeMap<String, Message>,
}

/// A plotted topic: its consumer, how many pages watch it, its fields' decimators.
struct PlotTopic {
    _consumer: DirectConsumer,
    watchers: usize,
    series: Arc<Mutex<Series>>,
}

#[derive(Default)]
struct Series {
    names: Vec<String>,
    decimators: Vec<Decimator>,
    error: Option<String>,
}

/// What the hub keeps of one topic's rate consumer.
struct RateMonitor {
    _consumer: DirectConsumer,
    counts: Arc<RateCounts>,
    last: (u64, Instant),
    rate: f64,
}

#[derive(Default)]
struct RateCounts {
    samples: AtomicU64,
    lost: AtomicU64,
}

fn unix_seconds(t: SystemTime) -> f64 {
    t.duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

impl Hub {
    /// A hub on `participant`; `rates`: measure each user topic's rate.
    pub fn new(participant: Participant, rates: bool) -> Arc<Self> {
        let (tx, _) = broadcast::channel(1024);
        Arc::new(Hub {
            participant: participant.clone(),
            tx,
            latest: Mutex::new(Latest::default()),
            plots: Mutex::new(BTreeMap::new()),
            ports: Mutex::new(HashMap::new()),
            rates,
            foxglove: Arc::new(crate::foxglove::Bridge::new(participant.clone())),
            stop: AtomicBool::new(false),
        })
    }

    /// Starts the watching threads; they end with [`stop`](Self::stop).
    pub fn start(self: &Arc<Self>) -> std::io::Result<()> {
        let hub = Arc::clone(self);
        std::thread::Builder::new()
            .name("studio-graph".into())
            .spawn(move || hub.watch_graph())?;
        let hub = Arc::clone(self);
        std::thread::Builder::new()
            .name("studio-plots".into())
            .spawn(move || hub.send_points())?;
        Ok(())
    }

    /// Ends the watching threads.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
    }

    /// The Foxglove WebSocket protocol's side of the hub.
    pub fn foxglove(&self) -> Arc<crate::foxglove::Bridge> {
        Arc::clone(&self.foxglove)
    }

    /// Messages from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<Message> {
        self.tx.subscribe()
    }

    /// The last message of each kind, for a new page.
    pub fn snapshot(&self) -> Vec<Message> {
        let latest = lock(&self.latest);
        (latest.network.iter())
            .chain(latest.descriptions.values())
            .chain(latest.machines.values())
            .chain(latest.stats.values())
            .cloned()
            .collect()
    }

    fn publish(&self, message: serde_json::Value) -> Message {
        let text: Message = Arc::from(message.to_string());
        // No page connected is not an error.
        let _ = self.tx.send(Arc::clone(&text));
        text
    }

    fn watch_graph(self: Arc<Self>) {
        let mut monitors: BTreeMap<String, RateMonitor> = BTreeMap::new();
        let mut systems: BTreeMap<String, DirectConsumer> = BTreeMap::new();
        let mut failing = false;
        while !self.stop.load(Ordering::Acquire) {
            match self.participant.graph() {
                Ok(graph) => {
                    if failing {
                        tracing::info!("the daemon answers again");
                        failing = false;
                    }
                    self.follow(&graph, &mut monitors, &mut systems);
                    self.foxglove.follow(&graph);
                    let now = Instant::now();
                    let mut rates = BTreeMap::new();
                    for (topic, m) in monitors.iter_mut() {
                        let samples = m.counts.samples.load(Ordering::Relaxed);
                        let elapsed = now.duration_since(m.last.1).as_secs_f64();
                        if elapsed >= 0.5 {
                            m.rate = (samples - m.last.0) as f64 / elapsed;
                            m.last = (samples, now);
                        }
                        rates.insert(
                            topic.clone(),
                            (m.rate, m.counts.lost.load(Ordering::Relaxed)),
                        );
                    }
                    let model = network::model(&graph, &rates);
                    let text = self.publish(json!({"type": "network", "network": model}));
                    lock(&self.latest).network = Some(text);
                }
                Err(err) => {
                    if !failing {
                        tracing::warn!(%err, "the daemon does not answer");
                        failing = true;
                    }
                    self.publish(json!({"type": "error", "text": format!("the daemon does not answer: {err}")}));
                }
            }
            std::thread::sleep(Duration::from_secs(1));
        }
    }

    /// Consumers for what appeared in `graph`: a rate monitor per user topic, and each
    /// system's description, statistics and state machines.
    fn follow(
        self: &Arc<Self>,
        graph: &Graph,
        monitors: &mut BTreeMap<String, RateMonitor>,
        systems: &mut BTreeMap<String, DirectConsumer>,
    ) {
        let mut present: BTreeMap<&str, &TypeDescription> = BTreeMap::new();
        for e in &graph.endpoints {
            if e.info.kind() == ndds_core::wire::EndpointKind::Producer {
                present.entry(&e.info.topic).or_insert(&e.info.type_desc);
            }
        }
        monitors.retain(|topic, _| present.contains_key(topic.as_str()));
        for (topic, desc) in &present {
            let kind = if topic.starts_with("cs/") && topic.ends_with("/description") {
                Watch::Description
            } else if topic.starts_with("cs/") && topic.ends_with("/stats") {
                Watch::Stats
            } else if topic.starts_with("fsm/") && topic.ends_with("/state") {
                Watch::Machine
            } else if network::is_internal(topic) {
                continue;
            } else {
                if self.rates && !monitors.contains_key(*topic) {
                    match self.monitor(topic, desc) {
                        Ok(m) => {
                            monitors.insert((*topic).to_owned(), m);
                        }
                        Err(err) => tracing::debug!(topic, %err, "no rate for this topic"),
                    }
                }
                continue;
            };
            if systems.contains_key(*topic) {
                continue;
            }
            match self.system_consumer(topic, kind) {
                Ok(consumer) => {
                    systems.insert((*topic).to_owned(), consumer);
                }
                Err(err) => tracing::debug!(topic, %err, "not followed"),
            }
        }
    }

    fn monitor(&self, topic: &str, desc: &TypeDescription) -> Result<RateMonitor, String> {
        let qos = ConsumerQos {
            every_producer: true,
            ..ConsumerQos::default()
        };
        let consumer = self
            .participant
            .raw_consumer(topic, desc.clone(), qos)
            .map_err(|e| e.to_string())?;
        let counts = Arc::new(RateCounts::default());
        let shared = Arc::clone(&counts);
        let mut last: HashMap<Guid, u64> = HashMap::new();
        let consumer = consumer
            .on_raw_sample_direct(move |sample| {
                shared.samples.fetch_add(1, Ordering::Relaxed);
                let seq = sample.info.seq;
                if let Some(prev) = last.insert(sample.info.writer, seq)
                    && seq > prev + 1
                {
                    shared.lost.fetch_add(seq - prev - 1, Ordering::Relaxed);
                }
            })
            .map_err(|e| e.to_string())?;
        Ok(RateMonitor {
            _consumer: consumer,
            counts,
            last: (0, Instant::now()),
            rate: 0.0,
        })
    }

    fn system_consumer(
        self: &Arc<Self>,
        topic: &str,
        kind: Watch,
    ) -> Result<DirectConsumer, String> {
        match kind {
            Watch::Description => self.forward::<SystemDescription>(
                topic,
                ndds_runtime::describe::description_type(),
                ConsumerQos {
                    reliability: Reliability::Reliable { depth: 4 },
                    ..ConsumerQos::default()
                },
                ("system", "system"),
                |latest| &mut latest.descriptions,
                |d, _| d.runtime.clone(),
            ),
            Watch::Stats => self.forward::<HabitatStats>(
                topic,
                TypeDescription::named::<HabitatStats>(builtin::HABITAT_STATS),
                ConsumerQos::default(),
                ("stats", "stats"),
                |latest| &mut latest.stats,
                |_, topic| topic.to_owned(),
            ),
            Watch::Machine => self.forward::<MachineState>(
                topic,
                TypeDescription::named::<MachineState>(builtin::FSM_STATE),
                ConsumerQos::default(),
                ("machine", "state"),
                |latest| &mut latest.machines,
                |m, _| m.machine.clone(),
            ),
        }
    }

    /// A consumer of `topic` whose every sample goes to the pages as `{"type": kind, field:
    /// sample}` and is kept, under `key(sample, topic)`, as the last of its kind for pages that
    /// connect later.
    fn forward<T>(
        self: &Arc<Self>,
        topic: &str,
        desc: TypeDescription,
        qos: ConsumerQos,
        (kind, field): (&'static str, &'static str),
        slot: fn(&mut Latest) -> &mut BTreeMap<String, Message>,
        key: fn(&T, &str) -> String,
    ) -> Result<DirectConsumer, String>
    where
        T: serde::Serialize + serde::de::DeserializeOwned + Send + 'static,
    {
        let weak = Arc::downgrade(self);
        let name = topic.to_owned();
        self.participant
            .consumer_with_type::<T>(topic, desc, qos)
            .map_err(|e| e.to_string())?
            .on_sample_direct(move |sample| {
                if let Some(hub) = weak.upgrade() {
                    let mut message = serde_json::Map::new();
                    message.insert("type".into(), kind.into());
                    message.insert(field.into(), json!(sample.value));
                    let text = hub.publish(serde_json::Value::Object(message));
                    slot(&mut lock(&hub.latest)).insert(key(&sample.value, &name), text);
                }
            })
            .map_err(|e| e.to_string())
    }

    /// A page wants the points of `topic`.
    pub fn watch(&self, topic: &str) -> Result<(), String> {
        if let Some(plot) = lock(&self.plots).get_mut(topic) {
            plot.watchers += 1;
            return Ok(());
        }
        // Asked of the daemon without holding the plots, which the points thread takes.
        let graph = self.participant.graph().map_err(|e| e.to_string())?;
        let desc = graph
            .endpoints
            .iter()
            .filter(|e| e.info.topic == topic)
            .min_by_key(|e| e.info.kind() != ndds_core::wire::EndpointKind::Producer)
            .map(|e| e.info.type_desc.clone())
            .ok_or_else(|| format!("no topic `{topic}` in the graph"))?;
        let is_csmat = desc.fingerprint() == TypeDescription::of::<CsMat>().fingerprint();
        if !is_csmat && desc.layout.is_none() {
            return Err(format!(
                "`{topic}` carries {} without a layout: its fields cannot be decoded",
                desc.name
            ));
        }
        let series = Arc::new(Mutex::new(Series::default()));
        let shared = Arc::clone(&series);
        let mut mat = CsMat::zeros("", 0, 0);
        // A CSMat's element names change only with its shape or fields: made again then only.
        let mut named: Option<(CsMat, Vec<String>)> = None;
        let consumer = self
            .participant
            .raw_consumer(topic, desc.clone(), watching_qos())
            .map_err(|e| e.to_string())?
            .on_raw_sample_direct(move |sample| {
                let t = unix_seconds(sample.info.source_timestamp);
                let mut json_names = Vec::new();
                let decoded: Result<Vec<f64>, String> = if is_csmat {
                    mat.decode_into(&sample.payload)
                        .map_err(|e| e.to_string())
                        .map(|()| {
                            let same = named.as_ref().is_some_and(|(m, _)| {
                                m.shape() == mat.shape()
                                    && m.row_fields() == mat.row_fields()
                                    && m.col_fields() == mat.col_fields()
                            });
                            if !same {
                                named = Some((mat.clone(), plot::csmat_names(&mat)));
                            }
                            plot::csmat_values(&mat)
                        })
                } else {
                    match &desc.layout {
                        Some(layout) => ndds_core::dynamic::decode_json(layout, &sample.payload)
                            .map(|v| {
                                let values;
                                (json_names, values) = plot::json_fields(&v).into_iter().unzip();
                                values
                            })
                            .map_err(|e| e.to_string()),
                        None => Ok(Vec::new()),
                    }
                };
                let names: &[String] = match (&named, is_csmat) {
                    (Some((_, names)), true) => names,
                    _ => &json_names,
                };
                let mut series = lock(&shared);
                match decoded {
                    Ok(values) => {
                        if series.names != names {
                            series.decimators =
                                names.iter().map(|_| Decimator::new(BUCKET_S)).collect();
                            series.names = names.to_vec();
                        }
                        for (d, v) in series.decimators.iter_mut().zip(values) {
                            d.push(t, v);
                        }
                    }
                    Err(e) => series.error = Some(e),
                }
            })
            .map_err(|e| e.to_string())?;
        let mut plots = lock(&self.plots);
        match plots.get_mut(topic) {
            // Another page asked meanwhile: its consumer serves both, this one is dropped.
            Some(plot) => plot.watchers += 1,
            None => {
                plots.insert(
                    topic.to_owned(),
                    PlotTopic {
                        _consumer: consumer,
                        watchers: 1,
                        series,
                    },
                );
            }
        }
        Ok(())
    }

    /// A page no longer wants the points of `topic`.
    pub fn unwatch(&self, topic: &str) {
        let mut plots = lock(&self.plots);
        if let Some(plot) = plots.get_mut(topic) {
            plot.watchers = plot.watchers.saturating_sub(1);
            if plot.watchers == 0 {
                plots.remove(topic);
            }
        }
    }

    fn send_points(self: Arc<Self>) {
        while !self.stop.load(Ordering::Acquire) {
            std::thread::sleep(Duration::from_millis(100));
            let now = unix_seconds(SystemTime::now());
            let taken: Vec<(String, serde_json::Value)> = {
                let plots = lock(&self.plots);
                plots
                    .iter()
                    .filter_map(|(topic, plot)| {
                        let mut series = lock(&plot.series);
                        let error = series.error.take();
                        let names = series.names.clone();
                        let points: Vec<Vec<(f64, f64)>> =
                            series.decimators.iter_mut().map(|d| d.take(now)).collect();
                        if points.iter().all(Vec::is_empty) && error.is_none() {
                            return None;
                        }
                        Some((
                            topic.clone(),
                            json!({"fields": names, "points": points, "error": error}),
                        ))
                    })
                    .collect()
            };
            for (topic, body) in taken {
                self.publish(json!({"type": "points", "topic": topic, "data": body}));
            }
        }
    }

    /// A port user of `port`, declared once and kept.
    fn port_user<Q, R>(&self, port: &str) -> Result<Arc<PortUser<Q, R>>, String>
    where
        Q: serde::Serialize + serde::de::DeserializeOwned + Send + Sync + 'static,
        R: serde::Serialize + serde::de::DeserializeOwned + Send + Sync + 'static,
    {
        let mut ports = lock(&self.ports);
        if let Some(user) = ports.get(port).cloned()
            && let Ok(user) = user.downcast::<PortUser<Q, R>>()
        {
            return Ok(user);
        }
        let user = Arc::new(
            PortUser::<Q, R>::declare(&self.participant, port, "studio")
                .map_err(|e| e.to_string())?,
        );
        ports.insert(port.to_owned(), user.clone());
        Ok(user)
    }

    /// Runs a command of a page, blocking until the system answers (or the timeout); the
    /// answer in words.
    pub fn command(&self, command: &Command) -> CommandReply {
        match command {
            Command::Configure {
                runtime,
                configuration,
            } => self.ask_runtime(runtime, RuntimeCommand::Configure(configuration.clone())),
            Command::Set {
                runtime,
                mat,
                values,
            } => self.ask_runtime(
                runtime,
                RuntimeCommand::SetMat {
                    name: mat.clone(),
                    values: values.clone(),
                },
            ),
            Command::Read { runtime, mats } => {
                self.ask_runtime(runtime, RuntimeCommand::ReadMats(mats.clone()))
            }
            Command::Stimulus { machine, stimuli } => {
                let parsed: Vec<Stimulus> = stimuli
                    .split(',')
                    .map(str::trim)
                    .filter(|s| !s.is_empty())
                    .map(Stimulus::parse)
                    .collect();
                if parsed.is_empty() {
                    return Err("no stimulus given".into());
                }
                let user = self.port_user::<Vec<Stimulus>, CommandReply>(
                    &ndds_runtime::fsm::command_port(machine),
                )?;
                user.send(&parsed, COMMAND_TIMEOUT)
                    .map_err(|e| e.to_string())?
            }
        }
    }

    /// Sends `command` to the command port of `runtime` and waits for its answer.
    fn ask_runtime(&self, runtime: &str, command: RuntimeCommand) -> CommandReply {
        let user =
            self.port_user::<RuntimeCommand, CommandReply>(&ndds_runtime::command_port(runtime))?;
        user.send(&command, COMMAND_TIMEOUT)
            .map_err(|e| e.to_string())?
    }
}

#[derive(Clone, Copy)]
enum Watch {
    Description,
    Stats,
    Machine,
}

/// What a page may ask of a running system.
#[derive(Clone, Debug, serde::Deserialize)]
#[serde(tag = "command", rename_all = "lowercase")]
pub enum Command {
    /// Switch `runtime` to `configuration`.
    Configure {
        /// The system.
        runtime: String,
        /// The configuration.
        configuration: String,
    },
    /// Set a parameter (a CSMat no module writes).
    Set {
        /// The system.
        runtime: String,
        /// The CSMat.
        mat: String,
        /// Its values, row-major.
        values: Vec<f64>,
    },
    /// Send stimuli (`Name` or `Name=value`, comma-separated) to a machine.
    Stimulus {
        /// The machine.
        machine: String,
        /// The stimuli.
        stimuli: String,
    },
    /// Read CSMats' values (answered as JSON text).
    Read {
        /// The system.
        runtime: String,
        /// The CSMats.
        mats: Vec<String>,
    },
}

impl Command {
    /// Whether it changes the system (and so needs the page's token).
    pub fn changes(&self) -> bool {
        !matches!(self, Command::Read { .. })
    }
}

/// How the studio takes a topic it forwards (a plot, a Foxglove channel): every producer's
/// samples, with room for bursts.
pub(crate) fn watching_qos() -> ConsumerQos {
    ConsumerQos {
        every_producer: true,
        depth: 1024,
        ..ConsumerQos::default()
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

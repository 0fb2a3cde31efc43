//! Shared views of the daemon's graph for the listing commands.

use std::collections::BTreeMap;

use ndds_client::Graph;
use ndds_core::ipc::EndpointSummary;
use ndds_core::types::{TypeDescription, fingerprint_hex};
use ndds_core::wire::{EndpointKind, EndpointQos, Reliability};
use serde::Serialize;

use ndds_core::suggest;

/// Endpoints of one topic.
pub struct Topic<'a> {
    /// Producers.
    pub producers: Vec<&'a EndpointSummary>,
    /// Consumers.
    pub consumers: Vec<&'a EndpointSummary>,
}

impl Topic<'_> {
    /// Distinct (type name, fingerprint) pairs on the topic, producers first.
    pub fn types(&self) -> Vec<(&str, u64)> {
        let mut types: Vec<(&str, u64)> = Vec::new();
        for e in self.producers.iter().chain(&self.consumers) {
            let entry = (e.info.type_desc.name.as_str(), e.info.fingerprint);
            if !types.iter().any(|(_, f)| *f == entry.1) {
                types.push(entry);
            }
        }
        types
    }
}

/// Groups the graph's endpoints by topic name, sorted.
pub fn topics(graph: &Graph) -> BTreeMap<&str, Topic<'_>> {
    let mut topics: BTreeMap<&str, Topic<'_>> = BTreeMap::new();
    for endpoint in &graph.endpoints {
        let topic = topics.entry(&endpoint.info.topic).or_insert_with(|| Topic {
            producers: Vec::new(),
            consumers: Vec::new(),
        });
        match endpoint.info.kind() {
            EndpointKind::Producer => topic.producers.push(endpoint),
            EndpointKind::Consumer => topic.consumers.push(endpoint),
        }
    }
    topics
}

/// The type description of a topic, preferring producers; errors when the topic is unknown
/// or carries several types and none was chosen.
pub fn topic_type(
    graph: &Graph,
    name: &str,
    fingerprint: Option<&str>,
) -> anyhow::Result<TypeDescription> {
    let all = topics(graph);
    let Some(topic) = all.get(name) else {
        anyhow::bail!(
            "topic {name:?} not found; {}",
            unknown_topic_hint(name, &all)
        );
    };
    let candidates: Vec<&EndpointSummary> = topic
        .producers
        .iter()
        .chain(&topic.consumers)
        .copied()
        .collect();
    let chosen = match fingerprint {
        Some(hex) => candidates
            .iter()
            .find(|e| fingerprint_hex(e.info.fingerprint) == hex.to_ascii_lowercase())
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "no endpoint of {name:?} has fingerprint {hex} (types on the topic: {})",
                    type_list(topic)
                )
            })?,
        None => {
            let types = topic.types();
            if types.len() > 1 {
                anyhow::bail!(
                    "topic {name:?} carries incompatible types: {}; choose one with --fingerprint",
                    type_list(topic)
                );
            }
            candidates
                .first()
                .ok_or_else(|| anyhow::anyhow!("topic {name:?} has no endpoints"))?
        }
    };
    Ok(chosen.info.type_desc.clone())
}

/// At most this many topic names are listed when none is close to an unknown one.
const LISTED_TOPICS: usize = 12;

/// What to say after "topic X not found": the close names (internal ones included, so
/// `fsm/arm/stat` finds `fsm/arm/state`), else the user topics there are.
fn unknown_topic_hint(name: &str, all: &BTreeMap<&str, Topic<'_>>) -> String {
    if let Some(question) = suggest::did_you_mean(&suggest::suggest(name, all.keys())) {
        return question;
    }
    let user: Vec<&str> = all.keys().copied().filter(|t| !is_internal(t)).collect();
    let hidden = all.len() - user.len();
    let mut text = match user.len() {
        0 => "no user topics exist".to_owned(),
        n if n <= LISTED_TOPICS => format!("known topics: {}", user.join(", ")),
        n => format!(
            "known topics: {} and {} more",
            user[..LISTED_TOPICS].join(", "),
            n - LISTED_TOPICS
        ),
    };
    if hidden > 0 {
        text.push_str(&format!(
            " ({hidden} internal not listed; `ndds topics --all`)"
        ));
    }
    text
}

/// Prefixes of the topics the runtime and the SDK use for themselves (ports' declarations
/// and requests, state machines' events and states, ControlShell status), and whether a topic
/// is one of them: the studio's, so both tell them apart alike.
pub use ndds_studio::network::{INTERNAL_PREFIXES, is_internal};

/// `name (fingerprint), ...` of the types on a topic.
fn type_list(topic: &Topic<'_>) -> String {
    topic
        .types()
        .iter()
        .map(|(t, f)| format!("{t} ({})", fingerprint_hex(*f)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// An endpoint as the JSON listings show it.
#[derive(Serialize)]
pub struct EndpointView {
    /// `participant.entity`.
    pub guid: String,
    /// Host name of its daemon.
    pub host: String,
    /// Node id of its daemon.
    pub node: String,
    /// Owning process id.
    pub pid: u32,
    /// Owning process name.
    pub process: String,
    /// Data locator.
    pub locator: String,
    /// Type name.
    pub type_name: String,
    /// Type fingerprint.
    pub fingerprint: String,
    /// QoS, kind-specific.
    pub qos: QosView,
}

/// QoS as the JSON listings show it.
#[derive(Serialize)]
#[serde(untagged)]
pub enum QosView {
    /// A producer's.
    Producer {
        /// Strength.
        strength: i32,
        /// Persistence in ms.
        persistence_ms: f64,
        /// best-effort or reliable.
        reliability: String,
    },
    /// A consumer's.
    Consumer {
        /// Minimum separation in ms.
        min_separation_ms: f64,
        /// Deadline in ms (0: none).
        deadline_ms: f64,
        /// immediate or polled.
        mode: String,
        /// best-effort or reliable.
        reliability: String,
    },
}

impl EndpointView {
    /// The view of one endpoint.
    pub fn of(e: &EndpointSummary) -> Self {
        EndpointView {
            guid: e.info.guid.to_string(),
            host: e.hostname.clone(),
            node: fingerprint_hex(e.node),
            pid: e.info.pid,
            process: e.info.process.clone(),
            locator: e.info.locator.to_string(),
            type_name: e.info.type_desc.name.clone(),
            fingerprint: fingerprint_hex(e.info.fingerprint),
            qos: qos_view(&e.info.qos),
        }
    }
}

fn reliability(r: Reliability) -> String {
    match r {
        Reliability::BestEffort => "best-effort".to_owned(),
        Reliability::Reliable { depth } => format!("reliable(depth {depth})"),
    }
}

fn qos_view(qos: &EndpointQos) -> QosView {
    let ms = |us: u64| us as f64 / 1000.0;
    match qos {
        EndpointQos::Producer(p) => QosView::Producer {
            strength: p.strength,
            persistence_ms: ms(p.persistence_us),
            reliability: reliability(p.reliability),
        },
        EndpointQos::Consumer(c) => QosView::Consumer {
            min_separation_ms: ms(c.min_separation_us),
            deadline_ms: ms(c.deadline_us),
            mode: format!("{:?}", c.mode).to_ascii_lowercase(),
            reliability: reliability(c.reliability),
        },
    }
}

/// One line of QoS for the text listings.
pub fn qos_text(qos: &EndpointQos) -> String {
    match qos_view(qos) {
        QosView::Producer {
            strength,
            persistence_ms,
            reliability,
        } => format!("strength {strength}, persistence {persistence_ms} ms, {reliability}"),
        QosView::Consumer {
            min_separation_ms,
            deadline_ms,
            mode,
            reliability,
        } => format!(
            "min separation {min_separation_ms} ms, deadline {}, {mode}, {reliability}",
            if deadline_ms == 0.0 {
                "none".to_owned()
            } else {
                format!("{deadline_ms} ms")
            }
        ),
    }
}

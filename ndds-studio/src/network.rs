//! The network view's model: the daemon's graph turned into what the page draws (hosts,
//! processes, topics, ports, endpoints with their QoS) and every producer-consumer pair of a
//! topic that does not match, with the reason in words.

use std::collections::BTreeMap;

use ndds_client::{Graph, Incompatibility};
use ndds_core::discovery::incompatibility;
use ndds_core::ipc::EndpointSummary;
use ndds_core::types::fingerprint_hex;
use ndds_core::wire::{ConsumerMode, EndpointKind, EndpointQos, Reliability};
use serde::Serialize;

/// The prefixes of the topics the runtime and the SDK use for themselves: ports'
/// declarations and requests, state machines' events and states, ControlShell status (`ndds
/// topics` hides them too).
pub const INTERNAL_PREFIXES: [&str; 3] = ["port/", "fsm/", "cs/"];

/// Whether `topic` is one of those.
pub fn is_internal(topic: &str) -> bool {
    INTERNAL_PREFIXES.iter().any(|p| topic.starts_with(p))
}

/// What the page draws.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Network {
    /// Daemons, this host's first.
    pub hosts: Vec<Host>,
    /// Processes with endpoints or sessions.
    pub processes: Vec<Process>,
    /// Topics (ports' own topics are folded into their port).
    pub topics: Vec<Topic>,
    /// Ports.
    pub ports: Vec<Port>,
    /// Endpoints.
    pub endpoints: Vec<Endpoint>,
    /// Pairs on one topic that do not match.
    pub mismatches: Vec<Mismatch>,
}

/// A daemon.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Host {
    /// Its node id (hex).
    pub id: String,
    /// Its host name.
    pub hostname: String,
    /// This studio's daemon.
    pub local: bool,
    /// Lease granted to it, ms.
    pub lease_ms: u64,
    /// Until its entry expires without a refresh, ms (`None` for the local daemon).
    pub expires_in_ms: Option<u64>,
    /// Authenticated by signed discovery.
    pub authenticated: bool,
}

/// A process.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Process {
    /// `host:pid`.
    pub id: String,
    /// Its daemon.
    pub host: String,
    /// Process id.
    pub pid: u32,
    /// Its name.
    pub name: String,
}

/// A topic.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Topic {
    /// Its name.
    pub name: String,
    /// A runtime's, a machine's or a port's own.
    pub internal: bool,
    /// Type names on it (more than one: a mismatch).
    pub types: Vec<String>,
    /// Producers and consumers.
    pub producers: usize,
    /// Consumers.
    pub consumers: usize,
    /// Samples per second the studio measured (`None` when not measured).
    pub rate_hz: Option<f64>,
    /// Samples the studio saw skipped (gaps in producers' sequence numbers), in all.
    pub lost: Option<u64>,
}

/// A port: its owners and users (the processes that declare on its topics).
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Port {
    /// Its name.
    pub name: String,
    /// Processes owning it (producing `port/P/owner`).
    pub owners: Vec<String>,
    /// Processes using it (producing `port/P/users`).
    pub users: Vec<String>,
}

/// A producer or consumer.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Endpoint {
    /// Its id.
    pub guid: String,
    /// `producer` or `consumer`.
    pub kind: &'static str,
    /// Its topic.
    pub topic: String,
    /// Its process (`host:pid`).
    pub process: String,
    /// Type name.
    pub type_name: String,
    /// Type fingerprint (hex).
    pub fingerprint: String,
    /// QoS in words.
    pub qos: String,
    /// Until it expires without a refresh, ms (`None`: local).
    pub expires_in_ms: Option<u64>,
}

/// A producer and a consumer of one topic that do not match, and why.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Mismatch {
    /// The topic.
    pub topic: String,
    /// The producer.
    pub producer: String,
    /// The consumer.
    pub consumer: String,
    /// Why, in words, with both sides.
    pub reason: String,
}

fn process_id(e: &EndpointSummary) -> String {
    format!("{:016x}:{}", e.node, e.info.pid)
}

fn reliability(r: &Reliability) -> String {
    match r {
        Reliability::BestEffort => "best-effort".into(),
        Reliability::Reliable { depth } => format!("reliable (depth {depth})"),
    }
}

/// The QoS of an endpoint, in words.
pub fn qos_text(qos: &EndpointQos) -> String {
    match qos {
        EndpointQos::Producer(p) => format!(
            "strength {}, persistence {} ms, {}",
            p.strength,
            p.persistence_us / 1000,
            reliability(&p.reliability)
        ),
        EndpointQos::Consumer(c) => {
            let mut text = format!(
                "{}, {}",
                match c.mode {
                    ConsumerMode::Immediate => "immediate",
                    ConsumerMode::Polled => "polled",
                },
                reliability(&c.reliability)
            );
            if c.min_separation_us > 0 {
                text.push_str(&format!(
                    ", minimum separation {} ms",
                    c.min_separation_us / 1000
                ));
            }
            if c.deadline_us > 0 {
                text.push_str(&format!(", deadline {} ms", c.deadline_us / 1000));
            }
            text
        }
    }
}

/// Why `producer` and `consumer` do not match, with both sides; `None` when they match.
pub fn why_not_matched(producer: &EndpointSummary, consumer: &EndpointSummary) -> Option<String> {
    let (p, c) = (&producer.info, &consumer.info);
    Some(match incompatibility(p, c)? {
        Incompatibility::Type => format!(
            "types differ: the producer writes {} ({}), the consumer reads {} ({})",
            p.type_desc.name,
            fingerprint_hex(p.fingerprint),
            c.type_desc.name,
            fingerprint_hex(c.fingerprint)
        ),
        Incompatibility::Reliability => {
            "the consumer asks for reliable delivery and the producer offers best effort only"
                .to_owned()
        }
    })
}

/// The model of `graph`; `rates` holds what the studio measured per topic: (samples per
/// second, samples lost).
pub fn model(graph: &Graph, rates: &BTreeMap<String, (f64, u64)>) -> Network {
    let mut net = Network::default();
    for (node, local) in
        std::iter::once((&graph.local, true)).chain(graph.nodes.iter().map(|n| (n, false)))
    {
        net.hosts.push(Host {
            id: format!("{:016x}", node.node),
            hostname: node.info.hostname.clone(),
            local,
            lease_ms: u64::from(node.info.lease_ms),
            expires_in_ms: if local { None } else { node.expires_in_ms },
            authenticated: node.authenticated,
        });
    }
    let mut processes: BTreeMap<String, Process> = BTreeMap::new();
    let mut topics: BTreeMap<&str, (Vec<&EndpointSummary>, Vec<&EndpointSummary>)> =
        BTreeMap::new();
    let mut ports: BTreeMap<String, Port> = BTreeMap::new();
    for e in &graph.endpoints {
        let process = process_id(e);
        processes.entry(process.clone()).or_insert_with(|| Process {
            id: process.clone(),
            host: format!("{:016x}", e.node),
            pid: e.info.pid,
            name: e.info.process.clone(),
        });
        let kind = e.info.kind();
        net.endpoints.push(Endpoint {
            guid: e.info.guid.to_string(),
            kind: match kind {
                EndpointKind::Producer => "producer",
                EndpointKind::Consumer => "consumer",
            },
            topic: e.info.topic.clone(),
            process: process.clone(),
            type_name: e.info.type_desc.name.clone(),
            fingerprint: fingerprint_hex(e.info.fingerprint),
            qos: qos_text(&e.info.qos),
            expires_in_ms: e.expires_in_ms,
        });
        if let Some(rest) = e.info.topic.strip_prefix("port/")
            && let Some((port, what)) = rest.rsplit_once('/')
            && kind == EndpointKind::Producer
            && (what == "owner" || what == "users")
        {
            let entry = ports.entry(port.to_owned()).or_insert_with(|| Port {
                name: port.to_owned(),
                ..Port::default()
            });
            let list = if what == "owner" {
                &mut entry.owners
            } else {
                &mut entry.users
            };
            if !list.contains(&process) {
                list.push(process);
            }
        }
        let slot = topics.entry(&e.info.topic).or_default();
        match kind {
            EndpointKind::Producer => slot.0.push(e),
            EndpointKind::Consumer => slot.1.push(e),
        }
    }
    for (name, (producers, consumers)) in &topics {
        let mut types: Vec<String> = Vec::new();
        for e in producers.iter().chain(consumers) {
            let t = format!(
                "{} ({})",
                e.info.type_desc.name,
                fingerprint_hex(e.info.fingerprint)
            );
            if !types.contains(&t) {
                types.push(t);
            }
        }
        for p in producers {
            for c in consumers {
                if let Some(reason) = why_not_matched(p, c) {
                    net.mismatches.push(Mismatch {
                        topic: (*name).to_owned(),
                        producer: p.info.guid.to_string(),
                        consumer: c.info.guid.to_string(),
                        reason,
                    });
                }
            }
        }
        let measured = rates.get(*name);
        net.topics.push(Topic {
            name: (*name).to_owned(),
            internal: is_internal(name),
            types,
            producers: producers.len(),
            consumers: consumers.len(),
            rate_hz: measured.map(|m| m.0),
            lost: measured.map(|m| m.1),
        });
    }
    net.processes = processes.into_values().collect();
    net.ports = ports.into_values().collect();
    net
}

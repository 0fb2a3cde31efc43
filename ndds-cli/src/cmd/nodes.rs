//! `ndds nodes`: the daemons of the domain and the client processes.

use std::collections::BTreeMap;
use std::net::Ipv4Addr;

use ndds_core::ipc::{Graph, NodeSummary, PeerSummary, Role};
use ndds_core::types::fingerprint_hex;
use serde::Serialize;

use crate::connect::{DaemonArgs, connect};
use crate::outln;

/// Options of `ndds nodes`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct NodeView {
    node: String,
    host: String,
    pid: u32,
    local: bool,
    interface: String,
    unicast: String,
    /// The local daemon's discovery group, `null` when its multicast is off; `null` for remote
    /// nodes, whose settings are not known.
    multicast: Option<String>,
    /// The local daemon's configured unicast peers (absent for remote nodes).
    #[serde(skip_serializing_if = "Option::is_none")]
    peers: Option<Vec<PeerView>>,
    /// Remote nodes: ms since a refresh last arrived by multicast (`null`: never).
    #[serde(skip_serializing_if = "Option::is_none")]
    multicast_seen_ms: Option<Option<u64>>,
    /// Remote nodes: whether the local daemon also sends to it by unicast.
    #[serde(skip_serializing_if = "Option::is_none")]
    unicast_copies: Option<bool>,
    lease_ms: u32,
    announce_period_ms: u32,
    last_seen_ms: u64,
    /// In a domain with permissions: the identity that signs its datagrams.
    identity: Option<String>,
    /// The subject the answering daemon's permissions document gives that identity.
    subject: Option<String>,
    /// Whether the answering daemon verified its signatures (the local node: whether it signs).
    authenticated: bool,
    /// How many of its endpoints the answering daemon's document refuses.
    refused_endpoints: u32,
    version: String,
    processes: Vec<ProcessView>,
    /// The answering daemon's counters (datagrams, drops by reason, sessions); empty for
    /// remote nodes.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    counters: BTreeMap<String, u64>,
}

#[derive(Serialize)]
struct PeerView {
    /// As configured.
    peer: String,
    /// What it resolved to.
    locator: String,
    /// The node known at that locator, if any.
    node: Option<String>,
}

#[derive(Serialize, PartialEq, Eq, PartialOrd, Ord)]
struct ProcessView {
    pid: u32,
    name: String,
    role: String,
    endpoints: u32,
}

/// Runs `ndds nodes`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let graph = connect(daemon)?.graph()?;
    let nodes = views(&graph);
    if args.json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "nodes": nodes }))?
        )?;
        return Ok(());
    }
    // The answering daemon signs: it checks everyone's signatures.
    let guarded = nodes.first().is_some_and(|local| local.identity.is_some());
    for node in &nodes {
        outln!(
            "{} {} (node {}, daemon pid {}, v{}){}",
            if node.local { "*" } else { " " },
            node.host,
            node.node,
            node.pid,
            node.version,
            if node.local {
                String::new()
            } else {
                format!(", seen {} ms ago", node.last_seen_ms)
            }
        )?;
        outln!(
            "    interface {}  unicast {}{}  lease {} ms  period {} ms",
            node.interface,
            node.unicast,
            multicast_text(node),
            node.lease_ms,
            node.announce_period_ms
        )?;
        if let Some(line) = security_text(node, guarded) {
            outln!("    {line}")?;
        }
        if let Some(peers) = &node.peers {
            outln!("    peers: {}", peers_text(peers))?;
        }
        if let (Some(seen), Some(copies)) = (node.multicast_seen_ms, node.unicast_copies) {
            outln!(
                "    discovery: {}, {}",
                seen.map_or("never heard by multicast".to_owned(), |ms| format!(
                    "multicast heard {ms} ms ago"
                )),
                if copies {
                    "unicast copies sent"
                } else {
                    "no unicast copies"
                }
            )?;
        }
        for p in &node.processes {
            outln!(
                "    {} pid {} {} ({} endpoints)",
                p.role,
                p.pid,
                p.name,
                p.endpoints
            )?;
        }
        let nonzero: Vec<String> = node
            .counters
            .iter()
            .filter(|(_, value)| **value > 0)
            .map(|(name, value)| format!("{name} {value}"))
            .collect();
        if !nonzero.is_empty() {
            outln!("    counters: {}", nonzero.join(", "))?;
        }
    }
    Ok(())
}

fn multicast_text(node: &NodeView) -> String {
    match (&node.multicast, node.local) {
        (Some(group), _) => format!("  multicast {group}"),
        (None, true) => "  multicast off".to_owned(),
        (None, false) => String::new(),
    }
}

/// The identity line, in a domain with permissions (the answering daemon signs, or the node
/// does).
fn security_text(node: &NodeView, guarded: bool) -> Option<String> {
    let Some(identity) = node.identity.as_deref() else {
        return guarded.then(|| {
            format!(
                "not authenticated: its datagrams are not signed ({} endpoints refused)",
                node.refused_endpoints
            )
        });
    };
    let short: String = identity.chars().take(8 + 16).collect();
    let subject = node
        .subject
        .as_ref()
        .map_or("no subject of the document".to_owned(), |s| {
            format!("subject `{s}`")
        });
    let state = match (node.local, node.authenticated) {
        (true, _) => "this daemon",
        (false, true) => "authenticated",
        (false, false) => "not authenticated",
    };
    let refused = if node.refused_endpoints > 0 {
        format!(", {} endpoints refused", node.refused_endpoints)
    } else {
        String::new()
    };
    Some(format!("identity {short}…  {subject}, {state}{refused}"))
}

fn peers_text(peers: &[PeerView]) -> String {
    if peers.is_empty() {
        return "none".to_owned();
    }
    peers
        .iter()
        .map(|p| {
            let node = p
                .node
                .as_ref()
                .map_or("not heard".to_owned(), |n| format!("node {n}"));
            if p.peer == p.locator {
                format!("{} ({node})", p.peer)
            } else {
                format!("{} = {} ({node})", p.peer, p.locator)
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

fn views(graph: &Graph) -> Vec<NodeView> {
    let mut nodes = vec![node_view(&graph.local, true)];
    if let Some(local) = nodes.first_mut() {
        local.processes = graph
            .clients
            .iter()
            .map(|c| ProcessView {
                pid: c.pid,
                name: c.name.clone(),
                role: match c.role {
                    Role::Client => "client".to_owned(),
                    Role::Tool => "tool".to_owned(),
                },
                endpoints: c.endpoints,
            })
            .collect();
        local.processes.sort();
        local.counters = graph.counters.iter().cloned().collect();
        local.peers = Some(graph.local.peers.iter().map(peer_view).collect());
    }
    for remote in &graph.nodes {
        let mut view = node_view(remote, false);
        view.multicast_seen_ms = Some(remote.multicast_seen_ms);
        view.unicast_copies = Some(remote.unicast_copies);
        // Remote processes are known through the endpoints they announced.
        let mut processes: BTreeMap<(u32, String), u32> = BTreeMap::new();
        for e in graph.endpoints.iter().filter(|e| e.node == remote.node) {
            *processes
                .entry((e.info.pid, e.info.process.clone()))
                .or_default() += 1;
        }
        view.processes = processes
            .into_iter()
            .map(|((pid, name), endpoints)| ProcessView {
                pid,
                name,
                role: "client".to_owned(),
                endpoints,
            })
            .collect();
        nodes.push(view);
    }
    nodes
}

fn node_view(node: &NodeSummary, local: bool) -> NodeView {
    NodeView {
        node: fingerprint_hex(node.node),
        host: node.info.hostname.clone(),
        pid: node.info.pid,
        local,
        interface: Ipv4Addr::from(node.interface).to_string(),
        unicast: node.info.unicast.to_string(),
        multicast: node.multicast.map(|m| m.to_string()),
        peers: None,
        multicast_seen_ms: None,
        unicast_copies: None,
        lease_ms: node.info.lease_ms,
        announce_period_ms: node.info.announce_period_ms,
        last_seen_ms: node.last_seen_ms,
        identity: node.identity.clone(),
        subject: node.subject.clone(),
        authenticated: node.authenticated,
        refused_endpoints: node.refused_endpoints,
        version: node.info.version.clone(),
        processes: Vec::new(),
        counters: BTreeMap::new(),
    }
}

fn peer_view(peer: &PeerSummary) -> PeerView {
    PeerView {
        peer: peer.name.clone(),
        locator: peer.locator.to_string(),
        node: peer.node.map(fingerprint_hex),
    }
}

#[cfg(test)]
mod tests {
    use ndds_core::wire::{Locator, NodeInfo};

    use super::*;

    fn summary(node: u64, port: u16) -> NodeSummary {
        NodeSummary {
            node,
            info: NodeInfo {
                hostname: format!("host{node}"),
                pid: 1,
                unicast: Locator {
                    addr: [10, 0, 0, node as u8],
                    port,
                },
                lease_ms: 5000,
                announce_period_ms: 1000,
                version: "0.1.0".into(),
            },
            multicast: None,
            interface: [10, 0, 0, node as u8],
            last_seen_ms: 0,
            expires_in_ms: None,
            peers: Vec::new(),
            multicast_seen_ms: None,
            unicast_copies: false,
            identity: None,
            subject: None,
            authenticated: false,
            refused_endpoints: 0,
        }
    }

    #[test]
    fn the_local_daemon_shows_its_peers_and_multicast_state() {
        let mut local = summary(1, 7850);
        local.peers = vec![
            PeerSummary {
                name: "robot-2".into(),
                locator: summary(2, 7850).info.unicast,
                node: Some(2),
            },
            PeerSummary {
                name: "10.0.0.3:7850".into(),
                locator: summary(3, 7850).info.unicast,
                node: None,
            },
        ];
        let mut remote = summary(2, 7850);
        remote.unicast_copies = true;
        let graph = Graph {
            local,
            nodes: vec![remote],
            clients: Vec::new(),
            endpoints: Vec::new(),
            counters: Vec::new(),
        };
        let views = views(&graph);
        let json = serde_json::to_value(&views).unwrap();
        assert_eq!(json[0]["multicast"], serde_json::Value::Null);
        assert_eq!(json[0]["peers"][0]["peer"], "robot-2");
        assert_eq!(json[0]["peers"][0]["locator"], "10.0.0.2:7850");
        assert_eq!(json[0]["peers"][0]["node"], "0000000000000002");
        assert_eq!(json[0]["peers"][1]["node"], serde_json::Value::Null);
        assert!(json[0].get("unicast_copies").is_none());
        assert!(json[1].get("peers").is_none());
        assert_eq!(json[1]["unicast_copies"], true);
        assert_eq!(json[1]["multicast_seen_ms"], serde_json::Value::Null);

        assert_eq!(multicast_text(&views[0]), "  multicast off");
        assert_eq!(multicast_text(&views[1]), "");
        let peers = views[0].peers.as_deref().unwrap();
        assert_eq!(
            peers_text(peers),
            "robot-2 = 10.0.0.2:7850 (node 0000000000000002), 10.0.0.3:7850 (not heard)"
        );
        assert_eq!(peers_text(&[]), "none");
    }
}

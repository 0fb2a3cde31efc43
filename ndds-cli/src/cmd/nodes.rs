//! `ndds nodes`: the daemons of the domain and the client processes.

use std::collections::BTreeMap;
use std::net::Ipv4Addr;

use ndds_core::ipc::{Graph, NodeSummary, Role};
use ndds_core::types::fingerprint_hex;
use serde::Serialize;

use crate::connect::{DaemonArgs, connect};

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
    multicast: Option<String>,
    lease_ms: u32,
    announce_period_ms: u32,
    last_seen_ms: u64,
    version: String,
    processes: Vec<ProcessView>,
    /// The answering daemon's counters (datagrams, drops by reason, sessions); empty for
    /// remote nodes.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    counters: BTreeMap<String, u64>,
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
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "nodes": nodes }))?
        );
        return Ok(());
    }
    for node in &nodes {
        println!(
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
        );
        println!(
            "    interface {}  unicast {}{}  lease {} ms  period {} ms",
            node.interface,
            node.unicast,
            node.multicast
                .as_ref()
                .map(|m| format!("  multicast {m}"))
                .unwrap_or_default(),
            node.lease_ms,
            node.announce_period_ms
        );
        for p in &node.processes {
            println!(
                "    {} pid {} {} ({} endpoints)",
                p.role, p.pid, p.name, p.endpoints
            );
        }
        let nonzero: Vec<String> = node
            .counters
            .iter()
            .filter(|(_, value)| **value > 0)
            .map(|(name, value)| format!("{name} {value}"))
            .collect();
        if !nonzero.is_empty() {
            println!("    counters: {}", nonzero.join(", "));
        }
    }
    Ok(())
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
    }
    for remote in &graph.nodes {
        let mut view = node_view(remote, false);
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
        lease_ms: node.info.lease_ms,
        announce_period_ms: node.info.announce_period_ms,
        last_seen_ms: node.last_seen_ms,
        version: node.info.version.clone(),
        processes: Vec::new(),
        counters: BTreeMap::new(),
    }
}

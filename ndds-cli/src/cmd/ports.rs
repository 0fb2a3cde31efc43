//! `ndds ports`: the ports of a live system (`ndds_client::ports`) — owner, users,
//! restrictions and the owner's queue, from the ports' own declaration topics.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use ndds_client::ConsumerQos;
use ndds_client::ports::{OwnerInfo, PortWire, UserInfo};
use serde::Serialize;

use crate::connect::{DaemonArgs, connect};
use crate::{outln, seconds};

/// Options of `ndds ports`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Seconds to listen for the ports' declarations (each is kept for late readers, so they
    /// come as soon as discovery matched).
    #[arg(long, value_parser = seconds::parse, default_value = "0.8")]
    listen: Duration,
}

#[derive(Debug, Default, Serialize)]
struct PortView {
    port: String,
    owners: Vec<OwnerInfo>,
    users: Vec<UserInfo>,
}

/// Runs `ndds ports`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let participant = connect(daemon)?;
    let graph = participant.graph()?;
    let names: std::collections::BTreeSet<String> = graph
        .endpoints
        .iter()
        .filter_map(|e| {
            let rest = e.info.topic.strip_prefix("port/")?;
            let (port, leaf) = rest.split_once('/')?;
            matches!(leaf, "request" | "owner" | "users").then(|| port.to_owned())
        })
        .collect();
    // Declarations are written once and kept for readers that match later: reliable
    // readers get them (a best-effort reader gets only what is written after it matched).
    let qos = ConsumerQos {
        depth: 256,
        reliability: ndds_client::Reliability::Reliable { depth: 256 },
        ..ConsumerQos::default()
    };
    let mut listeners = Vec::new();
    for port in &names {
        let owners = participant.consumer_with_type::<OwnerInfo>(
            &format!("port/{port}/owner"),
            OwnerInfo::description(),
            qos,
        )?;
        let users = participant.consumer_with_type::<UserInfo>(
            &format!("port/{port}/users"),
            UserInfo::description(),
            qos,
        )?;
        listeners.push((port.clone(), owners, users));
    }
    let mut views: BTreeMap<String, PortView> = BTreeMap::new();
    let until = Instant::now() + args.listen;
    while Instant::now() < until {
        for (port, owners, users) in &listeners {
            let view = views.entry(port.clone()).or_insert_with(|| PortView {
                port: port.clone(),
                ..PortView::default()
            });
            while let Ok(sample) = owners.try_recv() {
                let info = sample.value;
                match view
                    .owners
                    .iter_mut()
                    .find(|o| o.incarnation == info.incarnation)
                {
                    Some(known) => *known = info,
                    None => view.owners.push(info),
                }
            }
            while let Ok(sample) = users.try_recv() {
                let info = sample.value;
                if !view.users.iter().any(|u| u.user == info.user) {
                    view.users.push(info);
                }
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let views: Vec<PortView> = views.into_values().collect();
    if args.json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "ports": views }))?
        )?;
        return Ok(());
    }
    if views.is_empty() {
        outln!("no ports")?;
    }
    for view in &views {
        print(view)?;
    }
    Ok(())
}

fn print(view: &PortView) -> anyhow::Result<()> {
    outln!("{}", view.port)?;
    // The highest takeover claim owns the port; lower ones were replaced.
    let top = view.owners.iter().map(|o| o.claim).max();
    let (current, replaced): (Vec<&OwnerInfo>, Vec<&OwnerInfo>) =
        view.owners.iter().partition(|o| Some(o.claim) == top);
    match current.as_slice() {
        [] => outln!("  owner     (none heard)")?,
        [owner] => outln!(
            "  owner     {} (pid {}), queue {}{}",
            owner.task,
            owner.pid,
            owner.queue,
            if owner.claim > 0 {
                format!(", took the port over (claim {})", owner.claim)
            } else {
                String::new()
            }
        )?,
        owners => {
            let all: Vec<String> = owners
                .iter()
                .map(|o| format!("{} (pid {})", o.task, o.pid))
                .collect();
            outln!("  owner     CONFLICT: {}", all.join(" and "))?;
        }
    }
    for old in &replaced {
        outln!(
            "  replaced  {} (pid {}), still announcing",
            old.task,
            old.pid
        )?;
    }
    if let Some(r) = current.first().map(|o| &o.restrictions) {
        let mut parts = Vec::new();
        if !r.usages.is_empty() {
            parts.push(format!("usages {:?}", r.usages));
        }
        if !r.users.is_empty() {
            parts.push(format!("users {:?}", r.users));
        }
        if let Some(max) = r.max_users {
            parts.push(format!("max users {max}"));
        }
        if let Some(ms) = r.timeout_ms {
            parts.push(format!("timeout {ms} ms"));
        }
        if let Some(priority) = r.priority {
            parts.push(format!("priority {priority}"));
        }
        if let Some(filter) = &r.filter {
            parts.push(format!("filter {filter:?}"));
        }
        if let ndds_client::ports::ProcessClass::Tight { spin_us } = r.class {
            parts.push(format!("tightly coupled (busy-waits {spin_us} us)"));
        }
        if !parts.is_empty() {
            outln!("  restrict  {}", parts.join(", "))?;
        }
    }
    let users: Vec<String> = view
        .users
        .iter()
        .map(|u| format!("{} {:?}", u.task, u.usages))
        .collect();
    outln!(
        "  users     {}",
        if users.is_empty() {
            "(none heard)".to_owned()
        } else {
            users.join(", ")
        }
    )?;
    Ok(())
}

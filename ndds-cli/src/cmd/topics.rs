//! `ndds topics`: every topic with its type, producers and consumers.
//!
//! The runtime's own topics (`port/…`, `fsm/…`, `cs/…`, see [`render::is_internal`]) are
//! counted but not listed unless `--all`; `--json` always lists every topic, each with an
//! `internal` flag, so scripts see the whole graph.

use ndds_core::types::fingerprint_hex;
use serde::Serialize;

use crate::connect::{DaemonArgs, connect};
use crate::outln;
use crate::render::{self, EndpointView, INTERNAL_PREFIXES, Topic};

/// Options of `ndds topics`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print JSON instead of text (always with every endpoint and every topic, internal ones
    /// flagged `"internal": true`).
    #[arg(long)]
    json: bool,
    /// Also list the runtime's internal topics (`port/`, `fsm/`, `cs/`).
    #[arg(short, long)]
    all: bool,
    /// List every producer (with strength and persistence) and consumer (with its QoS).
    #[arg(short, long)]
    verbose: bool,
}

#[derive(Serialize)]
struct TopicView {
    name: String,
    /// One of the runtime's own topics (`port/`, `fsm/`, `cs/`).
    internal: bool,
    types: Vec<TypeView>,
    incompatible: bool,
    producers: Vec<EndpointView>,
    consumers: Vec<EndpointView>,
}

#[derive(Serialize)]
struct TypeView {
    name: String,
    fingerprint: String,
}

/// Runs `ndds topics`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let graph = connect(daemon)?.graph()?;
    let topics = render::topics(&graph);
    if args.json {
        let views: Vec<TopicView> = topics.iter().map(|(name, t)| view(name, t)).collect();
        outln!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "topics": views }))?
        )?;
        return Ok(());
    }
    let (shown, hidden): (Vec<_>, Vec<_>) = topics
        .iter()
        .partition(|(name, _)| args.all || !render::is_internal(name));
    if shown.is_empty() {
        let what = if hidden.is_empty() { "" } else { "user " };
        outln!("no {what}topics (daemon on {})", graph.local.info.hostname)?;
    }
    for (name, topic) in &shown {
        print_topic(name, topic, args.verbose)?;
    }
    let hidden_names: Vec<&str> = hidden.iter().map(|(name, _)| **name).collect();
    if let Some(note) = hidden_note(&hidden_names) {
        outln!("{note}")?;
    }
    Ok(())
}

/// `3 internal topics hidden (port/, fsm/); --all lists them`, naming the prefixes present.
fn hidden_note(hidden: &[&str]) -> Option<String> {
    if hidden.is_empty() {
        return None;
    }
    let prefixes: Vec<&str> = INTERNAL_PREFIXES
        .into_iter()
        .filter(|prefix| hidden.iter().any(|name| name.starts_with(prefix)))
        .collect();
    let (n, s) = (hidden.len(), if hidden.len() == 1 { "" } else { "s" });
    Some(format!(
        "{n} internal topic{s} hidden ({}); --all lists them",
        prefixes.join(", ")
    ))
}

fn view(name: &str, topic: &Topic<'_>) -> TopicView {
    let types = topic.types();
    TopicView {
        name: name.to_owned(),
        internal: render::is_internal(name),
        incompatible: types.len() > 1,
        types: types
            .iter()
            .map(|(t, f)| TypeView {
                name: (*t).to_owned(),
                fingerprint: fingerprint_hex(*f),
            })
            .collect(),
        producers: topic
            .producers
            .iter()
            .map(|e| EndpointView::of(e))
            .collect(),
        consumers: topic
            .consumers
            .iter()
            .map(|e| EndpointView::of(e))
            .collect(),
    }
}

fn print_topic(name: &str, topic: &Topic<'_>, verbose: bool) -> anyhow::Result<()> {
    let count = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
    outln!(
        "{name}  ({}, {})",
        count(topic.producers.len(), "producer"),
        count(topic.consumers.len(), "consumer")
    )?;
    let types = topic.types();
    for (type_name, fingerprint) in &types {
        outln!("  type {} ({})", type_name, fingerprint_hex(*fingerprint))?;
    }
    if types.len() > 1 {
        outln!("  INCOMPATIBLE: endpoints of different types do not exchange samples")?;
    }
    if !verbose {
        return Ok(());
    }
    for (label, endpoints) in [
        ("producer", &topic.producers),
        ("consumer", &topic.consumers),
    ] {
        for e in endpoints.iter() {
            outln!(
                "  {label} {} pid {} ({}) on {}: {}{}",
                e.info.guid,
                e.info.pid,
                e.info.process,
                e.hostname,
                render::qos_text(&e.info.qos),
                if types.len() > 1 {
                    format!(" [type {}]", fingerprint_hex(e.info.fingerprint))
                } else {
                    String::new()
                }
            )?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hidden_note_counts_and_names_the_prefixes_present() {
        assert_eq!(hidden_note(&[]), None);
        assert_eq!(
            hidden_note(&["fsm/arm/state"]).as_deref(),
            Some("1 internal topic hidden (fsm/); --all lists them")
        );
        assert_eq!(
            hidden_note(&["cs/arm/configure", "fsm/arm/events", "port/grip/owner"]).as_deref(),
            Some("3 internal topics hidden (port/, fsm/, cs/); --all lists them")
        );
    }
}

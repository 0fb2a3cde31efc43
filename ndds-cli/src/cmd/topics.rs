//! `ndds topics`: every topic with its type, producers and consumers.

use ndds_core::types::fingerprint_hex;
use serde::Serialize;

use crate::connect::{DaemonArgs, connect};
use crate::render::{self, EndpointView, Topic};

/// Options of `ndds topics`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print JSON instead of text (always with every endpoint).
    #[arg(long)]
    json: bool,
    /// List every producer (with strength and persistence) and consumer (with its QoS).
    #[arg(short, long)]
    verbose: bool,
}

#[derive(Serialize)]
struct TopicView {
    name: String,
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
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "topics": views }))?
        );
        return Ok(());
    }
    if topics.is_empty() {
        println!("no topics (daemon on {})", graph.local.info.hostname);
    }
    for (name, topic) in &topics {
        print_topic(name, topic, args.verbose);
    }
    Ok(())
}

fn view(name: &str, topic: &Topic<'_>) -> TopicView {
    let types = topic.types();
    TopicView {
        name: name.to_owned(),
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

fn print_topic(name: &str, topic: &Topic<'_>, verbose: bool) {
    let count = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
    println!(
        "{name}  ({}, {})",
        count(topic.producers.len(), "producer"),
        count(topic.consumers.len(), "consumer")
    );
    let types = topic.types();
    for (type_name, fingerprint) in &types {
        println!("  type {type_name} ({})", fingerprint_hex(*fingerprint));
    }
    if types.len() > 1 {
        println!("  INCOMPATIBLE: endpoints of different types do not exchange samples");
    }
    if !verbose {
        return;
    }
    for (label, endpoints) in [
        ("producer", &topic.producers),
        ("consumer", &topic.consumers),
    ] {
        for e in endpoints.iter() {
            println!(
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
            );
        }
    }
}

//! `ndds modules`: the module tree of a live system (`ndds_client::ports::ModuleBuilder`) —
//! each running module with its parent, children, tasks and ports, from the modules' own
//! declarations (`module/<name>`, kept for late readers).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use ndds_client::ports::{ModuleInfo, PortWire};
use ndds_client::{ConsumerQos, Reliability};

use crate::connect::{DaemonArgs, connect};
use crate::{outln, seconds};

/// Options of `ndds modules`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Seconds to listen for the modules' declarations (each is kept for late readers, so
    /// they come as soon as discovery matched).
    #[arg(long, value_parser = seconds::parse, default_value = "0.8")]
    listen: Duration,
    /// Check a module specification file (`[[module]]` tables, docs/ports.md) instead: its
    /// form, and its modules against each other as one system; no daemon is needed.
    #[arg(long, value_name = "FILE")]
    check: Option<std::path::PathBuf>,
}

/// `ndds modules --check FILE`: every problem, one per line, and a failure if there is one.
fn check(path: &std::path::Path) -> anyhow::Result<()> {
    let file = match ndds_client::ports::ModuleFile::read(path) {
        Ok(file) => file,
        Err(err) => {
            for problem in &err.problems {
                outln!("{problem}")?;
            }
            anyhow::bail!("{}: {} problem(s)", path.display(), err.problems.len());
        }
    };
    let problems = file.check();
    for problem in &problems {
        outln!("{problem}")?;
    }
    if !problems.is_empty() {
        anyhow::bail!("{}: {} problem(s)", path.display(), problems.len());
    }
    outln!(
        "{}: {} module(s) hold together: {}",
        file.path(),
        file.names().len(),
        file.names().join(", ")
    )?;
    Ok(())
}

/// Runs `ndds modules`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    if let Some(path) = &args.check {
        return check(path);
    }
    let participant = connect(daemon)?;
    let graph = participant.graph()?;
    let topics: std::collections::BTreeSet<String> = graph
        .endpoints
        .iter()
        .filter(|e| e.info.topic.starts_with("module/"))
        .map(|e| e.info.topic.clone())
        .collect();
    let qos = ConsumerQos {
        depth: 16,
        reliability: Reliability::Reliable { depth: 16 },
        ..ConsumerQos::default()
    };
    let mut listeners = Vec::new();
    for topic in &topics {
        listeners.push(participant.consumer_with_type::<ModuleInfo>(
            topic,
            ModuleInfo::description(),
            qos,
        )?);
    }
    let mut modules: BTreeMap<String, ModuleInfo> = BTreeMap::new();
    let until = Instant::now() + args.listen;
    while Instant::now() < until {
        for listener in &listeners {
            while let Ok(sample) = listener.try_recv() {
                modules.insert(sample.value.name.clone(), sample.value);
            }
        }
        if modules.len() == listeners.len() && !listeners.is_empty() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    if args.json {
        let list: Vec<&ModuleInfo> = modules.values().collect();
        outln!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "modules": list }))?
        )?;
        return Ok(());
    }
    if modules.is_empty() {
        outln!("no modules")?;
        return Ok(());
    }
    // Roots: modules without a parent, or whose parent is not heard.
    let roots: Vec<&ModuleInfo> = modules
        .values()
        .filter(|m| m.parent.as_ref().is_none_or(|p| !modules.contains_key(p)))
        .collect();
    for root in roots {
        print(&modules, root, 0)?;
    }
    Ok(())
}

/// Prints `module` and, below it, the children it started.
fn print(
    modules: &BTreeMap<String, ModuleInfo>,
    module: &ModuleInfo,
    depth: usize,
) -> anyhow::Result<()> {
    let indent = "    ".repeat(depth);
    let parent = match (&module.parent, depth) {
        (Some(parent), 0) => format!(", started by `{parent}` (not heard)"),
        _ => String::new(),
    };
    outln!(
        "{indent}{}  (pid {} on {}{parent})",
        module.name,
        module.pid,
        module.host
    )?;
    let list = |names: &[String]| {
        if names.is_empty() {
            "-".to_owned()
        } else {
            names.join(", ")
        }
    };
    outln!("{indent}  owns   {}", list(&module.owns))?;
    outln!("{indent}  uses   {}", list(&module.uses))?;
    if !module.tasks.is_empty() {
        outln!("{indent}  tasks  {}", module.tasks.join(", "))?;
    }
    let waiting: Vec<String> = module
        .children
        .iter()
        .filter(|c| {
            modules
                .get(*c)
                .is_none_or(|m| m.parent.as_ref() != Some(&module.name))
        })
        .cloned()
        .collect();
    if !waiting.is_empty() {
        outln!("{indent}  not started  {}", waiting.join(", "))?;
    }
    for child in modules
        .values()
        .filter(|m| m.parent.as_ref() == Some(&module.name))
    {
        print(modules, child, depth + 1)?;
    }
    Ok(())
}

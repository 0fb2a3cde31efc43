//! `ndds record`: topics into an MCAP file (or a directory of split files), with a live status
//! line on a terminal and a summary at the end; Ctrl-C finishes the file properly.

use std::io::{IsTerminal as _, Write as _};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use ndds_bag::info::human_bytes;
use ndds_bag::record::{RecordOptions, Recorder, Selection, Snapshot, Summary};
use ndds_bag::write::{Compression, WriteOptions};
use ndds_client::ports::{PortError, PortOwner, PortUser, ReplyHandle};
use regex::Regex;
use serde_json::json;

use crate::connect::{DaemonArgs, connect};
use crate::{outln, seconds};

/// Options of `ndds record`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Topics to record (each taken when it appears).
    topics: Vec<String>,
    /// Record every topic.
    #[arg(long, conflicts_with_all = ["topics", "regex"])]
    all: bool,
    /// Record the topics whose name matches this regular expression.
    #[arg(long, value_name = "REGEX", conflicts_with = "topics")]
    regex: Option<Regex>,
    /// Never record topics whose name matches this regular expression.
    #[arg(long, value_name = "REGEX")]
    exclude: Option<Regex>,
    /// The file to write (never over an existing one); with --max-size or --max-duration, a
    /// directory of files NAME_0.mcap, NAME_1.mcap, ... [default: ndds_TIME.mcap, TIME in UTC]
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Start a new file at this size (bytes; K, M, G suffixes: 512M).
    #[arg(long, value_parser = parse_size)]
    max_size: Option<u64>,
    /// Start a new file after this many seconds.
    #[arg(long, value_parser = seconds::parse)]
    max_duration: Option<Duration>,
    /// Chunk compression: zstd, lz4 or none.
    #[arg(long, default_value = "zstd", value_parser = parse_compression)]
    compression: Compression,
    /// Uncompressed bytes per chunk (K, M suffixes): about what a recorder killed with -9
    /// loses.
    #[arg(long, default_value = "1M", value_parser = parse_size)]
    chunk_size: u64,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long, value_parser = seconds::parse)]
    duration: Option<Duration>,
    /// Bytes of samples that may wait for the disk (K, M, G suffixes); past it samples are
    /// dropped and counted.
    #[arg(long, default_value = "256M", value_parser = parse_size)]
    queue: u64,
    /// No status line (it is off anyway when standard error is not a terminal).
    #[arg(long, short)]
    quiet: bool,
    /// Also write every sample as JSON, on a channel `json/TOPIC` with a JSON Schema made
    /// from its type, for viewers that do not know ndds (Foxglove, Lichtblick, Python).
    #[arg(long)]
    json: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    summary_json: bool,
    /// Black box: keep the last SECONDS in memory and write them to a new file of the output
    /// directory only when asked (SIGUSR1, `ndds record --trigger NAME`, a query on port
    /// snapshot.NAME, a state machine's `snapshot NAME` action).
    #[arg(long, value_name = "SECONDS", value_parser = seconds::parse)]
    snapshot: Option<Duration>,
    /// The black box keeps at most this many bytes of samples (K, M, G suffixes).
    #[arg(long, default_value = "512M", value_parser = parse_size, requires = "snapshot")]
    snapshot_bytes: u64,
    /// The black box's name (its port is snapshot.NAME).
    #[arg(long, default_value = "recorder")]
    name: String,
    /// Ask the black box NAME for a snapshot, print the file it wrote, and exit.
    #[arg(long, value_name = "NAME", conflicts_with_all = ["topics", "all", "regex", "snapshot"])]
    trigger: Option<String>,
    /// Why (with --trigger): written into the snapshot's metadata.
    #[arg(
        long,
        default_value = "asked from the command line",
        requires = "trigger"
    )]
    reason: String,
}

/// The port of black box `name`: request the reason, reply the file written or why not.
fn snapshot_port(name: &str) -> String {
    format!("snapshot.{name}")
}

type SnapshotReply = Result<String, String>;

/// The receive buffer `ndds record` asks for.
const RECORDER_RECV_BUFFER: usize = 64 << 20;

/// `ndds record --trigger NAME`.
fn trigger(daemon: &DaemonArgs, name: &str, reason: &str) -> anyhow::Result<()> {
    let participant = connect(daemon)?;
    let port = snapshot_port(name);
    let user = PortUser::<String, SnapshotReply>::declare(&participant, &port, "ndds-trigger")?;
    match user.send(&reason.to_owned(), Duration::from_secs(60)) {
        Ok(Ok(path)) => outln!("{path}").map_err(Into::into),
        Ok(Err(why)) => anyhow::bail!("black box `{name}` wrote no snapshot: {why}"),
        Err(PortError::Timeout { .. }) => anyhow::bail!(
            "no answer from black box `{name}` (port {port}) within 60 s: is `ndds record \
             --snapshot SECONDS --name {name}` running in this domain?"
        ),
        Err(err) => Err(err.into()),
    }
}

/// Runs `ndds record`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    if let Some(name) = &args.trigger {
        return trigger(daemon, name, &args.reason);
    }
    let selection = match (&args.regex, args.all, args.topics.is_empty()) {
        (Some(re), _, _) => Selection::Regex(re.clone()),
        (None, true, _) => Selection::All,
        (None, false, false) => Selection::Topics(args.topics.clone()),
        (None, false, true) => {
            anyhow::bail!("name the topics to record, or give --all or --regex REGEX")
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // A second Ctrl-C exits at once (the file then ends like one of a killed recorder).
        signal_hook::flag::register_conditional_shutdown(signal, 130, Arc::clone(&stop))
            .context("cannot catch signals")?;
        signal_hook::flag::register(signal, Arc::clone(&stop)).context("cannot catch signals")?;
    }
    let output = args.output.clone().unwrap_or_else(default_name);
    // A recorder's receive thread shares the cores with the disk's writeback and often with
    // the publishers: a large socket buffer rides out the moments it is not scheduled
    // (granted up to `net.core.rmem_max`, or fully with CAP_NET_ADMIN; NDDS_RECV_BUFFER
    // overrides it).
    let participant = crate::connect::connect_with(daemon, |builder| {
        match std::env::var_os("NDDS_RECV_BUFFER") {
            Some(_) => builder,
            None => builder.receive_buffer(RECORDER_RECV_BUFFER),
        }
    })?;
    let mut metadata = std::collections::BTreeMap::new();
    metadata.insert(
        "recorder".into(),
        format!("ndds {}", env!("CARGO_PKG_VERSION")),
    );
    metadata.insert(
        "host".into(),
        std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_owned())
            .unwrap_or_default(),
    );
    let options = RecordOptions {
        selection,
        exclude: args.exclude.clone(),
        write: WriteOptions {
            compression: args.compression,
            chunk_size: args.chunk_size,
            max_size: args.max_size,
            max_duration: args.max_duration,
            metadata,
            ..WriteOptions::default()
        },
        queue_bytes: usize::try_from(args.queue).unwrap_or(usize::MAX),
        json: args.json,
        snapshot: args.snapshot.map(|duration| Snapshot {
            duration,
            max_bytes: usize::try_from(args.snapshot_bytes).unwrap_or(usize::MAX),
        }),
    };
    let output = match (&args.output, args.snapshot) {
        (None, Some(_)) => PathBuf::from(format!("ndds_snapshots_{}", args.name)),
        _ => output,
    };
    let mut recorder = Recorder::start(&participant, &output, options)?;
    // A black box answers on its port and to SIGUSR1.
    let usr1 = Arc::new(AtomicBool::new(false));
    let port = match args.snapshot {
        Some(_) => {
            signal_hook::flag::register(signal_hook::consts::SIGUSR1, Arc::clone(&usr1))
                .context("cannot catch SIGUSR1")?;
            Some(PortOwner::<String, SnapshotReply>::declare(
                &participant,
                &snapshot_port(&args.name),
                "recorder",
            )?)
        }
        None => None,
    };
    let live = !args.quiet && std::io::stderr().is_terminal();
    let started = Instant::now();
    let mut next_discovery = Instant::now();
    let mut next_status = Instant::now();
    let mut announced = std::collections::BTreeSet::new();
    while !stop.load(Ordering::Relaxed) {
        if args.duration.is_some_and(|d| started.elapsed() >= d) {
            break;
        }
        if recorder.failed().is_some() {
            break;
        }
        let now = Instant::now();
        if now >= next_discovery {
            for topic in recorder.discover()? {
                if announced.insert(topic.clone()) && !live && !args.quiet && !args.summary_json {
                    eprintln!("ndds record: recording {topic}");
                }
            }
            next_discovery = now + Duration::from_millis(500);
        }
        if live && now >= next_status {
            status_line(&recorder, started.elapsed());
            next_status = now + Duration::from_millis(250);
        }
        if usr1.swap(false, Ordering::Relaxed) {
            snapshot_now(&recorder, "SIGUSR1", live, None);
        }
        match &port {
            Some(port) => match port.receive(Duration::from_millis(20)) {
                Ok((reason, reply)) => snapshot_now(&recorder, &reason, live, Some(reply)),
                Err(PortError::Timeout { .. }) => {}
                Err(err) => tracing::warn!(%err, "snapshot port"),
            },
            None => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    if live {
        eprint!("\r\x1b[K");
    }
    let summary = recorder.finish()?;
    print_summary(&summary, started.elapsed(), args.summary_json)?;
    if let Some(why) = &summary.stopped {
        anyhow::bail!("recording stopped early: {why}");
    }
    Ok(())
}

/// Writes a snapshot, says so, and answers the port's request if there is one.
fn snapshot_now(
    recorder: &Recorder,
    reason: &str,
    live: bool,
    reply: Option<ReplyHandle<SnapshotReply>>,
) {
    let result = recorder
        .trigger(reason, Duration::from_secs(50))
        .map(|path| path.display().to_string())
        .map_err(|e| e.to_string());
    let line = match &result {
        Ok(path) => format!("snapshot ({reason}): {path}"),
        Err(why) => format!("snapshot ({reason}) not written: {why}"),
    };
    if live {
        eprint!("\r\x1b[K");
    }
    eprintln!("ndds record: {line}");
    if let Some(reply) = reply
        && let Err(err) = reply.reply(&result)
    {
        tracing::warn!(%err, "the snapshot's answer was not sent");
    }
}

/// `ndds_2026-12-06T08-31-37Z.mcap`, in the current directory.
fn default_name() -> PathBuf {
    let now = humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string();
    PathBuf::from(format!("ndds_{}.mcap", now.replace(':', "-")))
}

fn status_line(recorder: &Recorder, elapsed: Duration) {
    let stats = recorder.stats();
    let messages: u64 = stats.values().map(|t| t.messages).sum();
    let bytes: u64 = stats.values().map(|t| t.bytes).sum();
    let lost: u64 = stats.values().map(|t| t.lost.total()).sum();
    let mut line = format!(
        "recording {:.1} s  {} topics  {messages} msgs  {}  lost {lost}",
        elapsed.as_secs_f64(),
        stats.len(),
        human_bytes(bytes)
    );
    for (topic, t) in stats.iter().take(4) {
        line.push_str(&format!("  | {topic} {}", t.messages));
    }
    if stats.len() > 4 {
        line.push_str("  | ...");
    }
    let mut err = std::io::stderr().lock();
    // One write, so the terminal never shows half a line.
    let _ = err.write_all(format!("\r\x1b[K{line}").as_bytes());
    let _ = err.flush();
}

fn print_summary(summary: &Summary, elapsed: Duration, json: bool) -> anyhow::Result<()> {
    if json {
        let topics: Vec<_> = summary
            .topics
            .iter()
            .map(|(topic, t)| {
                json!({"topic": topic, "messages": t.messages, "bytes": t.bytes,
                       "lost_gaps": t.lost.gaps, "lost_overflow": t.lost.overflow})
            })
            .collect();
        let files: Vec<String> = summary
            .files
            .iter()
            .map(|f| f.display().to_string())
            .collect();
        outln!(
            "{}",
            json!({"files": files, "seconds": elapsed.as_secs_f64(),
                   "messages": summary.messages(), "lost": summary.lost(),
                   "stopped": summary.stopped, "topics": topics})
        )?;
        return Ok(());
    }
    for file in &summary.files {
        outln!("wrote {}", file.display())?;
    }
    outln!(
        "{} messages of {} topics in {:.1} s, {} lost",
        summary.messages(),
        summary.topics.len(),
        elapsed.as_secs_f64(),
        summary.lost()
    )?;
    for (topic, t) in &summary.topics {
        let mut line = format!("  {topic}: {} msgs, {}", t.messages, human_bytes(t.bytes));
        if t.lost.total() > 0 {
            line.push_str(&format!(
                ", lost {} ({} gaps in sequence numbers, {} the recorder could not keep up with)",
                t.lost.total(),
                t.lost.gaps,
                t.lost.overflow
            ));
        }
        outln!("{line}")?;
    }
    Ok(())
}

/// Bytes with an optional K, M or G suffix (powers of 1024).
pub fn parse_size(text: &str) -> Result<u64, String> {
    let text = text.trim();
    let (number, unit) = match text.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((at, _)) => text.split_at(at),
        None => (text, ""),
    };
    let scale: u64 = match unit.to_ascii_uppercase().trim_end_matches(['B', 'I']) {
        "" => 1,
        "K" => 1 << 10,
        "M" => 1 << 20,
        "G" => 1 << 30,
        _ => {
            return Err(format!(
                "{text:?}: a size is a number of bytes, with K, M or G"
            ));
        }
    };
    let value: f64 = number
        .trim()
        .parse()
        .map_err(|_| format!("{text:?} is not a size (bytes, with K, M or G)"))?;
    if !(value.is_finite() && value > 0.0) {
        return Err(format!("{text} is not a positive size"));
    }
    Ok((value * scale as f64) as u64)
}

/// A chunk compression by name: zstd, lz4 or none.
pub fn parse_compression(text: &str) -> Result<Compression, String> {
    Compression::from_name(text)
        .ok_or_else(|| format!("unknown compression `{text}` (zstd, lz4 or none)"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_take_suffixes_and_refuse_nonsense() {
        assert_eq!(parse_size("512"), Ok(512));
        assert_eq!(parse_size("1K"), Ok(1024));
        assert_eq!(parse_size("1.5M"), Ok(1_572_864));
        assert_eq!(parse_size("2GiB"), Ok(2 << 30));
        assert!(parse_size("-1").is_err());
        assert!(parse_size("10X").is_err());
        assert!(parse_size("lots").is_err());
    }
}

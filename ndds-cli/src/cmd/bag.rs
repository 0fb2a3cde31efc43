//! `ndds bag info | filter | cut`: what a recording holds, and parts of recordings into new
//! files.

use std::path::PathBuf;
use std::time::Duration;

use ndds_bag::edit::{Keep, rewrite};
use ndds_bag::info::BagInfo;
use ndds_bag::write::{Compression, WriteOptions};
use regex::Regex;
use serde_json::json;

use crate::cmd::record::{parse_compression, parse_size};
use crate::{outln, seconds};

/// Options of `ndds bag`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    action: Action,
}

#[derive(Debug, clap::Subcommand)]
enum Action {
    /// Duration, time range, per-topic counts, types, sizes, compression, losses; and whether
    /// the file is whole (a truncated one is read up to where it ends).
    Info {
        /// The recordings.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// As JSON (one object per file, in an array).
        #[arg(long)]
        json: bool,
    },
    /// Some topics (and optionally a time range) of recordings into a new file.
    Filter {
        /// The recordings (merged in time order).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// The new file.
        #[arg(short, long)]
        output: PathBuf,
        /// Keep only these topics.
        #[arg(long, num_args = 1..)]
        topics: Option<Vec<String>>,
        /// Drop topics whose name matches this regular expression.
        #[arg(long, value_name = "REGEX")]
        exclude: Option<Regex>,
        /// Keep from this many seconds after the recording's start.
        #[arg(long, value_parser = seconds::parse)]
        start: Option<Duration>,
        /// Keep this many seconds (after --start).
        #[arg(long, value_parser = seconds::parse)]
        duration: Option<Duration>,
        #[command(flatten)]
        write: WriteArgs,
    },
    /// A time range of recordings into a new file (every topic).
    Cut {
        /// The recordings (merged in time order).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// The new file.
        #[arg(short, long)]
        output: PathBuf,
        /// From this many seconds after the recording's start.
        #[arg(long, value_parser = seconds::parse, default_value = "0")]
        start: Duration,
        /// This many seconds (default: to the end).
        #[arg(long, value_parser = seconds::parse)]
        duration: Option<Duration>,
        #[command(flatten)]
        write: WriteArgs,
    },
}

/// How the new file is written.
#[derive(Debug, clap::Args)]
struct WriteArgs {
    /// Chunk compression: zstd, lz4 or none.
    #[arg(long, default_value = "zstd", value_parser = parse_compression)]
    compression: Compression,
    /// Uncompressed bytes per chunk (K, M suffixes).
    #[arg(long, default_value = "1M", value_parser = parse_size)]
    chunk_size: u64,
}

/// Runs `ndds bag`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    match &args.action {
        Action::Info { files, json } => {
            let mut all = Vec::new();
            for (i, file) in files.iter().enumerate() {
                let info = BagInfo::read(file)?;
                if *json {
                    all.push(info.to_json());
                } else {
                    if i > 0 {
                        outln!()?;
                    }
                    crate::out!("{info}")?;
                }
            }
            if *json {
                outln!("{}", serde_json::Value::Array(all))?;
            }
        }
        Action::Filter {
            files,
            output,
            topics,
            exclude,
            start,
            duration,
            write,
        } => {
            let keep = Keep {
                topics: topics.clone(),
                exclude: exclude.clone(),
                ..time_range(files, start.unwrap_or_default(), *duration)?
            };
            edit(files, output, &keep, write)?;
        }
        Action::Cut {
            files,
            output,
            start,
            duration,
            write,
        } => {
            let keep = time_range(files, *start, *duration)?;
            edit(files, output, &keep, write)?;
        }
    }
    Ok(())
}

/// Keeps messages from `start` after the first one, for `duration`.
fn time_range(
    files: &[PathBuf],
    start: Duration,
    duration: Option<Duration>,
) -> anyhow::Result<Keep> {
    let Some(first) = ndds_bag::read::first_log_time(files)? else {
        return Ok(Keep::default());
    };
    let nanos = |d: Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
    let from = first.saturating_add(nanos(start));
    Ok(Keep {
        from: Some(from),
        to: duration.map(|d| from.saturating_add(nanos(d))),
        ..Keep::default()
    })
}

fn edit(
    files: &[PathBuf],
    output: &std::path::Path,
    keep: &Keep,
    write: &WriteArgs,
) -> anyhow::Result<()> {
    let options = WriteOptions {
        compression: write.compression,
        chunk_size: write.chunk_size,
        ..WriteOptions::default()
    };
    let done = rewrite(files, output, keep, options)?;
    for warning in &done.warnings {
        eprintln!("ndds bag: {warning}");
    }
    outln!(
        "{}",
        json!({"output": output.display().to_string(), "read": done.read, "kept": done.kept})
    )?;
    Ok(())
}

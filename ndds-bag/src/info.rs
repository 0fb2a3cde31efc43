//! What a bag holds: [`BagInfo`] reads a whole file (a truncated one up to where it ends) and
//! counts per topic; `ndds bag info` prints it as text or JSON.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::BagError;
use crate::format;
use crate::read::{BagReader, ChunkStats, Ending};
use crate::write::Lost;

/// One topic of a bag.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TopicInfo {
    /// The type's name (its schema's name).
    pub type_name: String,
    /// The schema encoding (`ndds` for ndds recordings).
    pub schema_encoding: String,
    /// Messages.
    pub messages: u64,
    /// Payload bytes.
    pub bytes: u64,
    /// Recorded producers (channels).
    pub producers: usize,
    /// What the recorder lost (from the file's metadata).
    pub lost: Lost,
}

/// What a bag holds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BagInfo {
    /// The file.
    pub path: PathBuf,
    /// Its size in bytes.
    pub size: u64,
    /// First and last log time (ns since the Unix epoch), if it holds messages.
    pub time_range: Option<(u64, u64)>,
    /// Messages in all.
    pub messages: u64,
    /// Per topic.
    pub topics: BTreeMap<String, TopicInfo>,
    /// Chunks by compression (from the summary).
    pub chunks: BTreeMap<String, ChunkStats>,
    /// Whether the recording's metadata is there (it is written last: a file without it was
    /// not finished, so its losses are unknown).
    pub finished: bool,
    /// How reading ended.
    pub ending: Ending,
}

impl BagInfo {
    /// Reads `path` through.
    pub fn read(path: &Path) -> Result<Self, BagError> {
        let mut reader = BagReader::open(path)?;
        let mut topics: BTreeMap<String, TopicInfo> = BTreeMap::new();
        let mut channels_seen = std::collections::HashSet::new();
        let mut time_range: Option<(u64, u64)> = None;
        let mut messages = 0;
        while let Some(message) = reader.next_message()? {
            messages += 1;
            let topic = topics.entry(message.channel.topic.clone()).or_default();
            if channels_seen.insert(message.channel.id) {
                topic.producers += 1;
                topic.type_name.clone_from(&message.channel.schema_name);
                topic
                    .schema_encoding
                    .clone_from(&message.channel.schema_encoding);
            }
            topic.messages += 1;
            topic.bytes += message.data.len() as u64;
            time_range = Some(match time_range {
                None => (message.log_time, message.log_time),
                Some((a, b)) => (a.min(message.log_time), b.max(message.log_time)),
            });
        }
        // Channels without messages are topics too.
        for channel in reader.channels() {
            let topic = topics.entry(channel.topic.clone()).or_default();
            if topic.type_name.is_empty() {
                topic.type_name.clone_from(&channel.schema_name);
                topic.schema_encoding.clone_from(&channel.schema_encoding);
            }
        }
        let mut finished = false;
        for (name, metadata) in reader.metadata() {
            if name != format::RECORDING_METADATA {
                continue;
            }
            finished = true;
            for (key, value) in metadata {
                let count: u64 = value.parse().unwrap_or(0);
                if let Some(topic) = key.strip_prefix("gaps:") {
                    topics.entry(topic.to_owned()).or_default().lost.gaps += count;
                } else if let Some(topic) = key.strip_prefix("overflow:") {
                    topics.entry(topic.to_owned()).or_default().lost.overflow += count;
                }
            }
        }
        Ok(BagInfo {
            path: path.to_owned(),
            size: reader.length(),
            time_range,
            messages,
            topics,
            chunks: reader.chunks().clone(),
            finished,
            ending: reader.ending().clone(),
        })
    }

    /// Seconds from the first message to the last.
    pub fn duration_s(&self) -> f64 {
        self.time_range
            .map_or(0.0, |(a, b)| (b.saturating_sub(a)) as f64 / 1e9)
    }

    /// Samples lost in all (from the metadata).
    pub fn lost(&self) -> u64 {
        self.topics.values().map(|t| t.lost.total()).sum()
    }

    /// What reading the file says, in words.
    pub fn ending_text(&self) -> String {
        match &self.ending {
            Ending::Reading | Ending::Complete if self.finished => "complete".to_owned(),
            Ending::Reading | Ending::Complete => {
                "complete, but without the recording's metadata (not written by ndds, or not \
                 finished): losses unknown"
                    .to_owned()
            }
            Ending::Truncated { length } => format!(
                "truncated at byte {length}: the last chunk (up to its chunk size of samples) \
                 and the summary are missing, and so are the recording's loss counts; \
                 everything before was read"
            ),
            Ending::Damaged { error } => {
                format!("damaged: {error}; everything before was read")
            }
        }
    }

    /// As JSON.
    pub fn to_json(&self) -> Value {
        let topics: Vec<Value> = self
            .topics
            .iter()
            .map(|(name, t)| {
                json!({
                    "topic": name,
                    "type": t.type_name,
                    "schema_encoding": t.schema_encoding,
                    "messages": t.messages,
                    "bytes": t.bytes,
                    "producers": t.producers,
                    "lost_gaps": t.lost.gaps,
                    "lost_overflow": t.lost.overflow,
                })
            })
            .collect();
        let chunks: BTreeMap<&str, Value> = self
            .chunks
            .iter()
            .map(|(c, s)| {
                let name = if c.is_empty() { "none" } else { c.as_str() };
                (
                    name,
                    json!({"chunks": s.count, "compressed": s.compressed,
                           "uncompressed": s.uncompressed}),
                )
            })
            .collect();
        json!({
            "path": self.path.display().to_string(),
            "size": self.size,
            "start_ns": self.time_range.map(|r| r.0),
            "end_ns": self.time_range.map(|r| r.1),
            "duration_s": self.duration_s(),
            "messages": self.messages,
            "lost": self.lost(),
            "finished": self.finished,
            "state": match &self.ending {
                Ending::Truncated { .. } => "truncated",
                Ending::Damaged { .. } => "damaged",
                _ => "complete",
            },
            "state_text": self.ending_text(),
            "compression": chunks,
            "topics": topics,
        })
    }
}

impl fmt::Display for BagInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "file:        {}", self.path.display())?;
        writeln!(f, "size:        {}", human_bytes(self.size))?;
        writeln!(f, "state:       {}", self.ending_text())?;
        match self.time_range {
            Some((start, end)) => {
                writeln!(f, "duration:    {:.3} s", self.duration_s())?;
                writeln!(
                    f,
                    "start, end:  {:.6}, {:.6} (s since the Unix epoch)",
                    start as f64 / 1e9,
                    end as f64 / 1e9
                )?;
            }
            None => writeln!(f, "duration:    (no messages)")?,
        }
        writeln!(f, "messages:    {}", self.messages)?;
        let lost = if self.finished {
            self.lost().to_string()
        } else {
            "unknown (no recording metadata)".to_owned()
        };
        writeln!(f, "lost:        {lost}")?;
        for (compression, stats) in &self.chunks {
            let name = if compression.is_empty() {
                "none"
            } else {
                compression
            };
            writeln!(
                f,
                "compression: {name}: {} chunks, {} -> {}",
                stats.count,
                human_bytes(stats.uncompressed),
                human_bytes(stats.compressed)
            )?;
        }
        writeln!(f, "topics:")?;
        let width = self.topics.keys().map(String::len).max().unwrap_or(0);
        for (name, t) in &self.topics {
            let mut line = format!(
                "  {name:width$}  {:>8} msgs  {:>10}  {}",
                t.messages,
                human_bytes(t.bytes),
                t.type_name
            );
            if t.schema_encoding != format::SCHEMA_ENCODING {
                line.push_str(&format!(" (schema encoding `{}`)", t.schema_encoding));
            }
            if t.producers > 1 {
                line.push_str(&format!("  {} producers", t.producers));
            }
            if t.lost.total() > 0 {
                line.push_str(&format!(
                    "  lost {} ({} gaps, {} overflow)",
                    t.lost.total(),
                    t.lost.gaps,
                    t.lost.overflow
                ));
            }
            writeln!(f, "{line}")?;
        }
        Ok(())
    }
}

/// Bytes as people read them.
pub fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit < UNITS.len() - 1 {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}

//! Rewriting bags: the messages of some topics and a time range of one or more files into a
//! new file (`ndds bag filter` and `ndds bag cut`), channels, schemas and recorded losses
//! kept.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use regex::Regex;

use crate::read::Merged;
use crate::write::{BagWriter, ChannelKey, Lost, Record, WriteOptions};
use crate::{BagError, format};

/// What to keep.
#[derive(Clone, Debug, Default)]
pub struct Keep {
    /// Only these topics (`None`: all).
    pub topics: Option<Vec<String>>,
    /// Never these topics.
    pub exclude: Option<Regex>,
    /// Only messages logged at or after this (ns since the Unix epoch).
    pub from: Option<u64>,
    /// Only messages logged at or before this.
    pub to: Option<u64>,
}

impl Keep {
    /// Whether a channel's topic is kept (a JSON companion goes with its topic).
    fn channel(&self, channel: &crate::read::BagChannel) -> bool {
        self.topic(channel.json_of().unwrap_or(&channel.topic))
    }

    fn topic(&self, topic: &str) -> bool {
        if self.exclude.as_ref().is_some_and(|re| re.is_match(topic)) {
            return false;
        }
        self.topics
            .as_ref()
            .is_none_or(|topics| topics.iter().any(|t| t == topic))
    }

    fn time(&self, log_time: u64) -> bool {
        self.from.is_none_or(|from| log_time >= from) && self.to.is_none_or(|to| log_time <= to)
    }
}

/// What a rewrite did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Rewritten {
    /// Messages read.
    pub read: u64,
    /// Messages written.
    pub kept: u64,
    /// Warnings about the inputs (truncated, damaged).
    pub warnings: Vec<String>,
}

/// Writes the messages of `inputs` that `keep` keeps into a new file `output`.
pub fn rewrite(
    inputs: &[PathBuf],
    output: &Path,
    keep: &Keep,
    mut options: WriteOptions,
) -> Result<Rewritten, BagError> {
    let sources: Vec<String> = inputs.iter().map(|p| p.display().to_string()).collect();
    options.metadata.insert("source".into(), sources.join(", "));
    let mut writer = BagWriter::create(output, options)?;
    let mut merged = Merged::open(inputs)?;
    let mut channels: HashMap<(PathBuf, u16), ChannelKey> = HashMap::new();
    let mut done = Rewritten::default();
    let result = (|| {
        while let Some((message, path)) = merged.next_message()? {
            done.read += 1;
            let channel = &message.channel;
            if !keep.channel(channel) || !keep.time(message.log_time) {
                continue;
            }
            let key = match channels.get(&(path.to_owned(), channel.id)) {
                Some(key) => *key,
                None => {
                    let key = writer.add_raw_channel(channel.to_def());
                    channels.insert((path.to_owned(), channel.id), key);
                    key
                }
            };
            writer.write(Record {
                channel: key,
                seq: u64::from(message.sequence),
                log_time: message.log_time,
                publish_time: message.publish_time,
                data: &message.data,
            })?;
            done.kept += 1;
        }
        Ok::<(), BagError>(())
    })();
    // The recorded losses of the kept topics go along (they are the source's, whole).
    for reader in merged.readers() {
        for (name, metadata) in reader.metadata() {
            if name != format::RECORDING_METADATA {
                continue;
            }
            for (key, value) in metadata {
                let count = value.parse().unwrap_or(0);
                if let Some(topic) = key.strip_prefix("gaps:").filter(|t| keep.topic(t)) {
                    writer.note_lost(
                        topic,
                        Lost {
                            gaps: count,
                            overflow: 0,
                        },
                    );
                } else if let Some(topic) = key.strip_prefix("overflow:").filter(|t| keep.topic(t))
                {
                    writer.note_lost(
                        topic,
                        Lost {
                            gaps: 0,
                            overflow: count,
                        },
                    );
                }
            }
        }
        if let Some(warning) = crate::play::ending_warning(reader) {
            done.warnings.push(warning);
        }
    }
    writer.finish()?;
    result?;
    Ok(done)
}

//! Reading bags: [`BagReader`] streams one MCAP file's messages in file order with bounded
//! memory, and reads a truncated or damaged file up to its last readable record, saying
//! what happened ([`Ending`]); [`Merged`] merges several files in log-time order.

use std::collections::{BTreeMap, BinaryHeap, HashMap};
use std::fs::File;
use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use ndds_core::types::TypeDescription;

use crate::BagError;
use crate::format::{self, ChannelMeta};

/// Largest record a reader accepts (a bound on what a forged length can make it allocate).
pub const MAX_RECORD: usize = 256 << 20;

/// A channel of a bag.
#[derive(Clone, Debug)]
pub struct BagChannel {
    /// Its id in the file.
    pub id: u16,
    /// The topic.
    pub topic: String,
    /// Its schema's name (the type's name in ndds files).
    pub schema_name: String,
    /// Its schema's encoding (`ndds` in ndds files).
    pub schema_encoding: String,
    /// Its messages' encoding.
    pub message_encoding: String,
    /// The type description, or why there is none (another schema encoding, a broken one).
    pub desc: Result<TypeDescription, String>,
    /// The recorded producer's QoS (defaults in files from elsewhere).
    pub meta: ChannelMeta,
    /// The channel's metadata as written.
    pub metadata: BTreeMap<String, String>,
    /// Its schema's data as written.
    pub schema_data: Vec<u8>,
}

impl BagChannel {
    /// The topic this channel is the JSON companion of, in a recording made with `--json`
    /// (players skip such channels: their samples are on the topic's own channel).
    pub fn json_of(&self) -> Option<&str> {
        self.metadata.get(format::JSON_OF).map(String::as_str)
    }

    /// The channel as a writer takes it (to copy it into another file).
    pub fn to_def(&self) -> crate::write::ChannelDef {
        crate::write::ChannelDef {
            topic: self.topic.clone(),
            schema: (
                self.schema_name.clone(),
                self.schema_encoding.clone(),
                self.schema_data.clone(),
            ),
            message_encoding: self.message_encoding.clone(),
            metadata: self.metadata.clone(),
        }
    }
}

impl BagChannel {
    /// The type description, or an error naming the channel that cannot be replayed.
    pub fn playable(&self, path: &Path) -> Result<&TypeDescription, BagError> {
        if self.message_encoding != format::MESSAGE_ENCODING
            || self.schema_encoding != format::SCHEMA_ENCODING
        {
            return Err(BagError::Unplayable {
                path: path.to_owned(),
                channel: self.id,
                topic: self.topic.clone(),
                why: format!(
                    "schema encoding `{}` and message encoding `{}` (ndds plays `{}` and `{}`: \
                     recordings made by ndds)",
                    self.schema_encoding,
                    self.message_encoding,
                    format::SCHEMA_ENCODING,
                    format::MESSAGE_ENCODING
                ),
            });
        }
        self.desc.as_ref().map_err(|why| BagError::Unplayable {
            path: path.to_owned(),
            channel: self.id,
            topic: self.topic.clone(),
            why: why.clone(),
        })
    }
}

/// One recorded sample.
#[derive(Clone, Debug)]
pub struct BagMessage {
    /// Its channel.
    pub channel: Arc<BagChannel>,
    /// The low 32 bits of the producer's sequence number.
    pub sequence: u32,
    /// When it was received (ns since the Unix epoch).
    pub log_time: u64,
    /// When it was written (ns since the Unix epoch).
    pub publish_time: u64,
    /// Its payload.
    pub data: Vec<u8>,
}

/// How reading a file ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Ending {
    /// Not yet at the end.
    Reading,
    /// At the end, with the file whole.
    Complete,
    /// The file ends in the middle of a record (a recorder killed, a copy cut short): what
    /// was read before is good, the rest of that record (a chunk of up to its chunk size)
    /// and the summary are missing.
    Truncated {
        /// Bytes of the file.
        length: u64,
    },
    /// A record could not be read (bad magic, a checksum, a record too large).
    Damaged {
        /// What the reader said.
        error: String,
    },
}

/// A chunk's compression and sizes (from the summary's chunk index).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ChunkStats {
    /// Chunks.
    pub count: u64,
    /// Compressed bytes.
    pub compressed: u64,
    /// Uncompressed bytes.
    pub uncompressed: u64,
}

/// Streams one MCAP file.
pub struct BagReader {
    path: PathBuf,
    file: File,
    length: u64,
    /// Whether the file ends with MCAP's closing magic (a whole file does; one whose writer
    /// was killed does not).
    closed: bool,
    reader: LinearReader,
    schemas: HashMap<u16, (String, String, Vec<u8>)>,
    channels: HashMap<u16, Arc<BagChannel>>,
    metadata: Vec<(String, BTreeMap<String, String>)>,
    chunks: BTreeMap<String, ChunkStats>,
    ending: Ending,
}

impl std::fmt::Debug for BagReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagReader")
            .field("path", &self.path)
            .field("ending", &self.ending)
            .finish_non_exhaustive()
    }
}

impl BagReader {
    /// Opens `path` (an MCAP file).
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let mut file = File::open(path).map_err(|e| BagError::io(path, e))?;
        let length = file.metadata().map_err(|e| BagError::io(path, e))?.len();
        let closed = ends_with_magic(&mut file).map_err(|e| BagError::io(path, e))?;
        let options = LinearReaderOptions::default().with_record_length_limit(MAX_RECORD);
        Ok(BagReader {
            path: path.to_owned(),
            file,
            length,
            closed,
            reader: LinearReader::new_with_options(options),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            metadata: Vec::new(),
            chunks: BTreeMap::new(),
            ending: Ending::Reading,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Its length in bytes.
    pub fn length(&self) -> u64 {
        self.length
    }

    /// How reading ended (once [`Self::next_message`] returned `None`).
    pub fn ending(&self) -> &Ending {
        &self.ending
    }

    /// The channels seen so far.
    pub fn channels(&self) -> impl Iterator<Item = &Arc<BagChannel>> {
        self.channels.values()
    }

    /// The metadata records seen so far.
    pub fn metadata(&self) -> &[(String, BTreeMap<String, String>)] {
        &self.metadata
    }

    /// Chunks by compression, from the summary (empty for a file without one).
    pub fn chunks(&self) -> &BTreeMap<String, ChunkStats> {
        &self.chunks
    }

    /// The next message in file order; `None` at the end of what can be read (see
    /// [`Self::ending`]). Only reading the file itself fails.
    pub fn next_message(&mut self) -> Result<Option<BagMessage>, BagError> {
        loop {
            let event = match self.reader.next_event() {
                None => {
                    self.ending = Ending::Complete;
                    return Ok(None);
                }
                Some(Err(mcap::McapError::UnexpectedEof)) => {
                    self.ending = Ending::Truncated {
                        length: self.length,
                    };
                    return Ok(None);
                }
                // Without its closing magic the file was cut short: a record or chunk that
                // ends early is the cut (a chunk's lengths are written when the chunk ends).
                Some(Err(
                    mcap::McapError::UnexpectedEoc | mcap::McapError::BadChunkLength { .. },
                )) if !self.closed => {
                    self.ending = Ending::Truncated {
                        length: self.length,
                    };
                    return Ok(None);
                }
                Some(Err(error)) => {
                    self.ending = Ending::Damaged {
                        error: error.to_string(),
                    };
                    return Ok(None);
                }
                Some(Ok(event)) => event,
            };
            let record = match event {
                LinearReadEvent::ReadRequest(need) => {
                    let buffer = self.reader.insert(need);
                    let read = self
                        .file
                        .read(buffer)
                        .map_err(|e| BagError::io(&self.path, e))?;
                    self.reader.notify_read(read);
                    continue;
                }
                LinearReadEvent::Record { opcode, data } => {
                    match mcap::parse_record(opcode, data) {
                        Ok(record) => record,
                        Err(error) => {
                            self.ending = Ending::Damaged {
                                error: error.to_string(),
                            };
                            return Ok(None);
                        }
                    }
                }
            };
            match record {
                Record::Schema { header, data } => {
                    self.schemas.entry(header.id).or_insert((
                        header.name,
                        header.encoding,
                        data.into_owned(),
                    ));
                }
                Record::Channel(channel) => {
                    if self.channels.contains_key(&channel.id) {
                        continue;
                    }
                    let schema = self.schemas.get(&channel.schema_id);
                    let schema_data = schema.map(|s| s.2.clone()).unwrap_or_default();
                    let (schema_name, schema_encoding, desc) = match schema {
                        None => (
                            String::new(),
                            String::new(),
                            Err("no schema (ndds needs the type description)".to_owned()),
                        ),
                        Some((name, encoding, data)) => {
                            let desc = if encoding == format::SCHEMA_ENCODING {
                                format::decode_schema(data)
                            } else {
                                Err(format!(
                                    "schema encoding `{encoding}` (ndds plays `{}`)",
                                    format::SCHEMA_ENCODING
                                ))
                            };
                            (name.clone(), encoding.clone(), desc)
                        }
                    };
                    let meta = ChannelMeta::from_map(&channel.metadata);
                    self.channels.insert(
                        channel.id,
                        Arc::new(BagChannel {
                            id: channel.id,
                            topic: channel.topic,
                            schema_name,
                            schema_encoding,
                            message_encoding: channel.message_encoding,
                            desc,
                            meta,
                            metadata: channel.metadata,
                            schema_data,
                        }),
                    );
                }
                Record::Message { header, data } => {
                    let Some(channel) = self.channels.get(&header.channel_id) else {
                        self.ending = Ending::Damaged {
                            error: format!(
                                "a message on channel {} before that channel was declared",
                                header.channel_id
                            ),
                        };
                        return Ok(None);
                    };
                    return Ok(Some(BagMessage {
                        channel: Arc::clone(channel),
                        sequence: header.sequence,
                        log_time: header.log_time,
                        publish_time: header.publish_time,
                        data: data.into_owned(),
                    }));
                }
                Record::Metadata(metadata) => {
                    self.metadata.push((metadata.name, metadata.metadata));
                }
                Record::ChunkIndex(index) => {
                    let stats = self.chunks.entry(index.compression.clone()).or_default();
                    stats.count += 1;
                    stats.compressed += index.compressed_size;
                    stats.uncompressed += index.uncompressed_size;
                }
                _ => {}
            }
        }
    }
}

/// The earliest first log time of `paths` (each file is in log-time order as ndds writes it,
/// so its first message has its first log time); `None` when none holds a message.
pub fn first_log_time(paths: &[PathBuf]) -> Result<Option<u64>, BagError> {
    let mut first: Option<u64> = None;
    for path in paths {
        if let Some(message) = BagReader::open(path)?.next_message()? {
            first = Some(first.map_or(message.log_time, |f| f.min(message.log_time)));
        }
    }
    Ok(first)
}

/// Whether `file` ends with MCAP's magic; the file is left at its start.
fn ends_with_magic(file: &mut File) -> std::io::Result<bool> {
    use std::io::{Seek, SeekFrom};
    let length = file.metadata()?.len();
    let mut end = [0u8; 8];
    let closed = length >= 16 && {
        file.seek(SeekFrom::End(-8))?;
        file.read_exact(&mut end)?;
        end == *mcap::MAGIC
    };
    file.seek(SeekFrom::Start(0))?;
    Ok(closed)
}

/// Several bags' messages merged in log-time order (each file is in log-time order as ndds
/// writes it; a file from elsewhere that is not comes out in its own order).
#[derive(Debug)]
pub struct Merged {
    readers: Vec<BagReader>,
    heads: BinaryHeap<Head>,
}

#[derive(Debug)]
struct Head {
    message: BagMessage,
    reader: usize,
}

impl PartialEq for Head {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}

impl Eq for Head {}

impl PartialOrd for Head {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Head {
    /// Reversed: the heap's top is the earliest (then the first file).
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (other.message.log_time, other.reader).cmp(&(self.message.log_time, self.reader))
    }
}

impl Merged {
    /// Opens every file.
    pub fn open(paths: &[PathBuf]) -> Result<Self, BagError> {
        let mut readers = Vec::new();
        for path in paths {
            readers.push(BagReader::open(path)?);
        }
        let mut merged = Merged {
            readers,
            heads: BinaryHeap::new(),
        };
        for reader in 0..merged.readers.len() {
            merged.refill(reader)?;
        }
        Ok(merged)
    }

    fn refill(&mut self, reader: usize) -> Result<(), BagError> {
        if let Some(message) = self.readers[reader].next_message()? {
            self.heads.push(Head { message, reader });
        }
        Ok(())
    }

    /// The next message in log-time order, and the file it came from.
    pub fn next_message(&mut self) -> Result<Option<(BagMessage, &Path)>, BagError> {
        let Some(head) = self.heads.pop() else {
            return Ok(None);
        };
        self.refill(head.reader)?;
        Ok(Some((head.message, self.readers[head.reader].path())))
    }

    /// The readers (for their endings once every message was taken).
    pub fn readers(&self) -> &[BagReader] {
        &self.readers
    }
}

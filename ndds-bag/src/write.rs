//! Writing bags: [`BagWriter`] puts samples into one MCAP file, or a directory of files split
//! by size or duration, and always finishes a file properly (summary and index), including
//! when the disk is about to fill.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use ndds_core::types::TypeDescription;

use crate::BagError;
use crate::format::{self, ChannelMeta};

/// Chunk compression.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Compression {
    /// Zstandard (the default: the best ratio for its speed).
    #[default]
    Zstd,
    /// LZ4 (faster, larger).
    Lz4,
    /// None.
    None,
}

impl Compression {
    /// From its name: `zstd`, `lz4` or `none`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "zstd" => Some(Compression::Zstd),
            "lz4" => Some(Compression::Lz4),
            "none" => Some(Compression::None),
            _ => None,
        }
    }

    fn to_mcap(self) -> Option<mcap::Compression> {
        match self {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        }
    }
}

/// How a [`BagWriter`] writes.
#[derive(Clone, Debug)]
pub struct WriteOptions {
    /// Chunk compression.
    pub compression: Compression,
    /// Uncompressed bytes per chunk (what a reader decompresses at once, and about what a
    /// recorder killed with -9 loses).
    pub chunk_size: u64,
    /// Start a new file when this one reaches this many bytes.
    pub max_size: Option<u64>,
    /// Start a new file when this one spans this much log time.
    pub max_duration: Option<Duration>,
    /// Stop (finishing the file) when the disk has less than this many bytes free.
    pub reserve: u64,
    /// Key/value pairs written into each file's recording metadata.
    pub metadata: BTreeMap<String, String>,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            compression: Compression::Zstd,
            chunk_size: 1 << 20,
            max_size: None,
            max_duration: None,
            reserve: 8 << 20,
            metadata: BTreeMap::new(),
        }
    }
}

/// Where the files go.
#[derive(Clone, Debug)]
enum Target {
    /// One file.
    File(PathBuf),
    /// Split files `DIR/NAME_N.mcap`.
    Split { dir: PathBuf, name: String },
}

/// A channel of a bag, as the writer knows it (by index).
#[derive(Clone, Debug)]
pub struct ChannelDef {
    /// The topic.
    pub topic: String,
    /// Its schema's name, encoding and data.
    pub schema: (String, String, Vec<u8>),
    /// Its messages' encoding.
    pub message_encoding: String,
    /// Its metadata.
    pub metadata: BTreeMap<String, String>,
}

/// A channel's handle: its index in the writer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ChannelKey(usize);

/// One sample to write.
#[derive(Clone, Copy, Debug)]
pub struct Record<'a> {
    /// Its channel.
    pub channel: ChannelKey,
    /// The producer's sequence number.
    pub seq: u64,
    /// When it was received (ns since the Unix epoch).
    pub log_time: u64,
    /// When it was written (ns since the Unix epoch).
    pub publish_time: u64,
    /// Its payload.
    pub data: &'a [u8],
}

/// What a topic lost, per file and in all.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Lost {
    /// Sequence numbers that never arrived (best-effort gaps, reliable samples lost).
    pub gaps: u64,
    /// Samples the recorder received but could not keep up with.
    pub overflow: u64,
}

impl Lost {
    /// Both together.
    pub fn total(&self) -> u64 {
        self.gaps + self.overflow
    }
}

/// A `Write + Seek` that counts the bytes of the file (shared with [`Open`], since the mcap
/// writer gives no access to what it writes into).
struct Counting {
    inner: BufWriter<File>,
    position: u64,
    length: Arc<AtomicU64>,
    /// The file's bytes before this are on their way to the disk or there: writeback was
    /// started for them.
    handed: u64,
    /// The file's bytes before this were written to the disk and dropped from the page cache.
    settled: u64,
}

impl Counting {
    fn note(&mut self) {
        self.length.fetch_max(self.position, Ordering::Relaxed);
    }
}

/// How much of the file is handed to the disk at a time.
const WRITEBACK_STEP: u64 = 8 << 20;

impl Write for Counting {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.position += n as u64;
        self.note();
        if self.position >= self.handed + WRITEBACK_STEP {
            self.inner.flush()?;
            self.write_back()?;
        }
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl Counting {
    /// Keeps the dirty pages of a long recording few, without stalling the disk: a page cache
    /// full of them makes the kernel reclaim memory in whatever thread allocates next, the
    /// participant's receive thread among them, which then drops samples. Writeback of what
    /// was written since the last step starts now, and the step before it, by now most
    /// likely on the disk, is waited for and dropped from the page cache. So the disk always
    /// has the next step queued (a sync of everything would leave it idle while this thread
    /// catches up), at most two steps are dirty, and the wait is the writer thread's, which
    /// the queue before it absorbs. Durability is `finish`'s (`sync_data`).
    #[cfg(target_os = "linux")]
    fn write_back(&mut self) -> std::io::Result<()> {
        use std::os::fd::AsRawFd;
        let fd = self.inner.get_ref().as_raw_fd();
        let range = |from: u64, to: u64| -> (libc::off64_t, libc::off64_t) {
            (from as libc::off64_t, (to - from) as libc::off64_t)
        };
        let (start, len) = range(self.handed, self.position);
        // SAFETY: `fd` is this writer's open file for the whole call; sync_file_range only
        // reads its arguments.
        if unsafe { libc::sync_file_range(fd, start, len, libc::SYNC_FILE_RANGE_WRITE) } != 0 {
            return Err(std::io::Error::last_os_error());
        }
        if self.settled < self.handed {
            let (start, len) = range(self.settled, self.handed);
            let wait = libc::SYNC_FILE_RANGE_WAIT_BEFORE
                | libc::SYNC_FILE_RANGE_WRITE
                | libc::SYNC_FILE_RANGE_WAIT_AFTER;
            // SAFETY: as above.
            if unsafe { libc::sync_file_range(fd, start, len, wait) } != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // Only advice: a failure costs page cache, nothing else.
            let _ = nix::fcntl::posix_fadvise(
                self.inner.get_ref(),
                start,
                len,
                nix::fcntl::PosixFadviseAdvice::POSIX_FADV_DONTNEED,
            );
            self.settled = self.handed;
        }
        self.handed = self.position;
        Ok(())
    }

    /// Elsewhere, a sync of everything so far every step.
    #[cfg(not(target_os = "linux"))]
    fn write_back(&mut self) -> std::io::Result<()> {
        self.inner.get_ref().sync_data()?;
        self.handed = self.position;
        self.settled = self.position;
        Ok(())
    }
}

impl Seek for Counting {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        self.position = self.inner.seek(to)?;
        self.note();
        Ok(self.position)
    }
}

/// The file being written.
struct Open {
    path: PathBuf,
    writer: mcap::Writer<Counting>,
    length: Arc<AtomicU64>,
    /// The writer's channel id for each channel key used in this file.
    channels: HashMap<ChannelKey, u16>,
    first_log_time: Option<u64>,
    last_log_time: u64,
    lost: BTreeMap<String, Lost>,
    /// File length at the last free-space check.
    checked_at: u64,
}

/// Writes samples into MCAP files.
pub struct BagWriter {
    target: Target,
    options: WriteOptions,
    channels: Vec<ChannelDef>,
    open: Option<Open>,
    files: Vec<PathBuf>,
    messages: u64,
}

impl std::fmt::Debug for BagWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagWriter")
            .field("target", &self.target)
            .field("files", &self.files)
            .field("messages", &self.messages)
            .finish_non_exhaustive()
    }
}

/// Makes a directory for recordings: new, or an existing empty one (never one with files,
/// which a recording could be mistaken for or mixed with).
pub(crate) fn prepare_dir(dir: &Path) -> Result<(), BagError> {
    if dir.exists() {
        let empty = std::fs::read_dir(dir)
            .map_err(|e| BagError::io(dir, e))?
            .next()
            .is_none();
        if !empty {
            return Err(BagError::Exists(dir.to_owned()));
        }
        return Ok(());
    }
    std::fs::create_dir_all(dir).map_err(|e| BagError::io(dir, e))
}

/// Free-space checks happen at most once per this many bytes written.
const SPACE_CHECK_BYTES: u64 = 1 << 20;

impl BagWriter {
    /// A writer of one file at `path` (never over an existing one). With `max_size` or
    /// `max_duration` in `options`, `path` is a directory (made, and empty or new) of split
    /// files `NAME_0.mcap`, `NAME_1.mcap`, ... where NAME is the directory's name.
    pub fn create(path: &Path, options: WriteOptions) -> Result<Self, BagError> {
        let target = if options.max_size.is_some() || options.max_duration.is_some() {
            prepare_dir(path)?;
            let name = path
                .file_name()
                .map_or_else(|| "ndds".to_owned(), |n| n.to_string_lossy().into_owned());
            Target::Split {
                dir: path.to_owned(),
                name,
            }
        } else {
            if path.exists() {
                return Err(BagError::Exists(path.to_owned()));
            }
            Target::File(path.to_owned())
        };
        let mut writer = BagWriter {
            target,
            options,
            channels: Vec::new(),
            open: None,
            files: Vec::new(),
            messages: 0,
        };
        writer.open_next()?;
        Ok(writer)
    }

    /// Adds a channel (a topic and one of its producers); it is written into each file when
    /// its first sample is.
    pub fn add_channel(
        &mut self,
        topic: &str,
        desc: &TypeDescription,
        meta: ChannelMeta,
    ) -> ChannelKey {
        self.add_raw_channel(ChannelDef {
            topic: topic.to_owned(),
            schema: (
                desc.name.clone(),
                format::SCHEMA_ENCODING.to_owned(),
                format::encode_schema(desc),
            ),
            message_encoding: format::MESSAGE_ENCODING.to_owned(),
            metadata: meta.to_map(),
        })
    }

    /// Adds a channel of any encoding (a JSON companion, one copied from another file).
    pub fn add_raw_channel(&mut self, def: ChannelDef) -> ChannelKey {
        self.channels.push(def);
        ChannelKey(self.channels.len() - 1)
    }

    /// The topic of a channel.
    pub fn topic(&self, key: ChannelKey) -> &str {
        &self.channels[key.0].topic
    }

    /// Writes one sample; opens the next split file first when the current one is full. On
    /// [`BagError::DiskFull`] the sample was not written, the current file has been finished
    /// properly, and nothing more may be written.
    pub fn write(&mut self, record: Record<'_>) -> Result<(), BagError> {
        self.split_if_due(record.log_time)?;
        // Before writing: a refused sample is one not in the file.
        self.check_space()?;
        let def = &self.channels[record.channel.0];
        let open = self.open.as_mut().ok_or(BagError::Finished)?;
        let id = match open.channels.get(&record.channel) {
            Some(id) => *id,
            None => {
                // The writer keeps one schema record per distinct schema.
                let (name, encoding, data) = &def.schema;
                let schema = open
                    .writer
                    .add_schema(name, encoding, data)
                    .map_err(|e| BagError::mcap(&open.path, e))?;
                let id = open
                    .writer
                    .add_channel(schema, &def.topic, &def.message_encoding, &def.metadata)
                    .map_err(|e| BagError::mcap(&open.path, e))?;
                open.channels.insert(record.channel, id);
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: record.seq as u32,
            log_time: record.log_time,
            publish_time: record.publish_time,
        };
        open.writer
            .write_to_known_channel(&header, record.data)
            .map_err(|e| BagError::mcap(&open.path, e))?;
        open.first_log_time.get_or_insert(record.log_time);
        open.last_log_time = open.last_log_time.max(record.log_time);
        self.messages += 1;
        Ok(())
    }

    /// Counts samples a topic lost into the current file's metadata.
    pub fn note_lost(&mut self, topic: &str, lost: Lost) {
        if let Some(open) = self.open.as_mut() {
            let entry = open.lost.entry(topic.to_owned()).or_default();
            entry.gaps += lost.gaps;
            entry.overflow += lost.overflow;
        }
    }

    /// Bytes of the current file so far.
    pub fn current_size(&self) -> u64 {
        self.open.as_ref().map_or(0, |o| o.writer_len())
    }

    /// The files written or being written.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// Samples written in all.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// Finishes the current file (summary, index, recording metadata). Idempotent.
    pub fn finish(&mut self) -> Result<(), BagError> {
        let Some(mut open) = self.open.take() else {
            return Ok(());
        };
        let mut metadata = self.options.metadata.clone();
        metadata.insert("part".into(), (self.files.len() - 1).to_string());
        if let Some(first) = open.first_log_time {
            metadata.insert("first_log_time_ns".into(), first.to_string());
            metadata.insert("last_log_time_ns".into(), open.last_log_time.to_string());
        }
        for (topic, lost) in &open.lost {
            metadata.insert(format!("gaps:{topic}"), lost.gaps.to_string());
            metadata.insert(format!("overflow:{topic}"), lost.overflow.to_string());
        }
        let path = open.path.clone();
        open.writer
            .write_metadata(&mcap::records::Metadata {
                name: format::RECORDING_METADATA.into(),
                metadata,
            })
            .map_err(|e| BagError::mcap(&path, e))?;
        open.writer.finish().map_err(|e| BagError::mcap(&path, e))?;
        let mut counting = open.writer.into_inner();
        counting.flush().map_err(|e| BagError::io(&path, e))?;
        counting
            .inner
            .get_ref()
            .sync_data()
            .map_err(|e| BagError::io(&path, e))?;
        Ok(())
    }

    fn split_if_due(&mut self, log_time: u64) -> Result<(), BagError> {
        let Some(open) = self.open.as_ref() else {
            return Err(BagError::Finished);
        };
        if open.first_log_time.is_none() {
            return Ok(());
        }
        let too_big = self
            .options
            .max_size
            .is_some_and(|max| open.writer_len() >= max);
        let too_long = self.options.max_duration.is_some_and(|max| {
            let span = log_time.saturating_sub(open.first_log_time.unwrap_or(log_time));
            span >= u64::try_from(max.as_nanos()).unwrap_or(u64::MAX)
        });
        if too_big || too_long {
            self.finish()?;
            self.open_next()?;
        }
        Ok(())
    }

    fn open_next(&mut self) -> Result<(), BagError> {
        let path = match &self.target {
            Target::File(path) if self.files.is_empty() => path.clone(),
            Target::File(_) => return Err(BagError::Finished),
            Target::Split { dir, name } => dir.join(format!("{name}_{}.mcap", self.files.len())),
        };
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|e| match e.kind() {
                std::io::ErrorKind::AlreadyExists => BagError::Exists(path.clone()),
                _ => BagError::io(&path, e),
            })?;
        let length = Arc::new(AtomicU64::new(0));
        let counting = Counting {
            inner: BufWriter::with_capacity(1 << 16, file),
            position: 0,
            length: Arc::clone(&length),
            handed: 0,
            settled: 0,
        };
        let writer = mcap::WriteOptions::new()
            .profile(format::PROFILE)
            .library(concat!("ndds ", env!("CARGO_PKG_VERSION")))
            .compression(self.options.compression.to_mcap())
            .chunk_size(Some(self.options.chunk_size))
            .create(counting)
            .map_err(|e| BagError::mcap(&path, e))?;
        self.files.push(path.clone());
        self.open = Some(Open {
            path,
            writer,
            length,
            channels: HashMap::new(),
            first_log_time: None,
            last_log_time: 0,
            lost: BTreeMap::new(),
            checked_at: 0,
        });
        self.check_space()
    }

    /// Stops with the file finished when the disk holds less than the reserve.
    fn check_space(&mut self) -> Result<(), BagError> {
        let Some(open) = self.open.as_mut() else {
            return Ok(());
        };
        let length = open.writer_len();
        if open.checked_at != 0 && length < open.checked_at + SPACE_CHECK_BYTES {
            return Ok(());
        }
        open.checked_at = length.max(1);
        let dir = open
            .path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .to_owned();
        let Ok(stat) = nix::sys::statvfs::statvfs(&dir) else {
            return Ok(());
        };
        // Both are u64 on Linux (`fsblkcnt_t`, `c_ulong`), not on every target.
        #[allow(clippy::unnecessary_cast)]
        let free = (stat.blocks_available() as u64).saturating_mul(stat.fragment_size() as u64);
        if free < self.options.reserve {
            let path = open.path.clone();
            self.finish()?;
            return Err(BagError::DiskFull {
                path,
                free,
                reserve: self.options.reserve,
            });
        }
        Ok(())
    }
}

impl Open {
    /// Bytes of the file so far (what went through [`Counting`]).
    fn writer_len(&self) -> u64 {
        self.length.load(Ordering::Relaxed)
    }
}

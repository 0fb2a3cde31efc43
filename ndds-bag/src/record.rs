//! The recorder: consumers of the chosen topics (every producer, reliable where the producer
//! offers it), a bounded queue, and a writer thread that puts each sample into the bag and
//! counts what was lost.
//!
//! # Threads
//! Samples arrive on the participant's I/O thread (direct consumers), which only stamps
//! nothing, copies nothing and queues them (a few hundred nanoseconds); when the queue holds
//! more than its byte budget the sample is dropped and counted as `overflow` (the I/O thread
//! never waits on the disk). The writer thread takes them in order, tracks each producer's
//! sequence numbers (a gap is a lost sample: a best-effort loss, or a reliable
//! `SamplesLost`), and writes. [`Recorder::discover`], called by the owner every half second
//! or so, adds consumers for topics that appeared.

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime};

use ndds_client::{
    ConsumerQos, DirectConsumer, Participant, RawSample, Reliability, TypeDescription,
};
use ndds_core::wire::{EndpointQos, Guid};
use regex::Regex;

use crate::BagError;
use crate::format::{self, ChannelMeta, nanos};
use crate::write::{BagWriter, ChannelDef, ChannelKey, Lost, Record, WriteOptions, prepare_dir};

/// Samples smaller than this are copied into a buffer of their own before they are queued.
const DETACH_BELOW: usize = 64 * 1024;

/// Which topics to record.
#[derive(Clone, Debug)]
pub enum Selection {
    /// These topics (recorded when they appear).
    Topics(Vec<String>),
    /// Every topic.
    All,
    /// Topics whose name matches.
    Regex(Regex),
}

/// How to record.
#[derive(Clone, Debug)]
pub struct RecordOptions {
    /// Which topics.
    pub selection: Selection,
    /// Topics never recorded.
    pub exclude: Option<Regex>,
    /// How the files are written.
    pub write: WriteOptions,
    /// Bytes of samples that may wait for the writer; past it samples are dropped and counted.
    pub queue_bytes: usize,
    /// Also write each sample as JSON on a companion channel `json/TOPIC` with a JSON Schema
    /// (for viewers that do not know ndds; see [`crate::format`]).
    pub json: bool,
    /// Black-box mode: keep only the last samples in memory and write them to a file of
    /// their own at each [`Recorder::trigger`].
    pub snapshot: Option<Snapshot>,
}

/// What a black box keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Snapshot {
    /// The last this much time (by reception).
    pub duration: Duration,
    /// At most this many payload bytes (the oldest go first).
    pub max_bytes: usize,
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            selection: Selection::All,
            exclude: None,
            write: WriteOptions::default(),
            queue_bytes: 256 << 20,
            json: false,
            snapshot: None,
        }
    }
}

impl RecordOptions {
    /// Whether `topic` is to be recorded.
    pub fn wants(&self, topic: &str) -> bool {
        if self.exclude.as_ref().is_some_and(|re| re.is_match(topic)) {
            return false;
        }
        match &self.selection {
            Selection::Topics(topics) => topics.iter().any(|t| t == topic),
            Selection::All => true,
            Selection::Regex(re) => re.is_match(topic),
        }
    }
}

/// What was recorded of one topic so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TopicStats {
    /// Samples written.
    pub messages: u64,
    /// Payload bytes written.
    pub bytes: u64,
    /// Samples lost.
    pub lost: Lost,
}

/// A stream: one consumer (topic, type, reliability), as the writer thread knows it.
#[derive(Debug)]
struct Stream {
    topic: String,
    desc: TypeDescription,
    reliable: bool,
    /// Sequence numbers its producers skipped (counted as samples arrive, on the I/O thread).
    gaps: AtomicU64,
    /// Samples it received that the recorder could not queue.
    overflow: AtomicU64,
}

/// What the recorder's threads share.
#[derive(Debug, Default)]
struct Shared {
    streams: Mutex<Vec<Arc<Stream>>>,
    /// Producers' QoS as discovery announced them.
    producers: Mutex<HashMap<Guid, ChannelMeta>>,
    /// Writers that a reliable consumer of their topic receives (their samples reaching a
    /// best-effort consumer too are not recorded twice).
    reliable_writers: Mutex<HashSet<Guid>>,
    stats: Mutex<BTreeMap<String, TopicStats>>,
    queued_bytes: AtomicUsize,
    stop: AtomicBool,
    failed: Mutex<Option<String>>,
}

/// What the writer thread receives.
#[derive(Clone)]
struct Item {
    stream: usize,
    sample: RawSample,
}

/// A request for a snapshot, answered with the file written.
struct Trigger {
    reason: String,
    reply: flume::Sender<Result<PathBuf, String>>,
}

/// At the end of a recording.
#[derive(Clone, Debug)]
pub struct Summary {
    /// The files written.
    pub files: Vec<std::path::PathBuf>,
    /// Per topic.
    pub topics: BTreeMap<String, TopicStats>,
    /// Why recording stopped early, if it did (the disk filled).
    pub stopped: Option<String>,
}

impl Summary {
    /// Samples written in all.
    pub fn messages(&self) -> u64 {
        self.topics.values().map(|t| t.messages).sum()
    }

    /// Samples lost in all.
    pub fn lost(&self) -> u64 {
        self.topics.values().map(|t| t.lost.total()).sum()
    }
}

/// Records topics into a bag until [`Recorder::finish`].
#[derive(Debug)]
pub struct Recorder {
    participant: Participant,
    options: RecordOptions,
    shared: Arc<Shared>,
    tx: Option<flume::Sender<Item>>,
    triggers: flume::Sender<Trigger>,
    writer: Option<JoinHandle<Result<Vec<std::path::PathBuf>, BagError>>>,
    /// Consumers by (topic, fingerprint, reliable).
    consumers: HashMap<(String, u64, bool), DirectConsumer>,
}

impl Recorder {
    /// Starts recording into `path` (see [`BagWriter::create`]); with
    /// [`RecordOptions::snapshot`], `path` is the directory (new or empty) that snapshots go
    /// into. Call [`Self::discover`] at once and then periodically.
    pub fn start(
        participant: &Participant,
        path: &Path,
        options: RecordOptions,
    ) -> Result<Self, BagError> {
        let shared = Arc::new(Shared::default());
        let (tx, rx) = flume::bounded(1 << 16);
        let (triggers, trigger_rx) = flume::bounded(16);
        let thread_shared = Arc::clone(&shared);
        let json = options.json;
        let work: Box<dyn FnOnce() -> Result<Vec<PathBuf>, BagError> + Send> =
            match options.snapshot {
                None => {
                    let writer = BagWriter::create(path, options.write.clone())?;
                    Box::new(move || write_loop(writer, &rx, &trigger_rx, &thread_shared, json))
                }
                Some(snapshot) => {
                    prepare_dir(path)?;
                    let ring = Ring {
                        dir: path.to_owned(),
                        snapshot,
                        write: options.write.clone(),
                        json,
                        items: VecDeque::new(),
                        bytes: 0,
                        files: Vec::new(),
                    };
                    Box::new(move || ring.run(&rx, &trigger_rx, &thread_shared))
                }
            };
        let writer = std::thread::Builder::new()
            .name("ndds-record".into())
            .spawn(move || {
                yield_to_receivers();
                work()
            })
            .map_err(|e| BagError::io(path, e))?;
        Ok(Recorder {
            participant: participant.clone(),
            options,
            shared,
            tx: Some(tx),
            triggers,
            writer: Some(writer),
            consumers: HashMap::new(),
        })
    }

    /// Black box: writes what the recorder keeps to a new file now and returns it (waits up
    /// to `timeout` for it to be written). Without [`RecordOptions::snapshot`], refused.
    pub fn trigger(&self, reason: &str, timeout: Duration) -> Result<PathBuf, BagError> {
        if self.options.snapshot.is_none() {
            return Err(BagError::Usage(
                "this recorder writes everything: snapshots are for --snapshot recorders".into(),
            ));
        }
        let (reply, answer) = flume::bounded(1);
        self.triggers
            .send(Trigger {
                reason: reason.to_owned(),
                reply,
            })
            .map_err(|_| BagError::Finished)?;
        match answer.recv_timeout(timeout) {
            Ok(Ok(path)) => Ok(path),
            Ok(Err(why)) => Err(BagError::Participant(format!(
                "snapshot not written: {why}"
            ))),
            Err(_) => Err(BagError::Participant(format!(
                "snapshot not written within {timeout:?}"
            ))),
        }
    }

    /// Looks at the graph and declares consumers for topics that appeared (and a reliable one
    /// where a reliable producer appeared). Returns the topics newly taken.
    pub fn discover(&mut self) -> Result<Vec<String>, BagError> {
        let graph = self
            .participant
            .graph()
            .map_err(|e| BagError::Participant(format!("reading the graph: {e}")))?;
        let mut producers = HashMap::new();
        let mut wanted: BTreeMap<(String, u64, bool), TypeDescription> = BTreeMap::new();
        for endpoint in &graph.endpoints {
            let info = &endpoint.info;
            let EndpointQos::Producer(qos) = &info.qos else {
                continue;
            };
            producers.insert(
                info.guid,
                ChannelMeta {
                    writer: Some(info.guid),
                    strength: qos.strength,
                    persistence: Duration::from_micros(qos.persistence_us),
                    reliability: qos.reliability,
                },
            );
            if !self.options.wants(&info.topic) {
                continue;
            }
            let reliable = matches!(qos.reliability, Reliability::Reliable { .. });
            if reliable {
                self.shared
                    .reliable_writers
                    .lock()
                    .expect("not poisoned")
                    .insert(info.guid);
            }
            wanted
                .entry((info.topic.clone(), info.fingerprint, reliable))
                .or_insert_with(|| info.type_desc.clone());
        }
        self.shared
            .producers
            .lock()
            .expect("not poisoned")
            .extend(producers);
        let mut added = Vec::new();
        for ((topic, fingerprint, reliable), desc) in wanted {
            // A best-effort consumer is there for every topic taken: it receives best-effort
            // producers (and reliable ones, whose samples its reliable sibling records).
            for reliable in [false, reliable].into_iter().collect::<HashSet<_>>() {
                let key = (topic.clone(), fingerprint, reliable);
                if self.consumers.contains_key(&key) {
                    continue;
                }
                let consumer = self.consume(&topic, &desc, reliable)?;
                if !reliable {
                    added.push(topic.clone());
                }
                self.consumers.insert(key, consumer);
            }
        }
        Ok(added)
    }

    fn consume(
        &self,
        topic: &str,
        desc: &TypeDescription,
        reliable: bool,
    ) -> Result<DirectConsumer, BagError> {
        let stream = Arc::new(Stream {
            topic: topic.to_owned(),
            desc: desc.clone(),
            reliable,
            gaps: AtomicU64::new(0),
            overflow: AtomicU64::new(0),
        });
        let index = {
            let mut streams = self.shared.streams.lock().expect("not poisoned");
            streams.push(Arc::clone(&stream));
            streams.len() - 1
        };
        let qos = ConsumerQos {
            depth: 4096,
            every_producer: true,
            reliability: if reliable {
                Reliability::Reliable { depth: 1024 }
            } else {
                Reliability::BestEffort
            },
            ..ConsumerQos::default()
        };
        let consumer = self
            .participant
            .raw_consumer(topic, desc.clone(), qos)
            .map_err(|e| BagError::Participant(format!("consumer of {topic}: {e}")))?;
        let Some(tx) = self.tx.clone() else {
            return Err(BagError::Finished);
        };
        let shared = Arc::clone(&self.shared);
        let budget = self.options.queue_bytes;
        // Each producer's last sequence number, as samples arrive: a gap is counted here, where
        // every sample is seen in order (one the queue cannot take is overflow, not a gap).
        let mut last_seq: HashMap<Guid, u64> = HashMap::new();
        consumer
            .on_raw_sample_direct(move |sample| {
                if !stream.reliable
                    && shared
                        .reliable_writers
                        .lock()
                        .expect("not poisoned")
                        .contains(&sample.info.writer)
                {
                    return;
                }
                let seq = sample.info.seq;
                match last_seq.get_mut(&sample.info.writer) {
                    Some(last) if seq > *last => {
                        stream.gaps.fetch_add(seq - *last - 1, Ordering::Relaxed);
                        *last = seq;
                    }
                    // A copy of a sample already taken, or one overtaken (best effort) and
                    // counted as a gap when its successor came: the file keeps each
                    // producer's samples in order, each once, and gaps + samples = the span.
                    Some(_) => return,
                    // Before a producer's first sample the recorder was not there.
                    None => {
                        last_seq.insert(sample.info.writer, seq);
                    }
                }
                let size = sample.payload.len();
                let queued = shared.queued_bytes.fetch_add(size, Ordering::Relaxed);
                // A small sample is a view into a receive region of several datagrams: queued
                // as it is, it would keep the whole region alive, and the queue's byte budget
                // would bound the payloads but not the memory they hold. A copy of its own
                // makes the budget the memory (large samples have their own buffer already).
                let sample = if size < DETACH_BELOW && queued + size <= budget {
                    sample.detached()
                } else {
                    sample
                };
                if queued + size > budget
                    || tx
                        .try_send(Item {
                            stream: index,
                            sample,
                        })
                        .is_err()
                {
                    shared.queued_bytes.fetch_sub(size, Ordering::Relaxed);
                    stream.overflow.fetch_add(1, Ordering::Relaxed);
                }
            })
            .map_err(|e| BagError::Participant(format!("consumer of {topic}: {e}")))
    }

    /// What was recorded so far, per topic.
    pub fn stats(&self) -> BTreeMap<String, TopicStats> {
        self.shared.stats.lock().expect("not poisoned").clone()
    }

    /// Why recording stopped by itself (the disk filled, a write failed), if it did.
    pub fn failed(&self) -> Option<String> {
        self.shared.failed.lock().expect("not poisoned").clone()
    }

    /// Stops: withdraws the consumers, writes what waits, and finishes the file.
    pub fn finish(mut self) -> Result<Summary, BagError> {
        self.consumers.clear();
        self.tx = None;
        self.shared.stop.store(true, Ordering::Release);
        let files = match self.writer.take().map(JoinHandle::join) {
            Some(Ok(result)) => result?,
            Some(Err(_)) => return Err(BagError::Participant("the writer thread panicked".into())),
            None => Vec::new(),
        };
        Ok(Summary {
            files,
            topics: self.stats(),
            stopped: self.failed(),
        })
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        self.consumers.clear();
        self.tx = None;
        self.shared.stop.store(true, Ordering::Release);
        if let Some(writer) = self.writer.take() {
            let _ = writer.join();
        }
    }
}

/// The writer thread's state.
struct WriteState<'a> {
    writer: BagWriter,
    shared: &'a Shared,
    streams: KnownStreams,
    channels: HashMap<(usize, Guid), ChannelKey>,
    last_seq: HashMap<(usize, Guid), u64>,
    losses_seen: HashMap<usize, Lost>,
    last_log_time: u64,
    /// JSON companions wanted.
    json: bool,
    /// Their channels by (topic, fingerprint); `None` where the type cannot be written as
    /// JSON (opaque).
    json_channels: HashMap<(String, u64), Option<ChannelKey>>,
    /// Whether what is written counts in the recorder's statistics (not for snapshots, whose
    /// samples were counted when the black box took them).
    count_stats: bool,
}

fn write_loop(
    writer: BagWriter,
    rx: &flume::Receiver<Item>,
    triggers: &flume::Receiver<Trigger>,
    shared: &Shared,
    json: bool,
) -> Result<Vec<PathBuf>, BagError> {
    let mut state = WriteState::new(writer, shared, json, true);
    // A failure (the disk's reserve reached, a write error) ends the recording with the file
    // finished; it is reported in the summary (`stopped`), not as the recorder's error.
    if let Err(err) = state.run(rx, triggers) {
        tracing::warn!(%err, "recording stopped");
        *shared.failed.lock().expect("not poisoned") = Some(err.to_string());
    }
    if let Err(err) = state.writer.finish() {
        let mut failed = shared.failed.lock().expect("not poisoned");
        let why = match failed.take() {
            Some(first) => format!("{first}; then finishing the file failed: {err}"),
            None => format!("finishing the file failed: {err}"),
        };
        *failed = Some(why);
    }
    Ok(state.writer.files().to_vec())
}

/// Lowers the calling thread's scheduling priority (nice +5, which needs no privilege): on a
/// busy machine the participant's receive thread, which must take every datagram before its
/// socket buffer fills, then runs before the writer, which has the queue to catch up from.
fn yield_to_receivers() {
    // SAFETY: `gettid` and `setpriority` only read their arguments; `PRIO_PROCESS` with a
    // thread id names this thread alone on Linux.
    let result = unsafe { libc::setpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t, 5) };
    if result != 0 {
        tracing::debug!("the recorder's writer thread keeps its priority");
    }
}

/// A black box: the last samples, by time and bytes.
struct Ring {
    dir: PathBuf,
    snapshot: Snapshot,
    write: WriteOptions,
    json: bool,
    items: VecDeque<Item>,
    bytes: usize,
    files: Vec<PathBuf>,
}

impl Ring {
    fn run(
        mut self,
        rx: &flume::Receiver<Item>,
        triggers: &flume::Receiver<Trigger>,
        shared: &Shared,
    ) -> Result<Vec<PathBuf>, BagError> {
        let mut taken = WriteState::counter(shared);
        loop {
            match rx.recv_timeout(Duration::from_millis(20)) {
                Ok(item) => {
                    let size = item.sample.payload.len();
                    shared.queued_bytes.fetch_sub(size, Ordering::Relaxed);
                    taken.count(&item);
                    self.keep(item);
                }
                Err(flume::RecvTimeoutError::Timeout) => {}
                Err(flume::RecvTimeoutError::Disconnected) => return Ok(self.files),
            }
            taken.count_overflow();
            while let Ok(trigger) = triggers.try_recv() {
                let written = self.write(&trigger.reason, shared);
                if let Err(err) = &written {
                    tracing::warn!(%err, "snapshot not written");
                }
                let _ = trigger.reply.send(written.map_err(|e| e.to_string()));
            }
            if shared.stop.load(Ordering::Acquire) && rx.is_empty() {
                return Ok(self.files);
            }
        }
    }

    /// Keeps `item`, dropping what is older than the duration or past the byte bound.
    fn keep(&mut self, item: Item) {
        let newest = item.sample.info.reception_timestamp;
        self.bytes += item.sample.payload.len();
        self.items.push_back(item);
        while let Some(oldest) = self.items.front() {
            let age = newest
                .duration_since(oldest.sample.info.reception_timestamp)
                .unwrap_or_default();
            if age <= self.snapshot.duration && self.bytes <= self.snapshot.max_bytes {
                break;
            }
            self.bytes -= oldest.sample.payload.len();
            self.items.pop_front();
        }
    }

    /// Writes what is kept into a new file of the directory.
    fn write(&mut self, reason: &str, shared: &Shared) -> Result<PathBuf, BagError> {
        let stamp = humantime_stamp(SystemTime::now());
        let path = self
            .dir
            .join(format!("snapshot_{}_{stamp}.mcap", self.files.len()));
        let mut options = self.write.clone();
        options.max_size = None;
        options.max_duration = None;
        options
            .metadata
            .insert("snapshot_reason".into(), reason.to_owned());
        options.metadata.insert(
            "snapshot_window_ms".into(),
            self.snapshot.duration.as_millis().to_string(),
        );
        let writer = BagWriter::create(&path, options)?;
        let mut state = WriteState::new(writer, shared, self.json, false);
        let result = self.items.iter().try_for_each(|item| state.write(item));
        state.writer.finish()?;
        result?;
        tracing::info!(path = %path.display(), samples = self.items.len(), reason, "snapshot written");
        self.files.push(path.clone());
        Ok(path)
    }
}

/// `2026-12-06T08-55-01Z`: a UTC time for file names (RFC 3339 without colons).
fn humantime_stamp(time: SystemTime) -> String {
    humantime::format_rfc3339_seconds(time)
        .to_string()
        .replace(':', "-")
}

/// The writer thread's copy of the streams: streams are only ever added, so the shared list is
/// locked only when a sample of one not seen yet comes, not for every sample.
#[derive(Default)]
struct KnownStreams(Vec<Arc<Stream>>);

impl KnownStreams {
    fn get(&mut self, shared: &Shared, index: usize) -> Arc<Stream> {
        if index >= self.0.len() {
            self.0 = shared.streams.lock().expect("not poisoned").clone();
        }
        Arc::clone(&self.0[index])
    }
}

/// `topic`'s statistics, its name copied only the first time.
fn topic_stats<'a>(stats: &'a mut BTreeMap<String, TopicStats>, topic: &str) -> &'a mut TopicStats {
    if !stats.contains_key(topic) {
        stats.insert(topic.to_owned(), TopicStats::default());
    }
    stats.get_mut(topic).expect("inserted above")
}

/// Counts what a black box takes (its samples go to files only when triggered).
struct Counter<'a> {
    shared: &'a Shared,
    streams: KnownStreams,
    seen: HashMap<usize, Lost>,
}

impl Counter<'_> {
    fn count(&mut self, item: &Item) {
        let stream = self.streams.get(self.shared, item.stream);
        let mut stats = self.shared.stats.lock().expect("not poisoned");
        let entry = topic_stats(&mut stats, &stream.topic);
        entry.messages += 1;
        entry.bytes += item.sample.payload.len() as u64;
    }

    fn count_overflow(&mut self) {
        for (topic, lost) in new_losses(self.shared, &mut self.seen) {
            let mut stats = self.shared.stats.lock().expect("not poisoned");
            let entry = &mut stats.entry(topic).or_default().lost;
            entry.gaps += lost.gaps;
            entry.overflow += lost.overflow;
        }
    }
}

/// The sequence numbers `item`'s producer skipped since its last sample in `last_seq` (0 for
/// its first): in a snapshot, the samples of the window that are not in it.
fn gap(last_seq: &mut HashMap<(usize, Guid), u64>, item: &Item) -> u64 {
    let seq = item.sample.info.seq;
    match last_seq.get_mut(&(item.stream, item.sample.info.writer)) {
        Some(last) if seq > *last => {
            let gaps = seq - *last - 1;
            *last = seq;
            gaps
        }
        Some(_) => 0,
        None => {
            last_seq.insert((item.stream, item.sample.info.writer), seq);
            0
        }
    }
}

/// Losses the consumers counted since the last call, per topic.
fn new_losses(shared: &Shared, seen: &mut HashMap<usize, Lost>) -> Vec<(String, Lost)> {
    let streams: Vec<Arc<Stream>> = shared.streams.lock().expect("not poisoned").clone();
    let mut out = Vec::new();
    for (index, stream) in streams.iter().enumerate() {
        let now = Lost {
            gaps: stream.gaps.load(Ordering::Relaxed),
            overflow: stream.overflow.load(Ordering::Relaxed),
        };
        let seen = seen.entry(index).or_default();
        if now != *seen {
            out.push((
                stream.topic.clone(),
                Lost {
                    gaps: now.gaps - seen.gaps,
                    overflow: now.overflow - seen.overflow,
                },
            ));
            *seen = now;
        }
    }
    out
}

impl<'a> WriteState<'a> {
    fn new(writer: BagWriter, shared: &'a Shared, json: bool, count_stats: bool) -> Self {
        WriteState {
            writer,
            shared,
            streams: KnownStreams::default(),
            channels: HashMap::new(),
            last_seq: HashMap::new(),
            losses_seen: HashMap::new(),
            last_log_time: 0,
            json,
            json_channels: HashMap::new(),
            count_stats,
        }
    }

    fn counter(shared: &'a Shared) -> Counter<'a> {
        Counter {
            shared,
            streams: KnownStreams::default(),
            seen: HashMap::new(),
        }
    }

    fn run(
        &mut self,
        rx: &flume::Receiver<Item>,
        triggers: &flume::Receiver<Trigger>,
    ) -> Result<(), BagError> {
        loop {
            match rx.recv_timeout(Duration::from_millis(50)) {
                Ok(item) => self.take(&item)?,
                Err(flume::RecvTimeoutError::Timeout) => {}
                Err(flume::RecvTimeoutError::Disconnected) => {
                    self.count_overflow();
                    return Ok(());
                }
            }
            self.count_overflow();
            while let Ok(trigger) = triggers.try_recv() {
                let _ = trigger.reply.send(Err(format!(
                    "this recorder writes everything (asked for `{}`)",
                    trigger.reason
                )));
            }
            if self.shared.stop.load(Ordering::Acquire) && rx.is_empty() {
                // The consumers are gone: what is queued is all there is.
                while let Ok(item) = rx.try_recv() {
                    self.take(&item)?;
                }
                self.count_overflow();
                return Ok(());
            }
        }
    }

    /// Writes an item taken off the queue.
    fn take(&mut self, item: &Item) -> Result<(), BagError> {
        self.shared
            .queued_bytes
            .fetch_sub(item.sample.payload.len(), Ordering::Relaxed);
        self.write(item)
    }

    fn write(&mut self, item: &Item) -> Result<(), BagError> {
        let Item { stream, sample } = item;
        let stream = *stream;
        let writer_id = sample.info.writer;
        let def = self.streams.get(self.shared, stream);
        let key = match self.channels.get(&(stream, writer_id)) {
            Some(key) => *key,
            None => {
                let announced = self
                    .shared
                    .producers
                    .lock()
                    .expect("not poisoned")
                    .get(&writer_id)
                    .cloned();
                let meta = announced.unwrap_or(ChannelMeta {
                    writer: Some(writer_id),
                    strength: sample.info.strength,
                    reliability: if def.reliable {
                        Reliability::Reliable { depth: 64 }
                    } else {
                        Reliability::BestEffort
                    },
                    ..ChannelMeta::default()
                });
                let key = self.writer.add_channel(&def.topic, &def.desc, meta);
                self.channels.insert((stream, writer_id), key);
                key
            }
        };
        // A recording's losses come from the consumers (`count_overflow`); a snapshot's file
        // counts the samples of its window that are not in it.
        let seq = sample.info.seq;
        let lost = Lost {
            gaps: if self.count_stats {
                0
            } else {
                gap(&mut self.last_seq, item)
            },
            overflow: 0,
        };
        // Log times never go back within a file, so it reads in time order.
        let log_time = nanos(sample.info.reception_timestamp).max(self.last_log_time);
        self.last_log_time = log_time;
        let publish_time = nanos(sample.info.source_timestamp);
        let mut result = self.writer.write(Record {
            channel: key,
            seq,
            log_time,
            publish_time,
            data: &sample.payload,
        });
        if self.json
            && result.is_ok()
            && let Some((key, json)) = self.json_of(&def, &sample.payload)
        {
            result = self.writer.write(Record {
                channel: key,
                seq,
                log_time,
                publish_time,
                data: &json,
            });
        }
        if lost.gaps > 0 {
            self.writer.note_lost(&def.topic, lost);
        }
        if !self.count_stats {
            return result;
        }
        let mut stats = self.shared.stats.lock().expect("not poisoned");
        let topic = topic_stats(&mut stats, &def.topic);
        if result.is_ok() {
            topic.messages += 1;
            topic.bytes += sample.payload.len() as u64;
        }
        result
    }

    /// The JSON companion channel of `stream`'s topic and the sample as JSON; `None` for an
    /// opaque type or a sample that does not decode (logged once per topic).
    fn json_of(&mut self, stream: &Stream, payload: &[u8]) -> Option<(ChannelKey, Vec<u8>)> {
        if payload.len() > format::MAX_JSON_PAYLOAD {
            return None;
        }
        let layout = stream.desc.layout.as_ref()?;
        let id = (stream.topic.clone(), stream.desc.fingerprint());
        let key = match self.json_channels.get(&id) {
            Some(key) => *key,
            None => {
                let key = match ndds_core::dynamic::json_schema(layout, &stream.desc.name) {
                    Ok(schema) => {
                        let mut metadata = BTreeMap::new();
                        metadata.insert(format::JSON_OF.to_owned(), stream.topic.clone());
                        Some(self.writer.add_raw_channel(ChannelDef {
                            topic: format!("{}{}", format::JSON_TOPIC_PREFIX, stream.topic),
                            schema: (
                                stream.desc.name.clone(),
                                "jsonschema".to_owned(),
                                schema.to_string().into_bytes(),
                            ),
                            message_encoding: "json".to_owned(),
                            metadata,
                        }))
                    }
                    Err(err) => {
                        tracing::warn!(topic = stream.topic, %err, "no JSON channel for this topic");
                        None
                    }
                };
                self.json_channels.insert(id, key);
                key
            }
        }?;
        match ndds_core::dynamic::decode_json(layout, payload) {
            Ok(value) => Some((key, value.to_string().into_bytes())),
            Err(err) => {
                tracing::debug!(topic = stream.topic, %err, "a sample did not decode as JSON");
                None
            }
        }
    }

    /// Moves the consumers' loss counts into the stats and the file.
    fn count_overflow(&mut self) {
        for (topic, lost) in new_losses(self.shared, &mut self.losses_seen) {
            self.writer.note_lost(&topic, lost);
            let mut stats = self.shared.stats.lock().expect("not poisoned");
            let entry = &mut stats.entry(topic).or_default().lost;
            entry.gaps += lost.gaps;
            entry.overflow += lost.overflow;
        }
    }
}

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

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use ndds_client::{
    ConsumerQos, DirectConsumer, Participant, RawSample, Reliability, TypeDescription,
};
use ndds_core::wire::{EndpointQos, Guid};
use regex::Regex;

use crate::BagError;
use crate::format::{self, ChannelMeta, nanos};
use crate::write::{BagWriter, ChannelDef, ChannelKey, Lost, Record, WriteOptions};

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
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            selection: Selection::All,
            exclude: None,
            write: WriteOptions::default(),
            queue_bytes: 256 << 20,
            json: false,
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
struct Item {
    stream: usize,
    sample: RawSample,
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
    writer: Option<JoinHandle<Result<Vec<std::path::PathBuf>, BagError>>>,
    /// Consumers by (topic, fingerprint, reliable).
    consumers: HashMap<(String, u64, bool), DirectConsumer>,
}

impl Recorder {
    /// Starts recording into `path` (see [`BagWriter::create`]); call [`Self::discover`]
    /// at once and then periodically.
    pub fn start(
        participant: &Participant,
        path: &Path,
        options: RecordOptions,
    ) -> Result<Self, BagError> {
        let writer = BagWriter::create(path, options.write.clone())?;
        let shared = Arc::new(Shared::default());
        let (tx, rx) = flume::bounded(1 << 16);
        let thread_shared = Arc::clone(&shared);
        let json = options.json;
        let writer = std::thread::Builder::new()
            .name("ndds-record".into())
            .spawn(move || write_loop(writer, rx, &thread_shared, json))
            .map_err(|e| BagError::io(path, e))?;
        Ok(Recorder {
            participant: participant.clone(),
            options,
            shared,
            tx: Some(tx),
            writer: Some(writer),
            consumers: HashMap::new(),
        })
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
                let size = sample.payload.len();
                let queued = shared.queued_bytes.fetch_add(size, Ordering::Relaxed);
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
    channels: HashMap<(usize, Guid), ChannelKey>,
    last_seq: HashMap<(usize, Guid), u64>,
    overflow_seen: HashMap<usize, u64>,
    last_log_time: u64,
    /// JSON companions wanted.
    json: bool,
    /// Their channels by (topic, fingerprint); `None` where the type cannot be written as
    /// JSON (opaque).
    json_channels: HashMap<(String, u64), Option<ChannelKey>>,
}

fn write_loop(
    writer: BagWriter,
    rx: flume::Receiver<Item>,
    shared: &Shared,
    json: bool,
) -> Result<Vec<std::path::PathBuf>, BagError> {
    let mut state = WriteState {
        writer,
        shared,
        channels: HashMap::new(),
        last_seq: HashMap::new(),
        overflow_seen: HashMap::new(),
        last_log_time: 0,
        json,
        json_channels: HashMap::new(),
    };
    let result = state.run(&rx);
    if let Err(err) = &result {
        *shared.failed.lock().expect("not poisoned") = Some(err.to_string());
        // Nothing more is written: what still arrives is refused at once and counted.
        drop(rx);
    }
    state.writer.finish()?;
    result.map(|()| state.writer.files().to_vec())
}

impl WriteState<'_> {
    fn run(&mut self, rx: &flume::Receiver<Item>) -> Result<(), BagError> {
        loop {
            match rx.recv_timeout(Duration::from_millis(50)) {
                Ok(item) => self.write(item)?,
                Err(flume::RecvTimeoutError::Timeout) => {}
                Err(flume::RecvTimeoutError::Disconnected) => {
                    self.count_overflow();
                    return Ok(());
                }
            }
            self.count_overflow();
            if self.shared.stop.load(Ordering::Acquire) && rx.is_empty() {
                // The consumers are gone: what is queued is all there is.
                while let Ok(item) = rx.try_recv() {
                    self.write(item)?;
                }
                self.count_overflow();
                return Ok(());
            }
        }
    }

    fn stream(&self, index: usize) -> Arc<Stream> {
        Arc::clone(&self.shared.streams.lock().expect("not poisoned")[index])
    }

    fn write(&mut self, item: Item) -> Result<(), BagError> {
        let Item { stream, sample } = item;
        self.shared
            .queued_bytes
            .fetch_sub(sample.payload.len(), Ordering::Relaxed);
        let writer_id = sample.info.writer;
        let def = self.stream(stream);
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
        // Gaps in a producer's sequence numbers are samples lost (before the first one
        // heard, nothing is counted: the recorder was not there yet).
        let seq = sample.info.seq;
        let mut lost = Lost::default();
        match self.last_seq.get_mut(&(stream, writer_id)) {
            Some(last) if seq > *last => {
                lost.gaps = seq - *last - 1;
                *last = seq;
            }
            Some(_) => {}
            None => {
                self.last_seq.insert((stream, writer_id), seq);
            }
        }
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
        let mut stats = self.shared.stats.lock().expect("not poisoned");
        let topic = stats.entry(def.topic.clone()).or_default();
        topic.lost.gaps += lost.gaps;
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

    /// Moves the consumers' overflow counts into the stats and the file.
    fn count_overflow(&mut self) {
        let streams: Vec<Arc<Stream>> = self.shared.streams.lock().expect("not poisoned").clone();
        for (index, stream) in streams.iter().enumerate() {
            let now = stream.overflow.load(Ordering::Relaxed);
            let seen = self.overflow_seen.entry(index).or_default();
            if now > *seen {
                let lost = Lost {
                    gaps: 0,
                    overflow: now - *seen,
                };
                *seen = now;
                self.writer.note_lost(&stream.topic, lost);
                let mut stats = self.shared.stats.lock().expect("not poisoned");
                stats.entry(stream.topic.clone()).or_default().lost.overflow += lost.overflow;
            }
        }
    }
}

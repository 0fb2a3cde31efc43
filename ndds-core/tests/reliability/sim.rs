//! A simulated link in virtual time between one [`ReliableWriter`] and several
//! [`ReliableReader`]s: per-reader latency, jitter (reordering), random loss, duplication and
//! outages (100 % loss for a while, both directions), a producer application that writes at a
//! fixed interval and may or may not wait for the window, and consumers that take samples at
//! once, now and then, or never. Everything is seeded: a run replays exactly.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use ndds_core::reliability::{
    Bitmap, Delivery, ReaderConfig, ReliableReader, ReliableWriter, WriterConfig, WriterOutput,
};

/// The value every sample carries: derived from its seq, so corruption or mix-ups show.
pub fn value(seq: u64) -> u64 {
    seq.wrapping_mul(7).wrapping_add(3)
}

/// Properties of the link between the writer and one reader (both directions).
#[derive(Clone, Debug, Default)]
pub struct Link {
    /// One-way latency.
    pub latency: Duration,
    /// Extra delay drawn uniformly from `0..jitter` per datagram (reorders them).
    pub jitter: Duration,
    /// Probability that a datagram is dropped.
    pub loss: f64,
    /// Probability that a datagram arrives twice.
    pub duplicate: f64,
    /// Periods (from the start) during which everything sent is dropped.
    pub outages: Vec<(Duration, Duration)>,
}

impl Link {
    /// A clean link with 1 ms latency.
    pub fn clean() -> Self {
        Link {
            latency: Duration::from_millis(1),
            ..Link::default()
        }
    }
}

/// How a reader's application takes samples.
#[derive(Clone, Copy, Debug)]
pub enum Consumer {
    /// Takes everything at once.
    Eager,
    /// Takes up to `batch` samples every `every`.
    Slow {
        /// Period.
        every: Duration,
        /// Samples per period.
        batch: usize,
    },
}

/// What travels.
#[derive(Clone, Debug)]
enum Body {
    Sample { seq: u64, value: u64 },
    Gap { from: u64, to: u64 },
    Heartbeat { first: u64, last: u64 },
    AckNack { acked: u64, missing: Bitmap },
}

#[derive(Clone, Debug)]
struct Packet {
    reader: usize,
    body: Body,
}

/// Counters of one link.
#[derive(Clone, Copy, Debug, Default)]
pub struct LinkStats {
    /// Sample datagrams (originals and resends) sent to the reader.
    pub samples_sent: u64,
    /// Of those, dropped.
    pub samples_dropped: u64,
    /// Original samples dropped.
    pub originals_dropped: u64,
    /// Other datagrams dropped (gaps, heartbeats, AckNacks).
    pub control_dropped: u64,
    /// Datagrams duplicated.
    pub duplicated: u64,
}

/// One reader node.
pub struct Node {
    /// Its state machine.
    pub reader: ReliableReader<u64>,
    /// Its link.
    pub link: Link,
    /// Its application.
    pub consumer: Consumer,
    next_take: Instant,
    /// Matched by the writer (samples flow to it).
    pub attached: bool,
    /// Its process runs (a dead one neither receives, acknowledges nor takes anything).
    pub alive: bool,
    /// Everything handed out, in order.
    pub got: Vec<Delivery<u64>>,
    /// Every AckNack it sent: (acked, seqs asked for).
    pub acknacks: Vec<(u64, Vec<u64>)>,
    /// Seqs the writer declared unavailable to it (gaps and heartbeat `first`s), lost or not.
    pub told_gone: Vec<(u64, u64)>,
    /// Link counters.
    pub stats: LinkStats,
}

impl Node {
    /// Seq after the last one handed out or reported lost.
    pub fn reached(&self) -> Option<u64> {
        self.got.last().map(|d| match d {
            Delivery::Sample { seq, .. } => seq + 1,
            Delivery::Lost { to, .. } => *to,
        })
    }
}

/// The producing application.
#[derive(Clone, Copy, Debug)]
pub struct Producer {
    /// Samples to write (seqs 1..=total).
    pub total: u64,
    /// Time between writes (zero: as fast as the window allows).
    pub interval: Duration,
    /// Wait while the window is closed (false: write anyway, as after a timeout).
    pub respect_window: bool,
    /// Size given for each sample.
    pub bytes: usize,
}

/// The simulation.
pub struct Sim {
    /// Start of virtual time.
    pub t0: Instant,
    /// Virtual now.
    pub now: Instant,
    rng: fastrand::Rng,
    /// The writer.
    pub writer: ReliableWriter<usize, u64>,
    /// The readers, by key.
    pub nodes: Vec<Node>,
    /// The producer.
    pub producer: Producer,
    /// Next seq the producer writes.
    pub next_seq: u64,
    next_write: Instant,
    /// Virtual time the producer spent waiting for the window.
    pub blocked_for: Duration,
    blocked_since: Option<Instant>,
    /// Largest history seen, in samples.
    pub max_history: usize,
    /// Largest number of samples any live reader held.
    pub max_buffered: usize,
    queue: BTreeMap<(Instant, u64), Packet>,
    order: u64,
}

impl Sim {
    /// A writer with `config`, no readers yet.
    pub fn new(seed: u64, config: WriterConfig, producer: Producer) -> Self {
        let t0 = Instant::now();
        Sim {
            t0,
            now: t0,
            rng: fastrand::Rng::with_seed(seed),
            writer: ReliableWriter::new(config),
            nodes: Vec::new(),
            producer,
            next_seq: 1,
            next_write: t0,
            blocked_for: Duration::ZERO,
            blocked_since: None,
            max_history: 0,
            max_buffered: 0,
            queue: BTreeMap::new(),
            order: 0,
        }
    }

    /// Adds a reader node (not yet matched); returns its key.
    pub fn add_node(&mut self, config: ReaderConfig, link: Link, consumer: Consumer) -> usize {
        self.nodes.push(Node {
            reader: ReliableReader::new(config),
            link,
            consumer,
            next_take: self.now,
            attached: false,
            alive: true,
            got: Vec::new(),
            acknacks: Vec::new(),
            told_gone: Vec::new(),
            stats: LinkStats::default(),
        });
        self.nodes.len() - 1
    }

    /// The writer matches reader `key` now.
    pub fn attach(&mut self, key: usize) {
        self.nodes[key].attached = true;
        self.writer.add_reader(self.now, key);
        self.flush();
    }

    /// The writer forgets reader `key` (discovery saw it go).
    pub fn detach(&mut self, key: usize) {
        self.nodes[key].attached = false;
        self.writer.remove_reader(key);
        self.flush();
    }

    /// The producer's first write happens `offset` after the start.
    pub fn start_writing_at(&mut self, offset: Duration) {
        self.next_write = self.t0 + offset;
    }

    /// Milliseconds since the start.
    pub fn at_ms(&self, ms: u64) -> Instant {
        self.t0 + Duration::from_millis(ms)
    }

    /// True when everything was written and every live, attached reader reached the end.
    pub fn done(&self) -> bool {
        self.next_seq > self.producer.total
            && self
                .nodes
                .iter()
                .filter(|n| n.alive && n.attached)
                .all(|n| n.reached() == Some(self.producer.total + 1))
    }

    /// Runs until `until` holds or virtual time reaches `deadline`.
    pub fn run_until(&mut self, deadline: Instant, mut until: impl FnMut(&Sim) -> bool) {
        let mut same_instant = 0;
        loop {
            self.step();
            if until(self) {
                return;
            }
            let Some(next) = self.next_event() else {
                self.now = deadline;
                return;
            };
            if next > deadline {
                self.now = deadline;
                return;
            }
            same_instant = if next <= self.now {
                same_instant + 1
            } else {
                0
            };
            assert!(
                same_instant < 10_000,
                "time does not advance at {:?}",
                self.now - self.t0
            );
            self.now = next;
        }
    }

    /// Runs for `span` of virtual time.
    pub fn run_for(&mut self, span: Duration) {
        let deadline = self.now + span;
        self.run_until(deadline, |_| false);
    }

    fn next_event(&self) -> Option<Instant> {
        let mut next = self.queue.keys().next().map(|k| k.0);
        let mut consider = |t: Option<Instant>| {
            if let Some(t) = t {
                next = Some(next.map_or(t, |n| n.min(t)));
            }
        };
        consider(self.writer.poll_timeout());
        let waiting = self.producer.respect_window && !self.writer.window_open();
        if self.next_seq <= self.producer.total && !waiting {
            consider(Some(self.next_write));
        }
        for node in self.nodes.iter().filter(|n| n.alive) {
            consider(node.reader.poll_timeout());
            if let Consumer::Slow { .. } = node.consumer {
                consider(Some(node.next_take));
            }
        }
        next
    }

    fn step(&mut self) {
        let now = self.now;
        while let Some(entry) = self.queue.first_entry() {
            if entry.key().0 > now {
                break;
            }
            let packet = entry.remove();
            self.receive(packet);
        }
        if self.writer.poll_timeout().is_some_and(|t| t <= now) {
            self.writer.handle_timeout(now);
        }
        for node in self.nodes.iter_mut().filter(|n| n.alive) {
            if node.reader.poll_timeout().is_some_and(|t| t <= now) {
                node.reader.handle_timeout(now);
            }
        }
        self.flush();
        self.produce();
        self.consume();
        self.flush();
    }

    fn receive(&mut self, packet: Packet) {
        let now = self.now;
        let node = &mut self.nodes[packet.reader];
        match packet.body {
            Body::AckNack { acked, missing } => {
                self.writer
                    .handle_acknack(now, packet.reader, acked, missing.as_bytes());
            }
            _ if !node.alive || !node.attached => {}
            Body::Sample { seq, value } => node.reader.handle_sample(now, seq, value),
            Body::Gap { from, to } => node.reader.handle_gap(from, to),
            Body::Heartbeat { first, last } => node.reader.handle_heartbeat(now, first, last),
        }
    }

    fn produce(&mut self) {
        let now = self.now;
        while self.next_seq <= self.producer.total && self.next_write <= now {
            if self.producer.respect_window && !self.writer.window_open() {
                self.blocked_since.get_or_insert(now);
                return;
            }
            if let Some(since) = self.blocked_since.take() {
                self.blocked_for += now - since;
            }
            let seq = self.next_seq;
            self.writer
                .write(now, seq, value(seq), self.producer.bytes)
                .expect("consecutive seqs");
            self.max_history = self.max_history.max(self.writer.history_len());
            for key in 0..self.nodes.len() {
                if self.nodes[key].attached {
                    self.send(
                        key,
                        Body::Sample {
                            seq,
                            value: value(seq),
                        },
                        true,
                    );
                }
            }
            self.next_seq += 1;
            self.next_write += self.producer.interval;
        }
    }

    fn consume(&mut self) {
        let now = self.now;
        for node in self.nodes.iter_mut().filter(|n| n.alive) {
            let limit = match node.consumer {
                Consumer::Eager => usize::MAX,
                Consumer::Slow { every, batch } => {
                    if node.next_take > now {
                        0
                    } else {
                        node.next_take = now + every;
                        batch
                    }
                }
            };
            for _ in 0..limit {
                let Some(delivery) = node.reader.poll_deliver() else {
                    break;
                };
                node.got.push(delivery);
            }
            self.max_buffered = self.max_buffered.max(node.reader.buffered());
        }
    }

    fn flush(&mut self) {
        while let Some(output) = self.writer.poll_output() {
            let (key, body) = match output {
                WriterOutput::Resend {
                    reader,
                    seq,
                    sample,
                } => (reader, Body::Sample { seq, value: sample }),
                WriterOutput::Gap { reader, from, to } => {
                    self.nodes[reader].told_gone.push((from, to));
                    (reader, Body::Gap { from, to })
                }
                WriterOutput::Heartbeat {
                    reader,
                    first,
                    last,
                } => {
                    self.nodes[reader].told_gone.push((0, first));
                    (reader, Body::Heartbeat { first, last })
                }
            };
            self.send(key, body, false);
        }
        for key in 0..self.nodes.len() {
            if !self.nodes[key].alive {
                continue;
            }
            while let Some(ack) = self.nodes[key].reader.poll_output() {
                let asked = ack.asked().collect();
                self.nodes[key].acknacks.push((ack.acked, asked));
                let body = Body::AckNack {
                    acked: ack.acked,
                    missing: ack.missing,
                };
                self.send(key, body, false);
            }
        }
    }

    /// Puts a datagram on the link of reader `key` (either direction), or drops it.
    fn send(&mut self, key: usize, body: Body, original: bool) {
        let now = self.now;
        let offset = now - self.t0;
        let link = &self.nodes[key].link;
        let out = link.outages.iter().any(|&(a, b)| offset >= a && offset < b);
        let dropped = out || self.rng.f64() < link.loss;
        let copies = if self.rng.f64() < link.duplicate {
            2
        } else {
            1
        };
        let delays: Vec<Duration> = (0..copies)
            .map(|_| link.latency + link.jitter.mul_f64(self.rng.f64()))
            .collect();
        let stats = &mut self.nodes[key].stats;
        let is_sample = matches!(body, Body::Sample { .. });
        if is_sample {
            stats.samples_sent += 1;
        }
        if dropped {
            match (is_sample, original) {
                (true, true) => {
                    stats.samples_dropped += 1;
                    stats.originals_dropped += 1;
                }
                (true, false) => stats.samples_dropped += 1,
                _ => stats.control_dropped += 1,
            }
            return;
        }
        stats.duplicated += copies - 1;
        for delay in delays {
            self.order += 1;
            let packet = Packet {
                reader: key,
                body: body.clone(),
            };
            self.queue.insert((now + delay, self.order), packet);
        }
    }
}

/// Checks that `got` hands out `first..=last` in order, each seq exactly once as a sample or
/// inside one lost range, every lost range followed by a sample (so runs are merged), and
/// returns the lost ranges.
pub fn check_stream(
    got: &[Delivery<u64>],
    first: u64,
    last: u64,
) -> Result<Vec<(u64, u64)>, String> {
    let mut expected = first;
    let mut lost = Vec::new();
    for (i, item) in got.iter().enumerate() {
        match *item {
            Delivery::Sample { seq, sample } => {
                if seq != expected || sample != value(seq) {
                    return Err(format!("item {i}: {item:?}, expected seq {expected}"));
                }
                expected += 1;
            }
            Delivery::Lost { from, to } => {
                if from != expected || to <= from {
                    return Err(format!("item {i}: {item:?}, expected from {expected}"));
                }
                if !matches!(got.get(i + 1), Some(Delivery::Sample { .. })) {
                    return Err(format!("item {i}: {item:?} not followed by a sample"));
                }
                lost.push((from, to));
                expected = to;
            }
        }
    }
    if expected != last + 1 {
        return Err(format!(
            "stream ends before {expected}, expected up to {last}"
        ));
    }
    Ok(lost)
}

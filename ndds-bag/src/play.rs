//! The player: publishes recorded samples on their topics, with their recorded types (so the
//! fingerprints match what consumers expect), a producer per recorded producer with its
//! recorded strength, persistence and reliability, and the recorded timing scaled by a rate.
//!
//! Files are read twice: a first pass collects the channels (every one must be playable,
//! else the player refuses naming it), the time range and the message count, and declares
//! the producers; the second pass publishes, several files merged in log-time order.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use ndds_client::{Participant, ProducerQos, RawProducer, Reliability, TypeDescription};
use ndds_core::wire::Guid;
use regex::Regex;

use crate::BagError;
use crate::read::{BagMessage, BagReader, Merged};

/// How to play.
#[derive(Clone, Debug)]
pub struct PlayOptions {
    /// Speed: 2.0 plays twice as fast.
    pub rate: f64,
    /// Start again at the end, until stopped.
    pub repeat: bool,
    /// Skip this much of the recording's start.
    pub start: Duration,
    /// Play only this much (after `start`).
    pub duration: Option<Duration>,
    /// Only these recorded topics (`None`: all).
    pub topics: Option<Vec<String>>,
    /// Never these recorded topics.
    pub exclude: Option<Regex>,
    /// Recorded topic → topic played on.
    pub remap: HashMap<String, String>,
    /// Every producer's strength (`None`: as recorded).
    pub strength: Option<i32>,
    /// Every producer's reliability (`None`: as recorded).
    pub reliability: Option<Reliability>,
    /// Wait this long after declaring the producers, so consumers match before the first
    /// sample.
    pub delay: Duration,
}

impl Default for PlayOptions {
    fn default() -> Self {
        PlayOptions {
            rate: 1.0,
            repeat: false,
            start: Duration::ZERO,
            duration: None,
            topics: None,
            exclude: None,
            remap: HashMap::new(),
            strength: None,
            reliability: None,
            delay: Duration::from_millis(500),
        }
    }
}

impl PlayOptions {
    fn wants(&self, topic: &str) -> bool {
        if self.exclude.as_ref().is_some_and(|re| re.is_match(topic)) {
            return false;
        }
        self.topics
            .as_ref()
            .is_none_or(|topics| topics.iter().any(|t| t == topic))
    }

    fn played_topic<'a>(&'a self, topic: &'a str) -> &'a str {
        self.remap.get(topic).map_or(topic, String::as_str)
    }
}

/// Control of a running player from another thread (a terminal's keys, a signal).
#[derive(Debug)]
pub struct PlayControl {
    paused: AtomicBool,
    steps: AtomicU64,
    rate_bits: AtomicU64,
    stop: AtomicBool,
}

impl PlayControl {
    /// A control at `rate`, playing or paused.
    pub fn new(rate: f64, paused: bool) -> Self {
        PlayControl {
            paused: AtomicBool::new(paused),
            steps: AtomicU64::new(0),
            rate_bits: AtomicU64::new(rate.to_bits()),
            stop: AtomicBool::new(false),
        }
    }

    /// Pauses or resumes.
    pub fn toggle_pause(&self) {
        self.paused.fetch_xor(true, Ordering::AcqRel);
    }

    /// Whether paused.
    pub fn is_paused(&self) -> bool {
        self.paused.load(Ordering::Acquire)
    }

    /// While paused: publish the next message now.
    pub fn step(&self) {
        self.steps.fetch_add(1, Ordering::AcqRel);
    }

    /// The rate.
    pub fn rate(&self) -> f64 {
        f64::from_bits(self.rate_bits.load(Ordering::Acquire))
    }

    /// Sets the rate (bounded to 0.01..=1000).
    pub fn set_rate(&self, rate: f64) {
        let rate = if rate.is_finite() {
            rate.clamp(0.01, 1000.0)
        } else {
            1.0
        };
        self.rate_bits.store(rate.to_bits(), Ordering::Release);
    }

    /// Stops the player after the message it is at.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
    }

    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }
}

/// Where a player is, for a progress display.
#[derive(Clone, Copy, Debug, Default)]
pub struct Progress {
    /// Recording time played so far (from the start offset).
    pub position: Duration,
    /// Recording time to play in all (one pass).
    pub total: Duration,
    /// Messages published.
    pub published: u64,
    /// Passes completed (with `repeat`).
    pub passes: u64,
}

/// What a player did.
#[derive(Clone, Debug, Default)]
pub struct PlaySummary {
    /// Messages published.
    pub published: u64,
    /// Messages whose write failed (a reliable producer whose consumers did not keep up).
    pub failed: u64,
    /// Per played topic.
    pub topics: std::collections::BTreeMap<String, u64>,
}

/// One producer per recorded producer.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
struct ProducerKey {
    topic: String,
    fingerprint: u64,
    writer: Option<Guid>,
    strength: i32,
    reliable: bool,
}

/// Plays bags.
#[derive(Debug)]
pub struct Player {
    participant: Participant,
    files: Vec<PathBuf>,
    options: PlayOptions,
    producers: HashMap<ProducerKey, RawProducer>,
    /// First and last log time over all files.
    range: Option<(u64, u64)>,
    /// Messages of one pass (selected topics, after `start`, within `duration`).
    messages: u64,
    log: Mutex<Vec<String>>,
}

impl Player {
    /// Reads the files' channels and declares a producer for each recorded producer of the
    /// selected topics; refuses a channel it cannot play, naming it.
    pub fn open(
        participant: &Participant,
        files: Vec<PathBuf>,
        options: PlayOptions,
    ) -> Result<Self, BagError> {
        if !(options.rate > 0.0 && options.rate.is_finite()) {
            return Err(BagError::Usage(format!(
                "rate {} is not a positive number",
                options.rate
            )));
        }
        let mut player = Player {
            participant: participant.clone(),
            files,
            options,
            producers: HashMap::new(),
            range: None,
            messages: 0,
            log: Mutex::new(Vec::new()),
        };
        let first = crate::read::first_log_time(&player.files)?;
        let from = first.map_or(0, |f| f.saturating_add(nanos(player.options.start)));
        let to = player
            .options
            .duration
            .map_or(u64::MAX, |d| from.saturating_add(nanos(d)));
        let mut last = None;
        for path in player.files.clone() {
            let mut reader = BagReader::open(&path)?;
            while let Some(message) = reader.next_message()? {
                if message.channel.json_of().is_some()
                    || !player.options.wants(&message.channel.topic)
                {
                    continue;
                }
                let desc = message.channel.playable(&path)?.clone();
                player.producer_for(&message, &desc)?;
                last = Some(last.map_or(message.log_time, |l: u64| l.max(message.log_time)));
                if message.log_time >= from && message.log_time <= to {
                    player.messages += 1;
                }
            }
            if let Some(warning) = ending_warning(&reader) {
                player.log.lock().expect("not poisoned").push(warning);
            }
        }
        if let (Some(first), Some(last)) = (first, last) {
            player.range = Some((first, last));
        }
        Ok(player)
    }

    /// Warnings about the files (truncated, damaged), for the user.
    pub fn warnings(&self) -> Vec<String> {
        self.log.lock().expect("not poisoned").clone()
    }

    /// Messages one pass publishes.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// Recording time one pass covers.
    pub fn total(&self) -> Duration {
        let Some((first, last)) = self.range else {
            return Duration::ZERO;
        };
        let span = Duration::from_nanos(last - first).saturating_sub(self.options.start);
        self.options.duration.map_or(span, |d| d.min(span))
    }

    /// The producers declared.
    pub fn producers(&self) -> impl Iterator<Item = &RawProducer> {
        self.producers.values()
    }

    fn producer_for(
        &mut self,
        message: &BagMessage,
        desc: &TypeDescription,
    ) -> Result<&RawProducer, BagError> {
        let meta = &message.channel.meta;
        let reliability = self.options.reliability.unwrap_or(meta.reliability);
        let strength = self.options.strength.unwrap_or(meta.strength);
        let topic = self.options.played_topic(&message.channel.topic).to_owned();
        let key = ProducerKey {
            topic: topic.clone(),
            fingerprint: desc.fingerprint(),
            writer: meta.writer,
            strength,
            reliable: matches!(reliability, Reliability::Reliable { .. }),
        };
        if !self.producers.contains_key(&key) {
            let qos = ProducerQos {
                strength,
                persistence: meta.persistence,
                reliability,
                write_timeout: Duration::from_secs(5),
                ..ProducerQos::default()
            };
            let producer = self
                .participant
                .raw_producer(&topic, desc.clone(), qos)
                .map_err(|e| BagError::Participant(format!("producer of {topic}: {e}")))?;
            self.producers.insert(key.clone(), producer);
        }
        Ok(&self.producers[&key])
    }

    /// Plays until the end (or forever with `repeat`, until `control` stops it), calling
    /// `progress` after each message and, while it waits for the next one (paused, or a gap in
    /// the recording), at least every 50 ms: a status line stays current through a pause.
    pub fn run(
        &mut self,
        control: &PlayControl,
        mut progress: impl FnMut(Progress),
    ) -> Result<PlaySummary, BagError> {
        let mut summary = PlaySummary::default();
        let Some((first, _)) = self.range else {
            return Ok(summary);
        };
        std::thread::sleep(self.options.delay);
        let from = first + nanos(self.options.start);
        let to = self
            .options
            .duration
            .map_or(u64::MAX, |d| from.saturating_add(nanos(d)));
        let mut passes = 0;
        loop {
            let mut merged = Merged::open(&self.files)?;
            let mut clock = PlayClock::new(from, control.rate());
            while let Some((message, path)) = merged.next_message()? {
                if control.stopped() {
                    return Ok(summary);
                }
                if message.log_time < from
                    || message.channel.json_of().is_some()
                    || !self.options.wants(&message.channel.topic)
                {
                    continue;
                }
                if message.log_time > to {
                    break;
                }
                let total = self.total();
                let waited = clock.wait_until(message.log_time, control, &mut |position| {
                    progress(Progress {
                        position: Duration::from_nanos(position.saturating_sub(from)),
                        total,
                        published: summary.published,
                        passes,
                    })
                });
                if !waited {
                    return Ok(summary);
                }
                let desc = message.channel.playable(path)?.clone();
                let producer = self.producer_for(&message, &desc)?;
                match producer.write_bytes(&message.data) {
                    Ok(()) => {
                        summary.published += 1;
                        *summary
                            .topics
                            .entry(producer.topic().to_owned())
                            .or_default() += 1;
                    }
                    Err(err) => {
                        summary.failed += 1;
                        tracing::warn!(topic = producer.topic(), %err, "a recorded sample could not be published");
                    }
                }
                progress(Progress {
                    position: Duration::from_nanos(message.log_time - from),
                    total: self.total(),
                    published: summary.published,
                    passes,
                });
            }
            passes += 1;
            if !self.options.repeat || control.stopped() {
                break;
            }
        }
        for producer in self.producers.values() {
            let _ = producer.flush();
            if matches!(producer.qos().reliability, Reliability::Reliable { .. }) {
                producer.wait_for_acknowledgments(Duration::from_secs(2));
            }
        }
        Ok(summary)
    }
}

/// Maps recording time to wall time at a rate that may change, through pauses.
struct PlayClock {
    /// Recording time and the instant it was played at.
    anchor: (u64, Instant),
    rate: f64,
    /// While paused: the recording time reached when the pause began.
    held: Option<u64>,
}

impl PlayClock {
    fn new(from: u64, rate: f64) -> Self {
        PlayClock {
            anchor: (from, Instant::now()),
            rate,
            held: None,
        }
    }

    /// The recording time reached now.
    fn position(&self) -> u64 {
        let played = self.anchor.1.elapsed().as_secs_f64() * self.rate * 1e9;
        self.anchor.0.saturating_add(played as u64)
    }

    /// Waits until `log_time` is due; false when stopped meanwhile. `waiting` is told the
    /// recording time reached, at least every 50 ms while it waits.
    fn wait_until(
        &mut self,
        log_time: u64,
        control: &PlayControl,
        waiting: &mut dyn FnMut(u64),
    ) -> bool {
        let mut told = Instant::now();
        loop {
            if control.stopped() {
                return false;
            }
            if told.elapsed() >= Duration::from_millis(50) {
                waiting(self.position().min(log_time));
                told = Instant::now();
            }
            if control.is_paused() {
                let held = match self.held {
                    Some(held) => held,
                    None => {
                        let held = self.position().min(log_time);
                        self.held = Some(held);
                        held
                    }
                };
                if control
                    .steps
                    .fetch_update(Ordering::AcqRel, Ordering::Acquire, |s| s.checked_sub(1))
                    .is_ok()
                {
                    // A step publishes the next message and holds there.
                    self.held = Some(log_time);
                    self.anchor = (log_time, Instant::now());
                    return true;
                }
                self.anchor = (held, Instant::now());
                std::thread::sleep(Duration::from_millis(10));
                continue;
            }
            if let Some(held) = self.held.take() {
                // Resuming plays on from where the pause held, not all at once.
                self.anchor = (held, Instant::now());
            }
            let rate = control.rate();
            if rate != self.rate {
                // Re-anchor where the old rate had got to.
                self.anchor = (self.position(), Instant::now());
                self.rate = rate;
            }
            let ahead = log_time.saturating_sub(self.anchor.0) as f64 / 1e9 / self.rate;
            let due = self.anchor.1 + Duration::from_secs_f64(ahead);
            let now = Instant::now();
            if now >= due {
                return true;
            }
            // Sleep in slices, so a pause, a new rate or a stop is seen within 50 ms.
            std::thread::sleep((due - now).min(Duration::from_millis(50)));
        }
    }
}

fn nanos(duration: Duration) -> u64 {
    u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX)
}

/// A warning for a file that did not read to its end.
pub fn ending_warning(reader: &BagReader) -> Option<String> {
    match reader.ending() {
        crate::Ending::Truncated { length } => Some(format!(
            "{}: truncated at byte {length}; playing what was read before",
            reader.path().display()
        )),
        crate::Ending::Damaged { error } => Some(format!(
            "{}: damaged ({error}); playing what was read before",
            reader.path().display()
        )),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn the_clock_keeps_recorded_spacing_scaled_by_the_rate() {
        let control = PlayControl::new(2.0, false);
        let mut clock = PlayClock::new(0, control.rate());
        let started = Instant::now();
        assert!(clock.wait_until(0, &control, &mut |_| {}));
        // 100 ms of recording at rate 2: 50 ms.
        assert!(clock.wait_until(100 * MS, &control, &mut |_| {}));
        let took = started.elapsed();
        assert!(took >= Duration::from_millis(50), "{took:?}");
        assert!(took < Duration::from_millis(90), "{took:?}");
    }

    #[test]
    fn a_pause_holds_a_step_releases_one_message_and_resuming_goes_on_from_there() {
        let control = std::sync::Arc::new(PlayControl::new(1.0, true));
        let mut clock = PlayClock::new(0, control.rate());
        let stepper = {
            let control = std::sync::Arc::clone(&control);
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(150));
                control.step();
            })
        };
        // Paused: the first message waits for the step, not for its time (0), and whoever
        // draws the progress hears of the held position meanwhile.
        let started = Instant::now();
        let mut told = Vec::new();
        assert!(clock.wait_until(0, &control, &mut |position| told.push(position)));
        assert!(started.elapsed() >= Duration::from_millis(100));
        assert!(!told.is_empty() && told.iter().all(|&p| p == 0), "{told:?}");
        stepper.join().unwrap();
        // Resumed after a while paused: the next message (20 ms later in the recording) comes
        // 20 ms after resuming, not at once for the time spent paused.
        std::thread::sleep(Duration::from_millis(40));
        control.toggle_pause();
        let resumed = Instant::now();
        assert!(clock.wait_until(20 * MS, &control, &mut |_| {}));
        let took = resumed.elapsed();
        assert!(took >= Duration::from_millis(15), "{took:?}");
        assert!(took < Duration::from_millis(60), "{took:?}");
        // Stopping ends a wait.
        control.stop();
        assert!(!clock.wait_until(10_000 * MS, &control, &mut |_| {}));
    }

    #[test]
    fn rates_are_bounded() {
        let control = PlayControl::new(1.0, false);
        control.set_rate(1e9);
        assert_eq!(control.rate(), 1000.0);
        control.set_rate(0.0);
        assert_eq!(control.rate(), 0.01);
        control.set_rate(f64::NAN);
        assert_eq!(control.rate(), 1.0);
    }
}

//! Sample habitats: a named periodic task on its own thread that runs one execution list.
//!
//! A timer-clocked habitat sleeps until absolute deadlines `t0 + k·period` on
//! `CLOCK_MONOTONIC` (timer slack 1 ns), so late wake-ups never accumulate into drift; a
//! sample that runs past the next deadline skips it and counts an *overrun*. A topic-clocked
//! habitat runs one sample per sample received on its clock topic (`u64` ticks); a manual one
//! runs when [`Habitat::step`] is called (simulation, tests).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};

use super::sync::lock;
use std::thread::JoinHandle;
use std::time::Duration;

use super::clock::{now_ns, ns, pin_to_cpu, set_realtime, sleep_until_ns, tighten_timer_slack};
use super::list::{BoundaryTask, ExecList, inside_routine};
use super::requests::Request;
use super::stats::{HabitatStats, Timings, percentiles};
use super::{Inner, VerifyReport};
use ndds_client::error::DeclareError;
use ndds_client::{ConsumerQos, RawConsumer, TypeDescription};

/// What clocks a habitat.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Clock {
    /// Its own timer at the habitat's rate.
    Timer,
    /// One sample per `u64` tick received on this topic (the rate is then nominal: it is what
    /// `timing_changed` reports and what period jitter is measured against).
    Topic(String),
    /// [`Habitat::step`] runs each sample.
    Manual,
}

/// How a habitat is created.
#[derive(Clone, Debug)]
pub struct HabitatOptions {
    /// Sample period.
    pub period: Duration,
    /// What clocks it.
    pub clock: Clock,
    /// `SCHED_FIFO` priority for its thread (needs `CAP_SYS_NICE`; refused requests are logged
    /// and sampling goes on at normal priority).
    pub realtime_priority: Option<i32>,
    /// Pin its thread to this CPU.
    pub cpu: Option<usize>,
    /// How often its statistics are handed over (and published).
    pub stats_interval: Duration,
}

impl HabitatOptions {
    /// A timer-clocked habitat at `hz`.
    pub fn rate(hz: f64) -> Self {
        Self {
            // An unusable rate gives a zero period, which `create_habitat` refuses.
            period: period_of(hz).unwrap_or(Duration::ZERO),
            clock: Clock::Timer,
            realtime_priority: None,
            cpu: None,
            stats_interval: Duration::from_secs(1),
        }
    }

    /// With another clock.
    pub fn clock(mut self, clock: Clock) -> Self {
        self.clock = clock;
        self
    }
}

/// The slowest usable rate: one sample an hour.
pub const MIN_RATE_HZ: f64 = 1.0 / 3600.0;
/// The fastest usable rate.
pub const MAX_RATE_HZ: f64 = 1e6;

/// The period of a rate, if it is a usable one ([`MIN_RATE_HZ`] ..= [`MAX_RATE_HZ`]).
pub(crate) fn period_of(hz: f64) -> Option<Duration> {
    (hz.is_finite() && (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&hz))
        .then(|| Duration::from_secs_f64(1.0 / hz))
}

/// Whether a period is usable (the period of a usable rate, within rounding).
pub(crate) fn period_is_usable(period: Duration) -> bool {
    let secs = period.as_secs_f64();
    (1.0 / MAX_RATE_HZ * 0.999..=1.0 / MIN_RATE_HZ * 1.001).contains(&secs)
}

/// Statistics intervals accepted: 10 ms ..= 1 h.
pub(crate) fn stats_interval_is_usable(interval: Duration) -> bool {
    (Duration::from_millis(10)..=Duration::from_secs(3600)).contains(&interval)
}

/// What can go wrong controlling a habitat.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HabitatError {
    /// It was referenced (a placeholder) but never created.
    #[error("habitat `{0}` is referenced but was never created")]
    NotCreated(String),
    /// `start` while sampling.
    #[error("habitat `{0}` is already sampling")]
    AlreadyRunning(String),
    /// `step` while not sampling.
    #[error("habitat `{0}` is not sampling (call start first)")]
    NotRunning(String),
    /// `step` on a habitat with its own clock.
    #[error("habitat `{0}` has its own clock; step() is for Clock::Manual habitats")]
    NotManual(String),
    /// The system does not verify: nothing was started.
    #[error("habitat `{habitat}` not started: the system does not verify\n{report}")]
    Verify {
        /// The habitat.
        habitat: String,
        /// Every problem found.
        report: VerifyReport,
    },
    /// A rate that is not finite, not positive, or above 1 MHz.
    #[error("habitat `{habitat}`: {hz} Hz is not a usable rate (from one sample an hour to 1 MHz)")]
    InvalidRate {
        /// The habitat.
        habitat: String,
        /// The rate asked for.
        hz: f64,
    },
    /// A statistics interval outside 10 ms ..= 1 h.
    #[error("habitat `{habitat}`: a statistics interval of {interval:?} is outside 10 ms ..= 1 h")]
    InvalidStatsInterval {
        /// The habitat.
        habitat: String,
        /// The interval asked for.
        interval: Duration,
    },
    /// The runtime it belonged to was dropped.
    #[error("habitat `{0}`: its runtime is gone")]
    RuntimeGone(String),
    /// A topic clock needs a participant.
    #[error("habitat `{0}`: a topic clock needs a runtime with a participant")]
    NoParticipant(String),
    /// The clock topic could not be subscribed.
    #[error("habitat `{habitat}`: clock topic: {source}")]
    ClockTopic {
        /// The habitat.
        habitat: String,
        /// Why.
        source: DeclareError,
    },
    /// Called from inside a module's routine, where it cannot be carried out (it would wait
    /// for the routine itself); `start`, `stop`, `set_rate` and `reset` are queued instead.
    #[error("habitat `{habitat}`: {operation} cannot be called from inside a module's routine")]
    InsideRoutine {
        /// The habitat.
        habitat: String,
        /// What was called.
        operation: &'static str,
    },
    /// The thread could not be spawned.
    #[error("habitat `{habitat}`: cannot spawn its thread: {source}")]
    Spawn {
        /// The habitat.
        habitat: String,
        /// Why.
        source: std::io::Error,
    },
}

/// A handle to a habitat (cheap to clone; every clone is the same habitat).
#[derive(Clone)]
pub struct Habitat {
    pub(crate) shared: Arc<Shared>,
}

pub(crate) struct Shared {
    pub(crate) name: String,
    pub(crate) list: Mutex<ExecList>,
    options: Mutex<Option<HabitatOptions>>,
    slot: Mutex<StatsSlot>,
    sampling: AtomicBool,
    stop: AtomicBool,
    samples: AtomicU64,
    overruns: AtomicU64,
    thread: Mutex<Option<JoinHandle<()>>>,
    /// Held by `start` and `stop` so that concurrent calls take turns.
    control: Mutex<()>,
    runtime: Weak<Inner>,
}

struct StatsSlot {
    interval: Timings,
    total: Timings,
    interval_s: f64,
}

impl Habitat {
    /// A placeholder (not created) habitat.
    pub(crate) fn placeholder(name: &str, runtime: Weak<Inner>) -> Self {
        Self {
            shared: Arc::new(Shared {
                name: name.to_owned(),
                list: Mutex::new(ExecList::new(Duration::from_millis(1))),
                options: Mutex::new(None),
                slot: Mutex::new(StatsSlot {
                    interval: Timings::new(),
                    total: Timings::new(),
                    interval_s: 0.0,
                }),
                sampling: AtomicBool::new(false),
                stop: AtomicBool::new(false),
                samples: AtomicU64::new(0),
                overruns: AtomicU64::new(0),
                thread: Mutex::new(None),
                control: Mutex::new(()),
                runtime,
            }),
        }
    }

    /// Creates (binds) the habitat.
    pub(crate) fn create(&self, options: HabitatOptions) {
        lock(&self.shared.list).ctx.period = options.period;
        *lock(&self.shared.options) = Some(options);
    }

    /// Its name.
    pub fn name(&self) -> &str {
        &self.shared.name
    }

    /// A handle that does not keep the habitat alive (what a module keeps).
    pub fn downgrade(&self) -> HabitatLink {
        HabitatLink {
            name: self.shared.name.clone(),
            shared: Arc::downgrade(&self.shared),
        }
    }

    /// What clocks it (`None` until it is created).
    pub fn clock(&self) -> Option<Clock> {
        lock(&self.shared.options).as_ref().map(|o| o.clock.clone())
    }

    /// Its rate in Hz: the one last set (see [`period`](Self::period)).
    pub fn rate_hz(&self) -> f64 {
        1.0 / self.period().as_secs_f64()
    }

    /// Whether it was created (not just referenced).
    pub fn is_created(&self) -> bool {
        lock(&self.shared.options).is_some()
    }

    /// How often its statistics are handed over.
    pub fn stats_interval(&self) -> Duration {
        lock(&self.shared.options)
            .as_ref()
            .map_or(Duration::from_secs(1), |o| o.stats_interval)
    }

    /// Whether sampling runs.
    pub fn is_running(&self) -> bool {
        self.shared.sampling.load(Ordering::Acquire)
    }

    /// The sample period: the one last set (a rate change reaches the modules, with
    /// `timing_changed`, at the next sample boundary).
    pub fn period(&self) -> Duration {
        let configured = lock(&self.shared.options).as_ref().map(|o| o.period);
        configured.unwrap_or_else(|| lock(&self.shared.list).ctx.period)
    }

    /// Whether a thread of its own samples it now (a timer or topic clock): routines are then
    /// called there, and other threads queue work for its sample boundary.
    fn has_thread(&self) -> bool {
        lock(&self.shared.thread).is_some()
    }

    /// Queues `request` to the runtime's request thread (for calls made inside a routine).
    fn request(&self, request: Request) -> Result<(), HabitatError> {
        self.runtime()?.request(request);
        Ok(())
    }

    /// Names of the active modules in execution order.
    pub fn order(&self) -> Vec<String> {
        lock(&self.shared.list).order_names()
    }

    /// Names of every installed module, in installation order.
    pub fn modules(&self) -> Vec<String> {
        let list = lock(&self.shared.list);
        list.slots.iter().map(|slot| slot.name.clone()).collect()
    }

    fn runtime(&self) -> Result<Arc<Inner>, HabitatError> {
        self.shared
            .runtime
            .upgrade()
            .ok_or_else(|| HabitatError::RuntimeGone(self.shared.name.clone()))
    }

    /// Begins sampling: verifies the whole runtime (refusing to start if any problem is
    /// found), calls every module's `startup`, then the active modules' `enable`, then starts
    /// the clock.
    ///
    /// Called from inside a module's routine, the start is queued to the runtime's request
    /// thread and carried out after that routine (its outcome is logged).
    pub fn start(&self) -> Result<(), HabitatError> {
        if inside_routine() {
            return self.request(Request::Start(self.shared.name.clone()));
        }
        let runtime = self.runtime()?;
        let _structure = runtime.structure();
        let _turn = lock(&self.shared.control);
        let name = &self.shared.name;
        let options = lock(&self.shared.options)
            .clone()
            .ok_or_else(|| HabitatError::NotCreated(name.clone()))?;
        if self.is_running() {
            return Err(HabitatError::AlreadyRunning(name.clone()));
        }
        let report = runtime.verify();
        if !report.is_ok() {
            return Err(HabitatError::Verify {
                habitat: name.clone(),
                report,
            });
        }
        let clock_consumer = match &options.clock {
            Clock::Topic(topic) => {
                let participant = runtime
                    .participant
                    .as_ref()
                    .ok_or_else(|| HabitatError::NoParticipant(name.clone()))?;
                let qos = ConsumerQos {
                    depth: 64,
                    ..ConsumerQos::default()
                };
                Some(
                    participant
                        .raw_consumer(topic, TypeDescription::of::<u64>(), qos)
                        .map_err(|source| HabitatError::ClockTopic {
                            habitat: name.clone(),
                            source,
                        })?,
                )
            }
            _ => None,
        };
        self.shared.samples.store(0, Ordering::Relaxed);
        self.shared.overruns.store(0, Ordering::Relaxed);
        lock(&self.shared.list).start();
        self.shared.stop.store(false, Ordering::Release);
        self.shared.sampling.store(true, Ordering::Release);
        if options.clock == Clock::Manual {
            return Ok(());
        }
        let shared = Arc::clone(&self.shared);
        let spawned = std::thread::Builder::new()
            .name(format!("habitat-{name}"))
            .spawn(move || match clock_consumer {
                Some(consumer) => run_topic_clock(&shared, &options, &consumer),
                None => run_timer(&shared, &options),
            });
        match spawned {
            Ok(handle) => {
                *lock(&self.shared.thread) = Some(handle);
                Ok(())
            }
            Err(source) => {
                lock(&self.shared.list).stop();
                self.shared.sampling.store(false, Ordering::Release);
                Err(HabitatError::Spawn {
                    habitat: name.clone(),
                    source,
                })
            }
        }
    }

    /// Ends sampling after the current sample: the active modules' `disable`, then every
    /// module's `shutdown`. Does nothing if it is not sampling. Called from inside a module's
    /// routine, the stop is queued and carried out right after that routine's sample.
    pub fn stop(&self) {
        if inside_routine() {
            if let Err(err) = self.request(Request::Stop(self.shared.name.clone())) {
                tracing::warn!(habitat = %self.shared.name, error = %err, "stop not queued");
            }
            return;
        }
        // Without its runtime (being dropped) nothing else can change the habitat.
        let runtime = self.shared.runtime.upgrade();
        let _structure = runtime.as_ref().map(|rt| rt.structure());
        self.stop_now();
    }

    pub(crate) fn stop_now(&self) {
        let _turn = lock(&self.shared.control);
        self.shared.stop.store(true, Ordering::Release);
        let thread = lock(&self.shared.thread).take();
        if let Some(thread) = thread
            && thread.join().is_err()
        {
            tracing::error!(habitat = %self.shared.name, "habitat thread panicked");
        }
        lock(&self.shared.list).stop();
        self.shared.sampling.store(false, Ordering::Release);
    }

    /// Runs one sample of a [`Clock::Manual`] habitat, on the calling thread.
    pub fn step(&self) -> Result<(), HabitatError> {
        let name = &self.shared.name;
        if inside_routine() {
            return Err(HabitatError::InsideRoutine {
                habitat: name.clone(),
                operation: "step",
            });
        }
        let manual = lock(&self.shared.options)
            .as_ref()
            .map(|options| options.clock == Clock::Manual);
        match manual {
            None => return Err(HabitatError::NotCreated(name.clone())),
            Some(false) => return Err(HabitatError::NotManual(name.clone())),
            Some(true) => {}
        }
        let start = now_ns();
        {
            let mut list = lock(&self.shared.list);
            if !list.sampling {
                return Err(HabitatError::NotRunning(name.clone()));
            }
            list.run_sample();
        }
        let exec = now_ns().saturating_sub(start);
        self.shared.samples.fetch_add(1, Ordering::Relaxed);
        let mut slot = lock(&self.shared.slot);
        slot.interval.record(None, None, exec);
        slot.total.record(None, None, exec);
        Ok(())
    }

    /// Changes the rate: at the next sample boundary the modules see the new period and
    /// every module's `timing_changed` runs (on the habitat's thread when one samples it, at
    /// once otherwise). A timer-clocked habitat starts its new phase at that sample. Called
    /// from inside a module's routine, the change is queued to the runtime's request thread.
    pub fn set_rate(&self, hz: f64) -> Result<(), HabitatError> {
        let period = period_of(hz).ok_or_else(|| HabitatError::InvalidRate {
            habitat: self.shared.name.clone(),
            hz,
        })?;
        if inside_routine() {
            return self.request(Request::SetRate(self.shared.name.clone(), hz));
        }
        let runtime = self.shared.runtime.upgrade();
        let _structure = runtime.as_ref().map(|rt| rt.structure());
        if let Some(options) = lock(&self.shared.options).as_mut() {
            options.period = period;
        }
        self.at_boundary(BoundaryTask::Timing(period));
        Ok(())
    }

    /// Calls every module's `reset` at the next sample boundary (at once when it is not
    /// sampling; queued to the runtime's request thread when called inside a routine).
    pub fn reset(&self) {
        if inside_routine() {
            if let Err(err) = self.request(Request::Reset(self.shared.name.clone())) {
                tracing::warn!(habitat = %self.shared.name, error = %err, "reset not queued");
            }
            return;
        }
        let runtime = self.shared.runtime.upgrade();
        let _structure = runtime.as_ref().map(|rt| rt.structure());
        self.at_boundary(BoundaryTask::Reset);
    }

    /// Queues `task` for the next sample of a habitat with a thread of its own; otherwise
    /// carries it out now, on this thread (holding the list's lock is then itself a sample
    /// boundary: a manual habitat's `step` waits for it, and no thread of its own does).
    fn at_boundary(&self, task: BoundaryTask) {
        let threaded = self.has_thread();
        let mut list = lock(&self.shared.list);
        let now = !(threaded && list.sampling);
        list.at_boundary(task, now);
    }

    /// Statistics: counters since sampling began, distributions over the last complete
    /// statistics interval.
    pub fn stats(&self) -> HabitatStats {
        let rate_hz = 1.0 / self.period().as_secs_f64();
        let (active, errors) = {
            let list = lock(&self.shared.list);
            (list.order.len(), list.module_errors)
        };
        let slot = lock(&self.shared.slot);
        HabitatStats {
            runtime: String::new(),
            habitat: self.shared.name.clone(),
            running: self.is_running(),
            rate_hz,
            samples: self.shared.samples.load(Ordering::Relaxed),
            overruns: self.shared.overruns.load(Ordering::Relaxed),
            module_errors: errors,
            active_modules: u32::try_from(active).unwrap_or(u32::MAX),
            configuration: String::new(),
            interval_s: slot.interval_s,
            latency: percentiles(&slot.interval.latency),
            period_jitter: percentiles(&slot.interval.jitter),
            exec: percentiles(&slot.interval.exec),
        }
    }

    /// The same figures over everything since the habitat was created (for benchmarks).
    pub fn stats_total(&self) -> HabitatStats {
        let mut stats = self.stats();
        let slot = lock(&self.shared.slot);
        stats.latency = percentiles(&slot.total.latency);
        stats.period_jitter = percentiles(&slot.total.jitter);
        stats.exec = percentiles(&slot.total.exec);
        stats.interval_s = 0.0;
        stats
    }
}

/// A habitat as a module keeps it ([`Binder::habitat`](crate::Binder::habitat)): it does
/// not keep the habitat alive (the habitat holds the module), so each use may find it gone.
///
/// From inside a routine, [`set_rate`](Self::set_rate), [`reset`](Self::reset),
/// [`start`](Self::start) and [`stop`](Self::stop) are queued to the runtime's request thread
/// and take effect at a sample boundary after the routine returns; the queries answer at once.
#[derive(Clone)]
pub struct HabitatLink {
    name: String,
    shared: std::sync::Weak<Shared>,
}

impl HabitatLink {
    /// The habitat's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The habitat, while it exists. Private: a routine holding its own habitat's `Habitat`
    /// could ask it for what needs the list its sampler holds (`stats`, `order`) and wait for
    /// itself; the link offers only what answers without it.
    fn upgrade(&self) -> Option<Habitat> {
        self.shared.upgrade().map(|shared| Habitat { shared })
    }

    fn get(&self) -> Result<Habitat, HabitatError> {
        self.upgrade()
            .ok_or_else(|| HabitatError::RuntimeGone(self.name.clone()))
    }

    /// What clocks it (`None` if it was dropped or not created).
    pub fn clock(&self) -> Option<Clock> {
        self.upgrade().and_then(|h| h.clock())
    }

    /// Its rate in Hz, the one last set (`None` if it was dropped or not created). Reads only
    /// the habitat's options, never its list: safe from its own routines.
    pub fn rate_hz(&self) -> Option<f64> {
        let shared = self.shared.upgrade()?;
        let period = lock(&shared.options).as_ref().map(|o| o.period)?;
        Some(1.0 / period.as_secs_f64())
    }

    /// [`Habitat::set_rate`].
    pub fn set_rate(&self, hz: f64) -> Result<(), HabitatError> {
        self.get()?.set_rate(hz)
    }

    /// [`Habitat::reset`].
    pub fn reset(&self) -> Result<(), HabitatError> {
        self.get().map(|h| h.reset())
    }

    /// [`Habitat::start`].
    pub fn start(&self) -> Result<(), HabitatError> {
        self.get()?.start()
    }

    /// [`Habitat::stop`].
    pub fn stop(&self) -> Result<(), HabitatError> {
        self.get().map(|h| h.stop())
    }
}

impl std::fmt::Debug for HabitatLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HabitatLink")
            .field("name", &self.name)
            .finish()
    }
}

impl std::fmt::Debug for Habitat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Habitat")
            .field("name", &self.shared.name)
            .field("created", &self.is_created())
            .field("running", &self.is_running())
            .finish()
    }
}

/// Per-thread setup: precise timers, and the optional priority and pinning.
fn prepare_thread(name: &str, options: &HabitatOptions) {
    tighten_timer_slack();
    if let Some(priority) = options.realtime_priority
        && let Err(err) = set_realtime(priority)
    {
        tracing::warn!(habitat = name, priority, error = %err, "SCHED_FIFO refused; sampling at normal priority");
    }
    if let Some(cpu) = options.cpu
        && let Err(err) = pin_to_cpu(cpu)
    {
        tracing::warn!(habitat = name, cpu, error = %err, "cannot pin the habitat thread");
    }
}

/// The habitat thread's own timing state.
struct Recorder {
    local: Timings,
    interval: u64,
    flush_at: u64,
    flushed_at: u64,
}

impl Recorder {
    fn new(interval: Duration, now: u64) -> Self {
        let interval = ns(interval).max(1_000_000);
        Self {
            local: Timings::new(),
            interval,
            flush_at: now.saturating_add(interval),
            flushed_at: now,
        }
    }

    /// Hands the interval's histograms over if it is time and the slot is free.
    fn maybe_flush(&mut self, shared: &Shared, now: u64, force: bool) {
        if now < self.flush_at && !force {
            return;
        }
        let slot = if force {
            Some(lock(&shared.slot))
        } else {
            shared.slot.try_lock().ok()
        };
        if let Some(mut slot) = slot {
            slot.total.add(&self.local);
            std::mem::swap(&mut slot.interval, &mut self.local);
            slot.interval_s = now.saturating_sub(self.flushed_at) as f64 / 1e9;
            self.local.reset();
            self.flushed_at = now;
            self.flush_at = now.saturating_add(self.interval);
        }
    }
}

const STOP_CHECK_NS: u64 = 20_000_000;

fn run_timer(shared: &Shared, options: &HabitatOptions) {
    prepare_thread(&shared.name, options);
    let mut period = ns(lock(&shared.list).ctx.period).max(1);
    let mut next = now_ns();
    let mut rec = Recorder::new(options.stats_interval, next);
    let mut previous_start: Option<u64> = None;
    'sampling: loop {
        loop {
            if shared.stop.load(Ordering::Acquire) {
                break 'sampling;
            }
            let now = now_ns();
            if now >= next {
                break;
            }
            sleep_until_ns(next.min(now.saturating_add(STOP_CHECK_NS)));
        }
        let start = now_ns();
        {
            let mut list = lock(&shared.list);
            if !list.boundary.is_empty() {
                list.run_boundary_tasks();
            }
            let p = ns(list.ctx.period).max(1);
            if p != period {
                period = p;
                next = start;
                previous_start = None;
            }
            list.run_sample();
        }
        let end = now_ns();
        let jitter = previous_start.map(|prev| (start - prev).abs_diff(period));
        rec.local
            .record(Some(start.saturating_sub(next)), jitter, end - start);
        shared.samples.fetch_add(1, Ordering::Relaxed);
        previous_start = Some(start);
        next = next.saturating_add(period);
        if end > next {
            let missed = (end - next) / period + 1;
            shared.overruns.fetch_add(missed, Ordering::Relaxed);
            next = next.saturating_add(missed.saturating_mul(period));
            previous_start = None;
        }
        rec.maybe_flush(shared, end, false);
    }
    rec.maybe_flush(shared, now_ns(), true);
}

fn run_topic_clock(shared: &Shared, options: &HabitatOptions, clock: &RawConsumer) {
    prepare_thread(&shared.name, options);
    let mut rec = Recorder::new(options.stats_interval, now_ns());
    let mut previous_start: Option<u64> = None;
    while !shared.stop.load(Ordering::Acquire) {
        if clock
            .recv_raw_wait(Duration::from_nanos(STOP_CHECK_NS))
            .is_err()
        {
            rec.maybe_flush(shared, now_ns(), false);
            continue;
        }
        let start = now_ns();
        let period = {
            let mut list = lock(&shared.list);
            list.run_sample();
            ns(list.ctx.period)
        };
        let end = now_ns();
        let jitter = previous_start.map(|prev| (start - prev).abs_diff(period));
        rec.local.record(None, jitter, end - start);
        shared.samples.fetch_add(1, Ordering::Relaxed);
        previous_start = Some(start);
        rec.maybe_flush(shared, end, false);
    }
    rec.maybe_flush(shared, now_ns(), true);
}

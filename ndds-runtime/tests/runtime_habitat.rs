//! Sample habitats (ControlShell paper, section 4): when each entry routine is called, error
//! counting, multi-rate systems joined by a rate transition, timer behaviour (overruns,
//! absolute deadlines, rate changes) and topic clocks.
//!
//! Exact sequences use `Clock::Manual`. Timer tests assert only what is about time, with wide
//! margins: the machine may have two cores and be loaded.

#[path = "../../ndds-client/tests/common/mod.rs"]
mod common;

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::{eventually, participant, unique_config};
use ndds_client::{ConsumerQos, ProducerQos, TypeDescription};
use ndds_runtime::{
    Binder, Clock, CsMat, HabitatError, HabitatOptions, HabitatStats, Mat, ModuleError,
    RoutineResult, Runtime, SampleContext, SampleModule,
};

type Log = Arc<Mutex<Vec<String>>>;
type TestResult = Result<(), Box<dyn std::error::Error>>;

const WAIT: Duration = Duration::from_secs(10);

fn manual() -> HabitatOptions {
    HabitatOptions::rate(100.0).clock(Clock::Manual)
}

fn timer(hz: f64) -> HabitatOptions {
    HabitatOptions {
        stats_interval: Duration::from_millis(200),
        ..HabitatOptions::rate(hz)
    }
}

fn new_log() -> Log {
    Arc::new(Mutex::new(Vec::new()))
}

fn calls(log: &Log) -> Vec<String> {
    log.lock().unwrap().clone()
}

/// The calls logged since `mark`.
fn since(log: &Log, mark: usize) -> Vec<String> {
    log.lock().unwrap()[mark..].to_vec()
}

/// `routine@sample` for each of `modules`.
fn each(modules: &[&str], routine: &str, sample: u64) -> Vec<String> {
    modules
        .iter()
        .map(|m| format!("{m}.{routine}@{sample}"))
        .collect()
}

/// Logs every routine as `"<module>.<routine>@<ctx.sample>"` (`timing_changed` adds the
/// period in µs, `terminate` has no sample). 1 × 1 data flow: each output becomes 1 + the sum
/// of the inputs. `fail_execute` makes `execute` and `startup` return an error.
struct Recorder {
    name: String,
    log: Log,
    inputs: Vec<Mat>,
    outputs: Vec<Mat>,
    fail: bool,
}

impl Recorder {
    fn build(
        b: &mut Binder<'_>,
        log: &Log,
        reads: &[&str],
        writes: &[&str],
    ) -> Result<Self, ModuleError> {
        let mut inputs = Vec::new();
        for mat in reads {
            inputs.push(b.input(mat, (1, 1)));
        }
        let mut outputs = Vec::new();
        for mat in writes {
            outputs.push(b.output(mat, (1, 1)));
        }
        Ok(Self {
            name: b.module_name().to_owned(),
            log: Arc::clone(log),
            inputs,
            outputs,
            fail: false,
        })
    }

    fn failing(mut self) -> Self {
        self.fail = true;
        self
    }

    fn note(&self, routine: &str, ctx: &SampleContext) -> RoutineResult {
        self.log
            .lock()
            .unwrap()
            .push(format!("{}.{routine}@{}", self.name, ctx.sample));
        Ok(())
    }
}

impl SampleModule for Recorder {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.note("execute", ctx)?;
        let sum: f64 = self.inputs.iter().map(|m| m.value(0, 0)).sum();
        for out in &self.outputs {
            out.write().fill(sum + 1.0);
        }
        if self.fail {
            return Err(ModuleError::Failed(format!("{} fails", self.name)));
        }
        Ok(())
    }
    fn state_update(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.note("state_update", ctx)
    }
    fn enable(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.note("enable", ctx)
    }
    fn disable(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.note("disable", ctx)
    }
    fn startup(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.note("startup", ctx)?;
        if self.fail {
            return Err(ModuleError::Failed(format!("{} cannot start", self.name)));
        }
        Ok(())
    }
    fn shutdown(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.note("shutdown", ctx)
    }
    fn timing_changed(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.log.lock().unwrap().push(format!(
            "{}.timing_changed@{}/{}us",
            self.name,
            ctx.sample,
            ctx.period.as_micros()
        ));
        Ok(())
    }
    fn reset(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.note("reset", ctx)
    }
    fn terminate(&mut self) {
        self.log
            .lock()
            .unwrap()
            .push(format!("{}.terminate", self.name));
    }
}

/// Counts its executes; optionally sleeps in each.
struct Busy {
    executes: Arc<Mutex<u64>>,
    sleep: Duration,
}

impl SampleModule for Busy {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        *self.executes.lock().unwrap() += 1;
        if !self.sleep.is_zero() {
            std::thread::sleep(self.sleep);
        }
        Ok(())
    }
}

fn busy(executes: &Arc<Mutex<u64>>, sleep: Duration) -> Busy {
    Busy {
        executes: Arc::clone(executes),
        sleep,
    }
}

// ----- entry routines -----

/// Installs, in list order, `c` (reads y), `b` (reads x, writes y), `a` (writes x) and `d`
/// (in an inactive group): execution order a, b, c.
fn three_in_a_chain(rt: &Runtime, log: &Log) -> TestResult {
    rt.group("extras", "none", &[])?;
    rt.group("extras", "all", &["d"])?;
    rt.install("h", "c", |b| Recorder::build(b, log, &["y"], &["z"]))?;
    rt.install("h", "b", |b| Recorder::build(b, log, &["x"], &["y"]))?;
    rt.install("h", "a", |b| Recorder::build(b, log, &[], &["x"]))?;
    rt.install("h", "d", |b| Recorder::build(b, log, &[], &["dz"]))?;
    Ok(())
}

#[test]
fn entry_routines_are_called_as_the_table_says() -> TestResult {
    let rt = Runtime::new("routines");
    let log = new_log();
    let h = rt.create_habitat("h", manual())?;
    three_in_a_chain(&rt, &log)?;
    assert_eq!(h.modules(), ["c", "b", "a", "d"], "list order");
    assert_eq!(h.order(), ["a", "b", "c"], "execution order");
    assert!(
        calls(&log).is_empty(),
        "installing a stopped habitat calls nothing"
    );

    // start: every startup in list order (inactive d too), then enables in execution order.
    h.start()?;
    let mut expected = each(&["c", "b", "a", "d"], "startup", 0);
    expected.extend(each(&["a", "b", "c"], "enable", 0));
    assert_eq!(calls(&log), expected);

    // each sample: the executes in order, then the state updates.
    for sample in 0..2 {
        let mark = calls(&log).len();
        h.step()?;
        let mut expected = each(&["a", "b", "c"], "execute", sample);
        expected.extend(each(&["a", "b", "c"], "state_update", sample));
        assert_eq!(since(&log, mark), expected);
    }
    assert_eq!(rt.mat("z").value(0, 0), 3.0, "a ran before b before c");

    // set_rate: timing_changed of every module, with the new period.
    let mark = calls(&log).len();
    h.set_rate(200.0)?;
    assert_eq!(h.period(), Duration::from_millis(5));
    assert_eq!(
        since(&log, mark),
        ["c", "b", "a", "d"].map(|m| format!("{m}.timing_changed@2/5000us"))
    );

    // reset: every module.
    let mark = calls(&log).len();
    h.reset();
    assert_eq!(since(&log, mark), each(&["c", "b", "a", "d"], "reset", 2));

    // stop: disables of the active modules in execution order, then every shutdown.
    let mark = calls(&log).len();
    h.stop();
    let mut expected = each(&["a", "b", "c"], "disable", 2);
    expected.extend(each(&["c", "b", "a", "d"], "shutdown", 2));
    assert_eq!(since(&log, mark), expected);
    let mark = calls(&log).len();
    h.stop();
    assert!(since(&log, mark).is_empty(), "stopping twice calls nothing");

    // Sampling again starts from sample 0.
    let mark = calls(&log).len();
    h.start()?;
    h.step()?;
    let mut expected = each(&["c", "b", "a", "d"], "startup", 0);
    expected.extend(each(&["a", "b", "c"], "enable", 0));
    expected.extend(each(&["a", "b", "c"], "execute", 0));
    expected.extend(each(&["a", "b", "c"], "state_update", 0));
    assert_eq!(since(&log, mark), expected);

    // Removing a module while sampling: disable, shutdown, terminate.
    let mark = calls(&log).len();
    rt.remove("c")?;
    assert_eq!(
        since(&log, mark),
        ["c.disable@1", "c.shutdown@1", "c.terminate"]
    );
    assert_eq!(h.order(), ["a", "b"]);
    assert_eq!(rt.modules(), ["a", "b", "d"]);

    // Installing into a sampling habitat: startup, then enable.
    let mark = calls(&log).len();
    rt.install("h", "e", |b| Recorder::build(b, &log, &["y"], &["e_out"]))?;
    assert_eq!(since(&log, mark), ["e.startup@1", "e.enable@1"]);
    assert_eq!(h.order(), ["a", "b", "e"]);

    // Dropping the runtime while sampling: it stops, then every module is terminated.
    let mark = calls(&log).len();
    drop(rt);
    let mut expected = each(&["a", "b", "e"], "disable", 1);
    expected.extend(each(&["b", "a", "d", "e"], "shutdown", 1));
    expected.extend(["b", "a", "d", "e"].map(|m| format!("{m}.terminate")));
    assert_eq!(since(&log, mark), expected);
    assert!(!h.is_running());
    assert!(h.modules().is_empty());
    Ok(())
}

#[test]
fn dropping_a_stopped_runtime_terminates_every_module_once() -> TestResult {
    let rt = Runtime::new("drop");
    let log = new_log();
    let h = rt.create_habitat("h", manual())?;
    three_in_a_chain(&rt, &log)?;
    h.start()?;
    h.step()?;
    h.stop();
    let mark = calls(&log).len();
    let clone = rt.clone();
    drop(rt);
    assert!(
        since(&log, mark).is_empty(),
        "a clone keeps the runtime alive"
    );
    drop(clone);
    assert_eq!(
        since(&log, mark),
        ["c", "b", "a", "d"].map(|m| format!("{m}.terminate"))
    );
    Ok(())
}

#[test]
fn a_failing_routine_is_counted_and_sampling_goes_on() -> TestResult {
    let rt = Runtime::new("errors");
    let log = new_log();
    let h = rt.create_habitat("h", manual())?;
    rt.install("h", "bad", |b| {
        Recorder::build(b, &log, &[], &["x"]).map(Recorder::failing)
    })?;
    rt.install("h", "good", |b| Recorder::build(b, &log, &["x"], &["y"]))?;
    h.start()?;
    assert_eq!(h.stats().module_errors, 1, "the failed startup");
    for _ in 0..5 {
        h.step()?;
    }
    let stats = h.stats();
    assert_eq!(stats.module_errors, 6, "one startup and five executes");
    assert_eq!(stats.samples, 5);
    let log = calls(&log);
    for module in ["bad", "good"] {
        let executes = log
            .iter()
            .filter(|c| c.starts_with(&format!("{module}.execute")))
            .count();
        assert_eq!(executes, 5, "{module} keeps being called: {log:?}");
    }
    assert_eq!(
        rt.mat("y").value(0, 0),
        2.0,
        "the failing module's output still flows"
    );

    // On its own clock too.
    let executes = Arc::new(Mutex::new(0));
    let t = rt.create_habitat("t", timer(200.0))?;
    let t_log = new_log();
    rt.install("t", "t-bad", |b| {
        Recorder::build(b, &t_log, &[], &["tx"]).map(Recorder::failing)
    })?;
    rt.install("t", "t-count", |_| Ok(busy(&executes, Duration::ZERO)))?;
    t.start()?;
    assert!(eventually(WAIT, || *executes.lock().unwrap() >= 20));
    t.stop();
    let stats = t.stats();
    assert!(stats.samples >= 20, "{stats:?}");
    assert_eq!(stats.module_errors, 1 + stats.samples, "{stats:?}");
    Ok(())
}

// ----- timer habitats -----

/// Writes a 4 × 4 matrix whose elements all equal the sample number.
struct Ramp {
    out: Mat,
}

impl SampleModule for Ramp {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.out.write().fill(ctx.sample as f64);
        Ok(())
    }
}

#[derive(Default)]
struct Seen {
    samples: u64,
    torn: u64,
    decreases: u64,
    last: f64,
    values: BTreeSet<u64>,
}

/// Checks that every matrix it reads is whole (16 equal elements) and never goes back.
struct Checker {
    input: Mat,
    seen: Arc<Mutex<Seen>>,
}

impl SampleModule for Checker {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let m = self.input.read();
        let first = m.get(0, 0)?;
        let whole = m.shape() == (4, 4) && m.matrix().iter().all(|&v| v == first);
        let mut seen = self.seen.lock().unwrap();
        seen.samples += 1;
        if !whole {
            seen.torn += 1;
        }
        if first < seen.last {
            seen.decreases += 1;
        }
        seen.last = first;
        seen.values.insert(first as u64);
        Ok(())
    }
}

fn assert_rate(hz: f64, expected: f64) {
    assert!((hz - expected).abs() < 1e-6, "rate {hz} != {expected}");
}

#[test]
fn two_timer_habitats_joined_by_a_rate_transition_never_tear() -> TestResult {
    let rt = Runtime::new("multirate");
    let fast = rt.create_habitat("fast", timer(1000.0))?;
    let slow = rt.create_habitat("slow", timer(100.0))?;
    let seen = Arc::new(Mutex::new(Seen::default()));
    rt.install("fast", "ramp", |b| {
        Ok(Ramp {
            out: b.output("m", (4, 4)),
        })
    })?;
    rt.rate_transition("link", ("fast", "m"), ("slow", "m_slow"))?;
    rt.install("slow", "checker", |b| {
        Ok(Checker {
            input: b.input("m_slow", (4, 4)),
            seen: Arc::clone(&seen),
        })
    })?;
    assert_eq!(fast.order(), ["ramp", "link.in"]);
    assert_eq!(slow.order(), ["link.out", "checker"]);
    assert!(rt.verify().is_ok(), "{}", rt.verify());

    let began = Instant::now();
    rt.start_all()?;
    assert!(fast.is_running() && slow.is_running());
    std::thread::sleep(Duration::from_millis(1000));
    let (f, s) = (fast.stats(), slow.stats());
    let elapsed = began.elapsed().as_secs_f64();
    rt.stop_all();
    // Sample counts consistent with the rates (a timer never runs ahead of its deadlines).
    assert!(f.running && s.running);
    assert_rate(f.rate_hz, 1000.0);
    assert_rate(s.rate_hz, 100.0);
    let fast_max = (1000.0 * elapsed) as u64 + 2;
    let slow_max = (100.0 * elapsed) as u64 + 2;
    assert!(
        f.samples >= 500 && f.samples <= fast_max,
        "fast: {} samples in {elapsed:.3} s",
        f.samples
    );
    assert!(
        s.samples >= 50 && s.samples <= slow_max,
        "slow: {} samples in {elapsed:.3} s",
        s.samples
    );
    // Distributions over the last complete statistics interval (200 ms).
    for stats in [&f, &s] {
        assert!(
            stats.interval_s > 0.1 && stats.interval_s < 1.0,
            "{stats:?}"
        );
        assert!(stats.period_jitter.count > 0, "{stats:?}");
        assert!(stats.latency.count > 0, "{stats:?}");
        assert!(stats.exec.count > 0, "{stats:?}");
        assert!(
            stats.period_jitter.p50_us <= stats.period_jitter.p99_us
                && stats.period_jitter.p99_us <= stats.period_jitter.max_us,
            "{stats:?}"
        );
        assert_eq!(stats.active_modules, 2);
    }
    assert!(
        f.exec.count < f.samples,
        "the distribution covers one interval, not everything: {f:?}"
    );

    let seen = seen.lock().unwrap();
    let after = slow.stats();
    assert!(!after.running);
    assert_eq!(
        seen.samples, after.samples,
        "the checker ran once per slow sample"
    );
    assert_eq!(seen.torn, 0, "{} torn reads", seen.torn);
    assert_eq!(
        seen.decreases, 0,
        "the value went back {} times",
        seen.decreases
    );
    assert!(
        seen.values.len() >= 10,
        "only {} distinct values reached the slow habitat",
        seen.values.len()
    );
    assert!(
        *seen.values.last().unwrap() < fast.stats().samples,
        "values come from the fast habitat's samples"
    );
    Ok(())
}

/// A fast habitat `fast` writing `m` (4 × 4) through `link` to `m_slow` in `slow`, manual clocks.
fn manual_rate_transition(rt: &Runtime, transition_first: bool) -> TestResult {
    rt.create_habitat("fast", manual())?;
    rt.create_habitat("slow", manual())?;
    let ramp = |b: &mut Binder<'_>| {
        Ok(Ramp {
            out: b.output("m", (4, 4)),
        })
    };
    if transition_first {
        rt.rate_transition("link", ("fast", "m"), ("slow", "m_slow"))?;
        rt.install("fast", "ramp", ramp)?;
    } else {
        rt.install("fast", "ramp", ramp)?;
        rt.rate_transition("link", ("fast", "m"), ("slow", "m_slow"))?;
    }
    Ok(())
}

#[test]
fn a_rate_transition_hands_over_the_newest_complete_value() -> TestResult {
    let rt = Runtime::new("transition");
    manual_rate_transition(&rt, false)?;
    assert!(rt.verify().is_ok(), "{}", rt.verify());
    let (fast, slow) = (rt.habitat("fast"), rt.habitat("slow"));
    let m_slow = rt.mat("m_slow");
    assert_eq!(m_slow.shape(), (4, 4), "created with its source's shape");
    fast.start()?;
    slow.start()?;
    for _ in 0..3 {
        fast.step()?;
    }
    assert_eq!(
        m_slow.value(3, 3),
        0.0,
        "only copied at the slow habitat's sample"
    );
    slow.step()?;
    assert!(m_slow.snapshot().matrix().iter().all(|&v| v == 2.0));
    slow.step()?;
    assert_eq!(
        m_slow.value(0, 0),
        2.0,
        "held while the source does not run"
    );
    fast.step()?;
    slow.step()?;
    assert_eq!(m_slow.value(2, 1), 3.0);
    Ok(())
}

/// Reference before creation: a rate transition declared before its source CSMat exists gets
/// its destination created when the source is.
#[test]
fn a_rate_transition_declared_before_its_source_follows_its_shape() -> TestResult {
    let rt = Runtime::new("transition-early");
    manual_rate_transition(&rt, true)?;
    let m_slow = rt.mat("m_slow");
    assert_eq!(
        m_slow.shape(),
        (4, 4),
        "`m_slow` should take the shape of `m` once `m` exists: {m_slow:?}\n{}",
        rt.verify()
    );
    assert!(rt.verify().is_ok(), "{}", rt.verify());
    let (fast, slow) = (rt.habitat("fast"), rt.habitat("slow"));
    fast.start()?;
    slow.start()?;
    fast.step()?;
    fast.step()?;
    slow.step()?;
    assert_eq!(m_slow.value(3, 3), 1.0);
    Ok(())
}

#[test]
fn a_sample_running_past_its_deadline_skips_deadlines_and_counts_overruns() -> TestResult {
    let rt = Runtime::new("overrun");
    let h = rt.create_habitat("h", timer(1000.0))?;
    let executes = Arc::new(Mutex::new(0));
    rt.install("h", "slow", |_| {
        Ok(busy(&executes, Duration::from_millis(3)))
    })?;
    let began = Instant::now();
    h.start()?;
    std::thread::sleep(Duration::from_millis(1000));
    h.stop();
    let elapsed_ms = began.elapsed().as_secs_f64() * 1000.0;
    let stats = h.stats();
    assert!(stats.overruns > 0, "{stats:?}");
    // 3 ms samples fit at most every third 1 ms deadline; a habitat that ran the missed ones
    // late (bursting) would count no overruns and run samples back to back.
    assert!(
        (stats.samples as f64) < 0.5 * elapsed_ms,
        "{} samples in {elapsed_ms:.0} ms at 1 kHz with 3 ms samples",
        stats.samples
    );
    assert_eq!(stats.samples, *executes.lock().unwrap());
    // Every deadline is either sampled or counted as skipped.
    let deadlines = (stats.samples + stats.overruns) as f64;
    assert!(
        deadlines <= elapsed_ms + 2.0 && deadlines >= 0.85 * elapsed_ms - 20.0,
        "{} samples + {} overruns for {elapsed_ms:.0} deadlines",
        stats.samples,
        stats.overruns
    );
    Ok(())
}

#[test]
fn a_timer_habitat_does_not_drift() -> TestResult {
    let rt = Runtime::new("drift");
    let h = rt.create_habitat("h", timer(200.0))?;
    let executes = Arc::new(Mutex::new(0));
    // 1 ms of work each 5 ms period: sleeping a period after each sample would make 166 Hz.
    rt.install("h", "work", |_| {
        Ok(busy(&executes, Duration::from_millis(1)))
    })?;
    let began = Instant::now();
    h.start()?;
    std::thread::sleep(Duration::from_secs(2));
    h.stop();
    let elapsed = began.elapsed().as_secs_f64();
    let stats = h.stats();
    let expected = 200.0 * elapsed;
    // Each deadline is either sampled or (if the thread was starved past it) counted as an
    // overrun: with absolute deadlines they add up to the elapsed periods.
    let deadlines = (stats.samples + stats.overruns) as f64;
    assert!(
        (deadlines - expected).abs() <= 20.0,
        "{} samples + {} overruns in {elapsed:.3} s (expected {expected:.0} ± 20)",
        stats.samples,
        stats.overruns
    );
    assert!(
        stats.samples as f64 >= 0.8 * expected,
        "{} samples in {elapsed:.3} s ({} overruns)",
        stats.samples,
        stats.overruns
    );
    Ok(())
}

#[test]
fn set_rate_changes_the_rate_of_a_running_habitat() -> TestResult {
    let rt = Runtime::new("set-rate");
    let log = new_log();
    let h = rt.create_habitat("h", timer(100.0))?;
    rt.install("h", "m", |b| Recorder::build(b, &log, &[], &["x"]))?;
    h.start()?;
    let window = Duration::from_millis(600);
    // Let the habitat get going, then count over a window at each rate.
    std::thread::sleep(Duration::from_millis(50));
    let rate_over = |window: Duration| {
        let (t0, s0) = (Instant::now(), h.stats().samples);
        std::thread::sleep(window);
        let (t1, s1) = (Instant::now(), h.stats().samples);
        (s1 - s0) as f64 / (t1 - t0).as_secs_f64()
    };
    let before = rate_over(window);
    h.set_rate(400.0)?;
    assert_eq!(h.period(), Duration::from_micros(2500));
    assert_rate(h.stats().rate_hz, 400.0);
    std::thread::sleep(Duration::from_millis(50));
    let after = rate_over(window);
    h.stop();
    assert!((60.0..=105.0).contains(&before), "{before:.1} Hz at 100 Hz");
    assert!((240.0..=405.0).contains(&after), "{after:.1} Hz at 400 Hz");
    assert!(
        calls(&log)
            .iter()
            .any(|c| c.starts_with("m.timing_changed@") && c.ends_with("/2500us")),
        "{:?}",
        calls(&log)
    );
    Ok(())
}

#[test]
fn unusable_rates_are_refused() -> TestResult {
    let rt = Runtime::new("bad-rates");
    let log = new_log();
    let h = rt.create_habitat("h", manual())?;
    rt.install("h", "m", |b| Recorder::build(b, &log, &[], &["x"]))?;
    for hz in [0.0, -0.0, -100.0, f64::NAN, f64::INFINITY, 1.000_001e6, 1e9] {
        match h.set_rate(hz) {
            Err(HabitatError::InvalidRate { habitat, hz: got }) => {
                assert_eq!(habitat, "h");
                assert!(got.to_bits() == hz.to_bits(), "{got} != {hz}");
            }
            other => panic!("{hz} Hz accepted: {other:?}"),
        }
        assert_eq!(
            h.period(),
            Duration::from_millis(10),
            "unchanged after {hz}"
        );
    }
    assert!(
        calls(&log).is_empty(),
        "no timing_changed: {:?}",
        calls(&log)
    );
    // The limits themselves are usable.
    h.set_rate(1e6)?;
    assert_eq!(h.period(), Duration::from_micros(1));
    h.set_rate(0.5)?;
    assert_eq!(h.period(), Duration::from_secs(2));
    assert_eq!(
        calls(&log),
        ["m.timing_changed@0/1us", "m.timing_changed@0/2000000us"]
    );
    Ok(())
}

#[test]
fn step_and_start_refuse_what_they_cannot_do() -> TestResult {
    let rt = Runtime::new("refusals");
    let t = rt.create_habitat("t", timer(100.0))?;
    let m = rt.create_habitat("m", manual())?;
    rt.create_mat(CsMat::zeros("unused", 1, 1))?;

    assert!(matches!(m.step(), Err(HabitatError::NotRunning(name)) if name == "m"));
    assert!(matches!(t.step(), Err(HabitatError::NotManual(name)) if name == "t"));
    m.start()?;
    assert!(matches!(m.start(), Err(HabitatError::AlreadyRunning(name)) if name == "m"));
    m.step()?;
    assert_eq!(m.stats().samples, 1, "the refused start did not restart it");
    t.start()?;
    assert!(matches!(t.start(), Err(HabitatError::AlreadyRunning(name)) if name == "t"));
    assert!(matches!(t.step(), Err(HabitatError::NotManual(_))));
    t.stop();
    m.stop();
    assert!(matches!(m.step(), Err(HabitatError::NotRunning(_))));
    // Stopped habitats start again.
    m.start()?;
    m.step()?;
    m.stop();
    Ok(())
}

// ----- topic clocks -----

#[test]
fn a_topic_clocked_habitat_runs_one_sample_per_tick() -> TestResult {
    let dir = tempfile::tempdir()?;
    let participant = participant(&unique_config(dir.path(), "clock"));
    let rt = Runtime::with_participant("topic-rt", &participant)?;
    let h = rt.create_habitat(
        "ticked",
        HabitatOptions::rate(50.0).clock(Clock::Topic("test/clock".into())),
    )?;
    let executes = Arc::new(Mutex::new(0));
    rt.install("ticked", "count", |_| Ok(busy(&executes, Duration::ZERO)))?;
    h.start()?;
    assert!(matches!(h.step(), Err(HabitatError::NotManual(_))));

    let ticks = participant.producer::<u64>("test/clock", ProducerQos::default())?;
    assert!(ticks.wait_for_consumers(1, WAIT));
    // Nothing runs without ticks.
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(h.stats().samples, 0);

    const N: u64 = 25;
    for tick in 0..N {
        ticks.write(&tick)?;
    }
    assert!(
        eventually(WAIT, || h.stats().samples == N),
        "{} samples for {N} ticks",
        h.stats().samples
    );
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(h.stats().samples, N, "no sample without a tick");
    assert_eq!(*executes.lock().unwrap(), N);
    assert_rate(h.stats().rate_hz, 50.0);
    h.stop();
    assert!(!h.is_running());
    Ok(())
}

#[test]
fn a_topic_clock_needs_a_participant() -> TestResult {
    let rt = Runtime::new("no-network");
    let log = new_log();
    let h = rt.create_habitat(
        "ticked",
        HabitatOptions::rate(50.0).clock(Clock::Topic("test/clock".into())),
    )?;
    rt.install("ticked", "m", |b| Recorder::build(b, &log, &[], &["x"]))?;
    match h.start() {
        Err(HabitatError::NoParticipant(name)) => assert_eq!(name, "ticked"),
        other => panic!("expected NoParticipant, got {other:?}"),
    }
    assert!(!h.is_running());
    assert!(calls(&log).is_empty(), "nothing started: {:?}", calls(&log));
    Ok(())
}

/// Dropping a runtime with a participant must stop its habitats and terminate their modules
/// whichever thread lets go of it last. Its statistics service holds the runtime during each
/// publishing pass, declaring a producer per habitat on the first pass (slow with many
/// habitats), so an application dropping its handle in the middle of that pass leaves the
/// service's thread the last owner.
#[test]
fn dropping_a_networked_runtime_during_a_statistics_pass_stops_its_habitats() -> TestResult {
    let dir = tempfile::tempdir()?;
    let participant = participant(&unique_config(dir.path(), "drop"));
    let rt = Runtime::with_participant("drop", &participant)?;
    // Habitats are published in name order: `a-watched` first, then the idle ones.
    let watched = participant.raw_consumer(
        "cs/drop/a-watched/stats",
        TypeDescription::of::<HabitatStats>(),
        ConsumerQos::default(),
    )?;
    let log = new_log();
    let h = rt.create_habitat("a-watched", timer(100.0))?;
    rt.install("a-watched", "m", |b| Recorder::build(b, &log, &[], &["x"]))?;
    for i in 0..200 {
        rt.create_habitat(&format!("z-idle{i}"), manual())?;
    }
    h.start()?;
    // The first pass has begun once the watched habitat's producer appears.
    assert!(watched.wait_for_producers(1, WAIT));
    drop(rt);
    let terminated = eventually(WAIT, || calls(&log).iter().any(|c| c == "m.terminate"));
    let running = h.is_running();
    h.stop(); // do not leave the thread sampling if the runtime did not stop it
    assert!(
        terminated && !running,
        "runtime dropped: module terminated: {terminated}, habitat still sampling: {running}"
    );
    Ok(())
}

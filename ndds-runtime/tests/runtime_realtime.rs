//! Habitats are never held hostage by non-real-time work (DESIGN.md section 8): a switch's
//! `enable` runs off the habitat thread while the habitat keeps sampling, and requests a
//! routine makes of its runtime or habitat are queued instead of waiting for the routine
//! itself. These tests check behaviour, not speed: each waits on a condition with a generous
//! bound; the old design (enable under the list lock, re-entrant calls) fails them by
//! deadlock or timeout, not by a few milliseconds.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ndds_runtime::{
    Binder, Clock, HabitatError, HabitatOptions, Mat, ModuleError, RoutineResult, Runtime,
    RuntimeError, SampleContext, SampleModule,
};

type TestResult = Result<(), Box<dyn std::error::Error>>;
/// What an [`Asker`]'s call returned, as text.
type Outcome = Arc<Mutex<Option<String>>>;

const WAIT: Duration = Duration::from_secs(20);

/// Polls `check` every millisecond until it holds or [`WAIT`] passes.
fn eventually(mut check: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + WAIT;
    while Instant::now() < deadline {
        if check() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    check()
}

/// Counts its samples into `count` and writes the count to its output.
struct Counter {
    out: Mat,
    count: Arc<AtomicU64>,
}

impl Counter {
    fn build(b: &mut Binder<'_>, out: &str, count: &Arc<AtomicU64>) -> Self {
        Self {
            out: b.output(out, (1, 1)),
            count: Arc::clone(count),
        }
    }
}

impl SampleModule for Counter {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let n = self.count.fetch_add(1, Ordering::Relaxed) + 1;
        self.out.write().set(0, 0, n as f64)?;
        Ok(())
    }
}

/// An `enable` that lasts until the habitat has run `samples` more samples (an expensive
/// design, such as LQG's): it can only return if the habitat samples while it runs.
struct SlowEnable {
    count: Arc<AtomicU64>,
    samples: u64,
    saw_progress: Arc<AtomicBool>,
}

impl SampleModule for SlowEnable {
    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        let from = self.count.load(Ordering::Relaxed);
        let progressed = eventually(|| self.count.load(Ordering::Relaxed) >= from + self.samples);
        self.saw_progress.store(progressed, Ordering::Relaxed);
        Ok(())
    }
}

#[test]
fn a_long_enable_runs_while_the_habitat_keeps_sampling() -> TestResult {
    let rt = Runtime::new("slow-enable");
    let h = rt.create_habitat("h", HabitatOptions::rate(1000.0))?;
    let count = Arc::new(AtomicU64::new(0));
    let saw_progress = Arc::new(AtomicBool::new(false));
    rt.install("h", "counter", |b| Ok(Counter::build(b, "n", &count)))?;
    let (c, s) = (Arc::clone(&count), Arc::clone(&saw_progress));
    rt.install("h", "design", move |_| {
        Ok(SlowEnable {
            count: c,
            samples: 50,
            saw_progress: s,
        })
    })?;
    rt.group("control", "idle", &[])?;
    rt.group("control", "designed", &["design"])?;
    rt.configuration("Idle", &[("control", "idle")])?;
    rt.configuration("Designed", &[("control", "designed")])?;
    rt.switch("Idle")?;
    h.start()?;
    assert!(eventually(|| count.load(Ordering::Relaxed) > 10));
    rt.switch("Designed")?;
    assert!(
        saw_progress.load(Ordering::Relaxed),
        "the habitat ran 50 samples while the entering module's enable ran"
    );
    assert_eq!(h.order(), ["counter", "design"]);
    h.stop();
    assert_eq!(h.stats_total().module_errors, 0);
    Ok(())
}

/// What a routine asks of its runtime from inside `execute`, once, at sample `at`.
#[derive(Clone)]
enum Ask {
    Switch(&'static str),
    Stop,
    SetRate(f64),
    Install,
    Step,
}

struct Asker {
    runtime: Runtime,
    ask: Ask,
    at: u64,
    outcome: Outcome,
}

impl SampleModule for Asker {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        if ctx.sample != self.at {
            return Ok(());
        }
        let h = self.runtime.habitat("h");
        let outcome = match self.ask.clone() {
            Ask::Switch(name) => self.runtime.switch(name).map_err(|e| e.to_string()),
            Ask::Stop => {
                h.stop();
                Ok(())
            }
            Ask::SetRate(hz) => h.set_rate(hz).map_err(|e| e.to_string()),
            Ask::Install => self
                .runtime
                .install("h", "late", |_| Ok(Idle))
                .map_err(|e| match e {
                    RuntimeError::InsideRoutine { operation } => format!("inside:{operation}"),
                    other => other.to_string(),
                }),
            Ask::Step => h.step().map_err(|e| match e {
                HabitatError::InsideRoutine { operation, .. } => format!("inside:{operation}"),
                other => other.to_string(),
            }),
        };
        *self.outcome.lock().unwrap() = Some(format!("{outcome:?}"));
        Ok(())
    }
}

struct Idle;
impl SampleModule for Idle {}

/// A runtime with habitat `h` running an [`Asker`] and a [`Counter`], and two
/// configurations `A` (the counter alone besides the asker) and `B` (an idle module too).
fn asking(clock: Clock, ask: Ask) -> Result<(Runtime, Outcome), ModuleError> {
    let rt = Runtime::new("asking");
    rt.create_habitat("h", HabitatOptions::rate(500.0).clock(clock))
        .map_err(|e| ModuleError::Failed(e.to_string()))?;
    let outcome = Arc::new(Mutex::new(None));
    let (runtime, o) = (rt.clone(), Arc::clone(&outcome));
    let count = Arc::new(AtomicU64::new(0));
    let installed = rt
        .install("h", "asker", move |_| {
            Ok(Asker {
                runtime,
                ask,
                at: 3,
                outcome: o,
            })
        })
        .and_then(|()| rt.install("h", "counter", |b| Ok(Counter::build(b, "n", &count))))
        .and_then(|()| rt.install("h", "extra", |_| Ok(Idle)))
        .and_then(|()| rt.group("mode", "a", &[]))
        .and_then(|()| rt.group("mode", "b", &["extra"]))
        .and_then(|()| rt.configuration("A", &[("mode", "a")]))
        .and_then(|()| rt.configuration("B", &[("mode", "b")]))
        .and_then(|()| rt.switch("A"));
    installed.map_err(|e| ModuleError::Failed(e.to_string()))?;
    Ok((rt, outcome))
}

#[test]
fn a_routine_that_switches_is_queued_and_the_switch_happens() -> TestResult {
    for clock in [Clock::Timer, Clock::Manual] {
        let (rt, outcome) = asking(clock.clone(), Ask::Switch("B"))?;
        let h = rt.habitat("h");
        h.start()?;
        if clock == Clock::Manual {
            for _ in 0..5 {
                h.step()?;
            }
        }
        assert!(
            eventually(|| rt.current_configuration().as_deref() == Some("B")),
            "{clock:?}: switched by the request thread"
        );
        assert_eq!(outcome.lock().unwrap().as_deref(), Some("Ok(())"));
        assert!(h.order().contains(&"extra".to_owned()), "{:?}", h.order());
        h.stop();
    }
    Ok(())
}

#[test]
fn a_routine_that_stops_its_own_habitat_does_not_deadlock() -> TestResult {
    let (rt, outcome) = asking(Clock::Timer, Ask::Stop)?;
    let h = rt.habitat("h");
    h.start()?;
    assert!(
        eventually(|| !h.is_running()),
        "the queued stop ended sampling"
    );
    assert_eq!(outcome.lock().unwrap().as_deref(), Some("Ok(())"));
    Ok(())
}

#[test]
fn a_routine_that_changes_the_rate_gets_it_at_a_later_boundary() -> TestResult {
    let (rt, outcome) = asking(Clock::Timer, Ask::SetRate(250.0))?;
    let h = rt.habitat("h");
    h.start()?;
    assert!(eventually(|| h.period() == Duration::from_millis(4)));
    assert!(eventually(|| (h.stats().rate_hz - 250.0).abs() < 1e-9));
    assert_eq!(outcome.lock().unwrap().as_deref(), Some("Ok(())"));
    h.stop();
    Ok(())
}

#[test]
fn installing_or_stepping_from_a_routine_is_refused_by_name() -> TestResult {
    for (ask, expected) in [
        (Ask::Install, "Err(\"inside:install\")"),
        (Ask::Step, "Err(\"inside:step\")"),
    ] {
        let (rt, outcome) = asking(Clock::Manual, ask)?;
        let h = rt.habitat("h");
        h.start()?;
        for _ in 0..5 {
            h.step()?;
        }
        assert_eq!(outcome.lock().unwrap().as_deref(), Some(expected));
        assert!(!rt.modules().contains(&"late".to_owned()));
        h.stop();
    }
    Ok(())
}

//! A habitat's rate changed from each place a running system is driven from: a module's own
//! routine (through the `HabitatLink` its binder gave it), a state machine's `rate HABITAT HZ`
//! action, and a configuration's `rates` in the description file (the command line's `ndds
//! habitat` is tested with real processes in ndds-cli's tests/shell.rs). Each change is
//! verified by the habitat's *published* statistics (`cs/RUNTIME/HABITAT/stats`), as a tool
//! sees them, and by the modules' `timing_changed`. A factory or routine using the link never
//! waits for itself. Bad `rate` actions and `rates` tables are refused at load,
//! where they are written.

#[path = "../../ndds-client/tests/common/mod.rs"]
mod common;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use ndds_client::{Consumer, ConsumerQos, Participant, TypeDescription};
use ndds_core::types::builtin;
use ndds_runtime::fsm::Stimulus;
use ndds_runtime::system::{LoadOptions, System, SystemError};
use ndds_runtime::{
    Clock, HabitatLink, HabitatOptions, HabitatStats, ModuleError, RoutineResult, Runtime,
    SampleContext, SampleModule,
};

type TestResult = Result<(), Box<dyn std::error::Error>>;

const WAIT: Duration = Duration::from_secs(20);

fn participant() -> (tempfile::TempDir, Participant) {
    let dir = tempfile::tempdir().unwrap();
    let config = common::unique_config(dir.path(), "habitat-control");
    let participant = common::participant(&config);
    (dir, participant)
}

fn stats_consumer(
    participant: &Participant,
    runtime: &str,
    habitat: &str,
) -> Consumer<HabitatStats> {
    participant
        .consumer_with_type(
            &format!("cs/{runtime}/{habitat}/stats"),
            TypeDescription::named::<HabitatStats>(builtin::HABITAT_STATS),
            ConsumerQos::default(),
        )
        .unwrap()
}

/// Waits until a published statistics sample says `hz`; the last rate seen otherwise.
fn published_rate(consumer: &Consumer<HabitatStats>, hz: f64) -> Result<(), f64> {
    let deadline = std::time::Instant::now() + WAIT;
    let mut last = f64::NAN;
    while std::time::Instant::now() < deadline {
        if let Ok(sample) = consumer.recv_timeout(Duration::from_millis(200)) {
            let stats = sample.value;
            last = stats.rate_hz;
            if (stats.rate_hz - hz).abs() < 1e-6 {
                return Ok(());
            }
        }
    }
    Err(last)
}

/// Counts its samples; at `at`, asks its own habitat for `hz`. Records what it learnt of its
/// habitat and each `timing_changed` period.
struct SelfPacing {
    habitat: HabitatLink,
    at: u64,
    hz: f64,
    seen: Arc<Mutex<Vec<String>>>,
}

impl SampleModule for SelfPacing {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        if ctx.sample == self.at {
            let clock = self.habitat.clock();
            let rate = self.habitat.rate_hz();
            self.seen
                .lock()
                .unwrap()
                .push(format!("{clock:?} {rate:?}"));
            // Queued to the sample boundary: a routine never waits for its own habitat.
            self.habitat
                .set_rate(self.hz)
                .map_err(|e| ModuleError::Failed(e.to_string()))?;
        }
        Ok(())
    }

    fn timing_changed(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.seen
            .lock()
            .unwrap()
            .push(format!("timing {:?}", ctx.period));
        Ok(())
    }
}

#[test]
fn a_module_asks_its_habitat_for_its_clock_and_rate_and_changes_the_rate() -> TestResult {
    let (_dir, participant) = participant();
    let rt = Runtime::with_participant("paced", &participant)?;
    let stats = stats_consumer(&participant, "paced", "servo");
    let mut options = HabitatOptions::rate(100.0);
    options.stats_interval = Duration::from_millis(100);
    let servo = rt.create_habitat("servo", options)?;
    let seen = Arc::new(Mutex::new(Vec::new()));
    let log = Arc::clone(&seen);
    rt.install("servo", "pacer", move |b| {
        let habitat = b.habitat().expect("installed into a habitat");
        assert_eq!(habitat.name(), "servo");
        Ok(SelfPacing {
            habitat,
            at: 5,
            hz: 250.0,
            seen: log,
        })
    })?;
    servo.start()?;
    let result = published_rate(&stats, 250.0);
    servo.stop();
    assert_eq!(result, Ok(()), "the published rate never became 250 Hz");
    let seen = seen.lock().unwrap().clone();
    assert_eq!(
        seen[0],
        format!("{:?} {:?}", Some(Clock::Timer), Some(100.0))
    );
    assert!(
        seen.contains(&format!("timing {:?}", Duration::from_millis(4))),
        "timing_changed saw the new period: {seen:?}"
    );
    Ok(())
}

fn write(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

const SYSTEM: &str = r#"
[system]
name = "paced"

[[habitat]]
name = "servo"
rate = 100.0
stats_interval = 0.1

[[component]]
name = "k"
type = "gain"
habitat = "servo"
group = "ctl/plain"
input = "u"
output = "y"

[[mat]]
name = "u"
value = [1.0]

[[configuration]]
name = "plain"
groups = ["ctl/plain"]

[[configuration]]
name = "fast"
groups = ["ctl/plain"]
rates = { servo = 400 }

[[state_machine]]
file = "pacer.toml"
"#;

const MACHINE: &str = r#"
main = "pacer"

[stimuli]
Faster = "transient"

[[machine]]
name = "pacer"
start = "Slow"
states = ["Slow", "Fast", "Broken"]

[[machine.transition]]
from = "Slow"
when = "Faster"
action = "rate servo 200"
next = { 0 = "Fast", 1 = "Broken" }
"#;

fn load(dir: &std::path::Path, participant: &Participant) -> Result<System, SystemError> {
    System::load_with(
        dir.join("system.toml"),
        Some(participant),
        LoadOptions::default().with_library(ndds_components::library()),
    )
}

#[test]
fn a_state_machine_action_and_a_configuration_change_the_rate() -> TestResult {
    let (_dir, participant) = participant();
    let files = tempfile::tempdir()?;
    write(files.path(), "system.toml", SYSTEM);
    write(files.path(), "pacer.toml", MACHINE);
    let system = load(files.path(), &participant)?;
    let stats = stats_consumer(&participant, "paced", "servo");
    system.start()?;
    assert_eq!(published_rate(&stats, 100.0), Ok(()));

    let machine = system.machine("pacer").expect("the machine runs");
    machine.send(Stimulus::event("Faster"))?;
    assert_eq!(published_rate(&stats, 200.0), Ok(()), "the `rate` action");
    assert!(machine.wait_for_state("Fast", WAIT));

    let rt = system.runtime();
    rt.switch("fast")?;
    assert_eq!(
        published_rate(&stats, 400.0),
        Ok(()),
        "the configuration's rates"
    );
    // A configuration without rates leaves the rate as it is.
    rt.switch("plain")?;
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(rt.habitat("servo").rate_hz(), 400.0);
    system.stop();
    Ok(())
}

#[test]
fn bad_rate_actions_and_rates_tables_are_refused_where_they_are_written() -> TestResult {
    let (_dir, participant) = participant();
    let files = tempfile::tempdir()?;
    let system = SYSTEM.replace(
        "rates = { servo = 400 }",
        "rates = { servoo = 400, servo = 0 }",
    );
    write(files.path(), "system.toml", &system);
    let machine = MACHINE.replace("rate servo 200", "rate servo fast");
    write(files.path(), "pacer.toml", &machine);
    let Err(SystemError::Invalid(problems)) = load(files.path(), &participant) else {
        panic!("the file should be refused");
    };
    let text = problems.to_string();
    assert!(
        text.contains("system.toml:29:")
            && text.contains("habitat `servoo`")
            && text.contains("did you mean `servo`"),
        "{text}"
    );
    assert!(
        text.contains("the rate of `servo` is 0 Hz"),
        "a rate out of range: {text}"
    );
    assert!(
        text.contains("action `rate servo fast`") && text.contains("`rate HABITAT HZ`"),
        "{text}"
    );
    Ok(())
}

/// Runs `work` on a thread of its own and fails if it has not finished within 10 s (a
/// deadlock would otherwise hang the test run).
fn finishes(what: &str, work: impl FnOnce() + Send + 'static) {
    let (done, finished) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        work();
        let _ = done.send(());
    });
    assert!(
        finished.recv_timeout(Duration::from_secs(10)).is_ok(),
        "{what}: did not finish (deadlock)"
    );
}

/// Asks its habitat's rate in `timing_changed`; nothing else.
struct AsksRate {
    habitat: HabitatLink,
    seen: Arc<Mutex<Vec<Option<f64>>>>,
}

impl SampleModule for AsksRate {
    fn timing_changed(&mut self, _: &SampleContext) -> RoutineResult {
        self.seen.lock().unwrap().push(self.habitat.rate_hz());
        Ok(())
    }
}

#[test]
fn a_factory_and_a_routine_using_the_link_never_wait_for_themselves() {
    // A factory that changes its habitat's rate while it is built (its runtime's structure
    // is locked then): the change is queued, as from a routine, and carried out after.
    let rt = Runtime::new("factory");
    let servo = rt
        .create_habitat("servo", HabitatOptions::rate(100.0).clock(Clock::Manual))
        .unwrap();
    let installer = rt.clone();
    finishes("install with set_rate in the factory", move || {
        installer
            .install("servo", "eager", |b| {
                let link = b.habitat().expect("a habitat");
                link.set_rate(50.0)
                    .map_err(|e| ModuleError::Failed(e.to_string()))?;
                link.start()
                    .map_err(|e| ModuleError::Failed(e.to_string()))?;
                Ok(AsksRate {
                    habitat: link,
                    seen: Arc::default(),
                })
            })
            .unwrap();
    });
    assert!(
        common::eventually(WAIT, || servo.rate_hz() == 50.0 && servo.is_running()),
        "the queued rate and start were carried out"
    );

    // A habitat only referenced (not created): its rate change runs `timing_changed` at once,
    // under its list's lock; the module's question must not need that lock.
    let rt = Runtime::new("uncreated");
    let seen = Arc::new(Mutex::new(Vec::new()));
    let log = Arc::clone(&seen);
    rt.install("later", "asker", move |b| {
        Ok(AsksRate {
            habitat: b.habitat().expect("a habitat"),
            seen: log,
        })
    })
    .unwrap();
    let later = rt.habitat("later");
    finishes("timing_changed asking the rate", move || {
        later.set_rate(20.0).unwrap();
    });
    assert_eq!(*seen.lock().unwrap(), [None], "not created: no rate yet");
}

//! Every description file under `examples/` loads, verifies and runs for a bounded number of
//! samples; the closed-loop examples converge (asserted on their tracking errors); the
//! sequencing state machine reaches its end.

#[path = "../../ndds-client/tests/common/mod.rs"]
mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use ndds_runtime::system::{LoadOptions, System};

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// Every `.toml` under `examples/` that is a system (state machine programs, which have a
/// top-level `main`, are loaded through the systems that name them).
fn system_files() -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut dirs = vec![examples()];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "toml") {
                let text = std::fs::read_to_string(&path).unwrap();
                if !text.lines().any(|l| l.starts_with("main = ")) {
                    out.push(path);
                }
            }
        }
    }
    out.sort();
    out
}

fn participant() -> (tempfile::TempDir, ndds_client::Participant) {
    let dir = tempfile::tempdir().unwrap();
    let config = common::unique_config(dir.path(), "examples");
    let participant = common::participant(&config);
    (dir, participant)
}

fn value(system: &System, mat: &str, row: usize) -> f64 {
    system.runtime().mat(mat).value(row, 0)
}

/// Simulates in steps of 0.1 s, giving the state machines real time to act between steps,
/// until `done` or `limit` simulated seconds.
fn simulate_until(system: &System, limit: f64, mut done: impl FnMut(&System) -> bool) -> f64 {
    let mut t = 0.0;
    while t < limit {
        system.simulate(0.1).expect("simulates");
        t += 0.1;
        if done(system) {
            return t;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    t
}

#[test]
fn every_example_loads_verifies_and_runs_bounded_samples() {
    let files = system_files();
    assert!(files.len() >= 5, "examples: {files:?}");
    let (_dir, participant) = participant();
    for file in &files {
        let system = System::load_with(
            file,
            Some(&participant),
            LoadOptions::simulated().with_library(ndds_components::library()),
        )
        .unwrap_or_else(|e| panic!("{}:\n{e}", file.display()));
        assert!(system.runtime().verify().is_ok());
        system.start().unwrap();
        let samples = system.simulate(1.0).unwrap();
        assert!(samples >= 10, "{}: {samples} samples", file.display());
        let status = system.status();
        for h in &status.habitats {
            assert!(
                h.samples > 0,
                "{}: habitat {} ran no sample",
                file.display(),
                h.habitat
            );
            assert_eq!(h.module_errors, 0, "{}: {h:?}", file.display());
        }
        system.stop();
    }
}

#[test]
fn multirate_servo_follows_the_plan_to_the_goal() {
    let system = System::load_with(
        examples().join("multirate.toml"),
        None,
        LoadOptions::simulated().with_library(ndds_components::library()),
    )
    .unwrap();
    system.start().unwrap();
    // Half way through the 2 s plan the servo is between start and goal, and close to the
    // plan.
    system.simulate(1.0).unwrap();
    let (q1, plan1) = (value(&system, "angles", 0), value(&system, "plan", 0));
    assert!(q1 > 0.4 && q1 < 0.9, "q1 half way: {q1}");
    // A PD servo without velocity feed-forward lags a moving plan (here by ~0.06 rad at the
    // plan's top speed, plus up to one planner period).
    assert!(
        (q1 - plan1).abs() < 0.1,
        "servo lags the plan: {q1} vs {plan1}"
    );
    system.simulate(2.0).unwrap();
    let error = [
        value(&system, "angles", 0) - 1.0,
        value(&system, "angles", 1) + 0.4,
    ];
    assert!(
        error.iter().all(|e| e.abs() < 1e-3),
        "joint error after 3 s: {error:?}"
    );
    let stats = system.status().habitats;
    let samples = |name: &str| stats.iter().find(|h| h.habitat == name).unwrap().samples;
    assert_eq!(samples("servo"), 3000);
    assert_eq!(samples("planner"), 150);
    assert_eq!(samples("logger"), 30);
}

#[test]
fn sequence_visits_a_then_b_then_home() {
    let system = System::load_with(
        examples().join("sequence.toml"),
        None,
        LoadOptions::simulated().with_library(ndds_components::library()),
    )
    .unwrap();
    system.start().unwrap();
    let task = || system.machine("task").unwrap().snapshot();
    // Every state of the task, in order (each arrival is a trigger's 2 mm test).
    let mut visited = vec![task().state];
    let t = simulate_until(&system, 30.0, |_| {
        let state = task().state;
        if visited.last() != Some(&state) {
            visited.push(state.clone());
        }
        state == "Done"
    });
    assert_eq!(
        visited,
        ["MovingToA", "MovingToB", "Homing", "Done"],
        "after {t:.1} s simulated"
    );
    assert_eq!(task().transitions, 3);
    assert_eq!(task().faults, 0);
    assert_eq!(
        system.runtime().current_configuration().as_deref(),
        Some("Home")
    );
    simulate_until(&system, 2.0, |_| false);
    assert!(value(&system, "position", 0).abs() < 0.002);
}

/// The quickstart in real time: plant and controller in one process, talking over topics of
/// an embedded daemon. JointPD settles, the supervisor switches to endptLQG, the tip reaches
/// the endpoint goal; the port switches back.
#[test]
fn arm_quickstart_switches_to_lqg_and_reaches_the_endpoint_goal() {
    let (_dir, participant) = participant();
    let system = System::load(
        examples().join("arm.toml"),
        Some(&participant),
        ndds_components::library(),
    )
    .unwrap();
    system.start().unwrap();
    let begun = Instant::now();
    let reached = common::eventually(Duration::from_secs(20), || {
        let s = system.status();
        s.configuration.as_deref() == Some("endptLQG")
            && s.machines[0].state == "Endpoint"
            && value(&system, "tip_error", 0).abs() < 1e-3
            && value(&system, "tip_error", 1).abs() < 1e-3
    });
    assert!(
        reached,
        "after {:?}: {:?}, tip error [{}, {}]",
        begun.elapsed(),
        system.status().configuration,
        value(&system, "tip_error", 0),
        value(&system, "tip_error", 1)
    );

    // The subscribed CSMat took the plant's field names and units.
    let tip = system.runtime().mat("tip").read().clone();
    let fields: Vec<(&str, &str)> = tip
        .row_fields()
        .iter()
        .map(|f| (f.name.as_str(), f.unit.as_str()))
        .collect();
    assert_eq!(fields, [("x", "m"), ("y", "m")]);

    // Another program asks for JointPD through the system's port.
    let user = ndds_client::ports::PortUser::<String, Result<String, String>>::declare(
        &participant,
        "arm-configure",
        "operator",
    )
    .unwrap();
    let reply = user
        .send(&"JointPD".to_owned(), Duration::from_secs(5))
        .unwrap();
    assert_eq!(
        reply,
        Ok("system `arm` switched to configuration `JointPD`".to_owned())
    );
    assert_eq!(
        system.runtime().current_configuration().as_deref(),
        Some("JointPD")
    );
    // An operator takes over: Coarse holds joint control although the joints settle again.
    let supervisor = system.machine("arm").unwrap();
    supervisor
        .send(ndds_runtime::fsm::Stimulus::event("Precise"))
        .unwrap();
    assert!(supervisor.wait_for_state("Endpoint", Duration::from_secs(5)));
    supervisor
        .send(ndds_runtime::fsm::Stimulus::event("Coarse"))
        .unwrap();
    assert!(supervisor.wait_for_state("Held", Duration::from_secs(5)));
    let joints_settle = common::eventually(Duration::from_secs(10), || {
        value(&system, "joint_error", 0).abs() < 0.005
            && value(&system, "joint_error", 1).abs() < 0.005
    });
    assert!(joints_settle, "the joints never settled under JointPD");
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(supervisor.snapshot().state, "Held");
    assert_eq!(
        system.runtime().current_configuration().as_deref(),
        Some("JointPD")
    );
    supervisor
        .send(ndds_runtime::fsm::Stimulus::event("Precise"))
        .unwrap();
    assert!(supervisor.wait_for_state("Endpoint", Duration::from_secs(5)));
    assert_eq!(
        system.runtime().current_configuration().as_deref(),
        Some("endptLQG")
    );

    let refused = user
        .send(&"NoSuch".to_owned(), Duration::from_secs(5))
        .unwrap();
    assert!(refused.is_err_and(|e| e.contains("NoSuch")));
    system.stop();
    let errors = system.status().module_errors();
    assert_eq!(errors, 0);
}

/// Simulated time is one clock across calls: many calls shorter than a period run the samples
/// due, not one sample per call.
#[test]
fn simulated_time_goes_on_across_calls() {
    let text = "[[habitat]]\nname = \"slow\"\nrate = 100\n\n[[habitat]]\nname = \"fast\"\n\
                rate = 1000\n\n[[component]]\nname = \"t\"\ntype = \"ramp\"\nhabitat = \"slow\"\n\
                slope = [1.0]\noutput = \"time\"\n";
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("clock.toml");
    std::fs::write(&file, text).unwrap();
    let system = System::load_with(
        &file,
        None,
        LoadOptions::simulated().with_library(ndds_components::library()),
    )
    .unwrap();
    system.start().unwrap();
    let mut samples = 0;
    for _ in 0..250 {
        samples += system.simulate(0.001).unwrap();
    }
    // 0.25 s: slow samples at 0, 10, ..., 240 ms (25), fast at 0, 1, ..., 249 ms (250).
    assert_eq!(samples, 275);
    let stats = system.status().habitats;
    let samples_of = |name: &str| stats.iter().find(|h| h.habitat == name).unwrap().samples;
    assert_eq!((samples_of("slow"), samples_of("fast")), (25, 250));
    // The ramp's last sample ran at t = 0.24 s.
    assert!((value(&system, "time", 0) - 0.24).abs() < 1e-9);
}

/// A recorder's `file` is relative to the description file, like includes.
#[test]
fn a_recording_is_written_next_to_its_description() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("log.toml");
    std::fs::write(
        &file,
        "[[habitat]]\nname = \"h\"\nrate = 100\n\n[[component]]\nname = \"t\"\ntype = \"ramp\"\n\
         habitat = \"h\"\nslope = [1.0]\noutput = \"time\"\n\n[[component]]\nname = \"rec\"\n\
         type = \"recorder\"\nhabitat = \"h\"\ninputs = [\"time\"]\nfile = \"run.csv\"\n",
    )
    .unwrap();
    let system = System::load_with(
        &file,
        None,
        LoadOptions::simulated().with_library(ndds_components::library()),
    )
    .unwrap();
    system.start().unwrap();
    system.simulate(0.05).unwrap();
    system.stop();
    let csv = std::fs::read_to_string(dir.path().join("run.csv")).expect("the recording");
    assert_eq!(csv.lines().count(), 6, "a header and 5 samples:\n{csv}");
    assert_eq!(system.status().module_errors(), 0);
}

#[test]
fn simulated_a_loop_closed_through_the_systems_own_topics_is_deterministic() {
    let (_dir, participant) = participant();
    let run = || {
        let system = System::load_with(
            examples().join("arm.toml"),
            Some(&participant),
            LoadOptions::simulated().with_library(ndds_components::library()),
        )
        .expect("arm.toml loads");
        let modules = system.runtime().modules();
        assert!(
            modules.iter().any(|m| m == "subscribe:arm/angles.out")
                && !modules.iter().any(|m| m == "subscribe:arm/angles"),
            "the plant's angles reach the controller inside the process: {modules:?}"
        );
        system.start().expect("starts");
        system.simulate(0.5).expect("simulates");
        let angles = (value(&system, "angles", 0), value(&system, "angles", 1));
        system.stop();
        angles
    };
    let first = run();
    assert!(first.0.is_finite() && first.1.is_finite(), "{first:?}");
    assert_ne!(first, (0.3, 0.6), "the arm moved from q0");
    assert_eq!(first, run(), "two simulated runs agree sample for sample");
}

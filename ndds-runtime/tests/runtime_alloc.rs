//! Steady-state sampling allocates nothing: a counting global allocator counts allocations
//! made on the thread that runs the samples (the test thread for a manual habitat, the
//! habitat's own thread for a timer habitat) after a warm-up.

#[path = "../../ndds-client/tests/counting/mod.rs"]
mod counting;

#[path = "../../ndds-client/tests/common/mod.rs"]
mod common;

#[path = "../examples/arm_controller.rs"]
#[allow(dead_code)]
mod arm_controller;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use counting::{allocations, allocations_during, track, turn};
use ndds_client::{ConsumerQos, ProducerQos};
use ndds_components::{Gain, MassSpringDamper};
use ndds_runtime::{
    Clock, CsMat, HabitatOptions, RoutineResult, Runtime, SampleContext, SampleModule,
};

/// A chain of 50 gains, `c0 -> c1 -> ... -> c50`, installed in reverse so sorting matters.
fn fifty_gains(rt: &Runtime, habitat: &str) {
    rt.create_mat(CsMat::from_row_slice("c0", 1, 1, &[1.0]).unwrap())
        .unwrap();
    for i in (0..50).rev() {
        rt.install(habitat, &format!("gain{i}"), |b| {
            Gain::new(b, &format!("c{i}"), &format!("c{}", i + 1), 1.0)
        })
        .unwrap();
    }
}

/// The paper's PD/LQG system on the simulated arm.
fn arm(rt: &Runtime, habitat: &str, hz: f64) {
    rt.create_mat(CsMat::from_row_slice("reference", 1, 1, &[0.1]).unwrap())
        .unwrap();
    rt.install(habitat, "arm", |b| {
        MassSpringDamper::new(b, "force", "tip", "angle", arm_controller::ARM)
    })
    .unwrap();
    arm_controller::install_controller(rt, habitat, 1.0 / hz).unwrap();
}

#[test]
fn stepping_fifty_modules_and_the_pd_lqg_loop_allocates_nothing() {
    let _turn = turn();
    let rt = Runtime::new("alloc");
    rt.create_habitat("servo", HabitatOptions::rate(1000.0).clock(Clock::Manual))
        .unwrap();
    fifty_gains(&rt, "servo");
    arm(&rt, "servo", 1000.0);
    let servo = rt.habitat("servo");
    servo.start().unwrap();
    for configuration in ["JointPD", "endptLQG"] {
        rt.switch(configuration).unwrap();
        for _ in 0..100 {
            servo.step().unwrap();
        }
        let allocations = allocations_during(|| {
            for _ in 0..2000 {
                servo.step().unwrap();
            }
        });
        assert_eq!(allocations, 0, "{configuration}: 2000 samples allocated");
    }
    assert_eq!(rt.mat("c50").value(0, 0), 1.0, "the chain ran");
    assert!(
        (rt.mat("tip").value(0, 0) - 0.1).abs() < 0.01,
        "the loop ran"
    );
    assert_eq!(servo.stats().module_errors, 0);
}

/// Turns allocation tracking on for the habitat's own thread while `COUNTING` is set.
struct Tracker {
    counting: Arc<AtomicBool>,
}

impl SampleModule for Tracker {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let on = self.counting.load(Ordering::Relaxed);
        track(on);
        Ok(())
    }

    fn shutdown(&mut self, _: &SampleContext) -> RoutineResult {
        track(false);
        Ok(())
    }
}

#[test]
fn a_timer_habitat_samples_without_allocating() {
    let _turn = turn();
    let rt = Runtime::new("alloc-timer");
    let mut options = HabitatOptions::rate(1000.0);
    options.stats_interval = Duration::from_millis(100);
    rt.create_habitat("servo", options).unwrap();
    let counting = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&counting);
    rt.install("servo", "tracker", |_| Ok(Tracker { counting: flag }))
        .unwrap();
    fifty_gains(&rt, "servo");
    arm(&rt, "servo", 1000.0);
    let servo = rt.habitat("servo");
    servo.start().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let before = allocations();
    let samples_before = servo.stats().samples;
    counting.store(true, Ordering::Relaxed);
    std::thread::sleep(Duration::from_millis(1000));
    counting.store(false, Ordering::Relaxed);
    std::thread::sleep(Duration::from_millis(20));
    let allocations = allocations() - before;
    let samples = servo.stats().samples - samples_before;
    servo.stop();
    assert!(samples > 500, "only {samples} samples in 1 s");
    // The window includes about ten statistics hand-overs (every 100 ms).
    assert_eq!(
        allocations, 0,
        "{samples} samples on the habitat thread allocated"
    );
}

#[test]
fn csmats_bound_to_topics_publish_and_receive_without_allocating() {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let participant = common::participant(&common::unique_config(dir.path(), "alloc"));
    let rt = Runtime::with_participant("alloc-net", &participant).unwrap();
    rt.create_habitat("servo", HabitatOptions::rate(1000.0).clock(Clock::Manual))
        .unwrap();
    let out = CsMat::from_row_slice("out", 3, 2, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
        .unwrap()
        .with_row_fields([("x", "m"), ("y", "m"), ("z", "m")])
        .unwrap();
    rt.create_mat(out).unwrap();
    rt.install("servo", "scale", |b| Gain::new(b, "out", "sent", 2.0))
        .unwrap();
    rt.publish("servo", "sent", "alloc/mat", ProducerQos::default())
        .unwrap();
    let qos = ConsumerQos {
        depth: 4,
        ..ConsumerQos::default()
    };
    rt.subscribe("servo", "received", (3, 2), "alloc/mat", qos)
        .unwrap();
    let report = rt.verify();
    assert!(report.is_ok(), "{report}");
    let servo = rt.habitat("servo");
    servo.start().unwrap();
    assert!(common::eventually(Duration::from_secs(5), || {
        servo.step().unwrap();
        rt.mat("received").value(2, 1) == 12.0
    }));
    for _ in 0..200 {
        servo.step().unwrap();
        std::thread::sleep(Duration::from_micros(200));
    }
    let allocations = allocations_during(|| {
        for _ in 0..1000 {
            servo.step().unwrap();
            std::thread::sleep(Duration::from_micros(200));
        }
    });
    assert_eq!(rt.mat("received").value(2, 1), 12.0);
    assert_eq!(servo.stats().module_errors, 0);
    assert_eq!(
        allocations, 0,
        "1000 samples published and received allocated"
    );
}

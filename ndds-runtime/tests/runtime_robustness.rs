//! What a user or a peer can do wrong does not take a running system down: habitats that feed
//! each other do not deadlock, a panicking module is counted and sampling goes on (also in
//! the middle of a configuration switch), a peer cannot change a subscribed CSMat's shape, and
//! absurd rates and intervals are refused.

#[path = "../../ndds-client/tests/common/mod.rs"]
mod common;

use std::sync::mpsc;
use std::time::Duration;

use ndds_client::{ConsumerQos, ProducerQos};
use ndds_components::Gain;
use ndds_runtime::{
    Clock, CsMat, HabitatError, HabitatOptions, RoutineResult, Runtime, RuntimeError,
    SampleContext, SampleModule,
};

/// Runs `f` on another thread; panics if it has not finished within `limit` (a deadlock).
fn within<T: Send + 'static>(limit: Duration, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(limit)
        .expect("finished in time (no deadlock)")
}

#[test]
fn habitats_that_feed_each_other_do_not_deadlock() {
    let rt = Runtime::new("crossfeed");
    rt.create_habitat("h1", HabitatOptions::rate(2000.0))
        .unwrap();
    rt.create_habitat("h2", HabitatOptions::rate(2000.0))
        .unwrap();
    rt.create_mat(CsMat::from_row_slice("a", 4, 4, &[1.0; 16]).unwrap())
        .unwrap();
    // h1 reads a and writes b while h2 reads b and writes a: opposite lock orders if a
    // module held its input while taking its output.
    rt.install("h1", "forward", |b| Gain::new(b, "a", "b", 1.0))
        .unwrap();
    rt.install("h2", "back", |b| Gain::new(b, "b", "a", 1.0))
        .unwrap();
    rt.start_all().unwrap();
    std::thread::sleep(Duration::from_millis(800));
    let rt2 = rt.clone();
    let samples = within(Duration::from_secs(10), move || {
        let counts: Vec<u64> = ["h1", "h2"]
            .iter()
            .map(|h| rt2.habitat(h).stats().samples)
            .collect();
        rt2.stop_all();
        counts
    });
    assert!(samples.iter().all(|&n| n > 400), "{samples:?}");
}

/// Panics in `execute` on every third sample, and in `enable` when told to.
struct Faulty {
    samples: u64,
    panic_on_enable: bool,
}

impl SampleModule for Faulty {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        self.samples += 1;
        if self.samples.is_multiple_of(3) {
            panic!("sample {} went wrong", self.samples);
        }
        Ok(())
    }

    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        if self.panic_on_enable {
            panic!("cannot enable");
        }
        Ok(())
    }
}

#[test]
fn a_panicking_module_is_counted_and_sampling_goes_on() {
    let rt = Runtime::new("panics");
    rt.create_habitat("h", HabitatOptions::rate(1000.0).clock(Clock::Manual))
        .unwrap();
    rt.create_mat(CsMat::from_row_slice("x", 1, 1, &[2.0]).unwrap())
        .unwrap();
    rt.group("mode", "plain", &["double"]).unwrap();
    rt.group("mode", "faulty", &["faulty", "triple"]).unwrap();
    rt.configuration("bad", &[("mode", "faulty")]).unwrap();
    rt.install("h", "double", |b| Gain::new(b, "x", "y", 2.0))
        .unwrap();
    rt.install("h", "faulty", |_| {
        Ok(Faulty {
            samples: 0,
            panic_on_enable: true,
        })
    })
    .unwrap();
    rt.install("h", "triple", |b| Gain::new(b, "x", "z", 3.0))
        .unwrap();
    let h = rt.habitat("h");
    h.start().unwrap();
    h.step().unwrap();
    // The faulty module's enable panics during the switch: the switch still completes.
    rt.switch("bad").unwrap();
    assert_eq!(h.order(), ["faulty", "triple"]);
    assert_eq!(rt.current_configuration().as_deref(), Some("bad"));
    for _ in 0..9 {
        h.step().unwrap();
    }
    assert_eq!(rt.mat("z").value(0, 0), 6.0, "the other modules ran");
    // One panic in enable, three in execute (samples 3, 6, 9).
    assert_eq!(h.stats().module_errors, 4);
    assert_eq!(h.stats().samples, 10);

    // A timer habitat keeps sampling through the panics too.
    let rt = Runtime::new("panics-timer");
    rt.create_habitat("t", HabitatOptions::rate(1000.0))
        .unwrap();
    rt.install("t", "faulty", |_| {
        Ok(Faulty {
            samples: 0,
            panic_on_enable: false,
        })
    })
    .unwrap();
    let t = rt.habitat("t");
    t.start().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let stats = t.stats();
    t.stop();
    assert!(stats.running && stats.samples > 100, "{stats:?}");
    assert!(stats.module_errors >= stats.samples / 3 - 1, "{stats:?}");
}

#[test]
fn a_peer_cannot_change_the_shape_of_a_subscribed_csmat() {
    let dir = tempfile::tempdir().unwrap();
    let participant = common::participant(&common::unique_config(dir.path(), "shape"));
    let rt = Runtime::with_participant("shape", &participant).unwrap();
    rt.create_habitat("h", HabitatOptions::rate(1000.0).clock(Clock::Manual))
        .unwrap();
    rt.subscribe("h", "input", (2, 1), "shape/in", ConsumerQos::default())
        .unwrap();
    let h = rt.habitat("h");
    h.start().unwrap();
    let producer = participant
        .producer::<CsMat>("shape/in", ProducerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(1, Duration::from_secs(5)));

    let wrong = CsMat::from_row_slice("peer", 3, 4, &[7.0; 12]).unwrap();
    assert!(common::eventually(Duration::from_secs(5), || {
        producer.write(&wrong).unwrap();
        h.step().unwrap();
        h.stats().module_errors > 0
    }));
    assert_eq!(rt.mat("input").shape(), (2, 1), "the shape is kept");
    assert!(rt.verify().is_ok(), "{}", rt.verify());

    let right = CsMat::from_row_slice("peer", 2, 1, &[1.5, -1.5]).unwrap();
    assert!(common::eventually(Duration::from_secs(5), || {
        producer.write(&right).unwrap();
        h.step().unwrap();
        rt.mat("input").value(1, 0) == -1.5
    }));
}

#[test]
fn absurd_rates_and_intervals_are_refused() {
    let rt = Runtime::new("absurd");
    for hz in [1e-20, 1e-4, 0.0, f64::NAN, 1e7] {
        assert!(
            matches!(
                rt.create_habitat("h", HabitatOptions::rate(hz)),
                Err(RuntimeError::Habitat(HabitatError::InvalidRate { .. }))
            ),
            "{hz} Hz"
        );
    }
    for interval in [Duration::MAX, Duration::ZERO, Duration::from_millis(1)] {
        let mut options = HabitatOptions::rate(100.0);
        options.stats_interval = interval;
        assert!(
            matches!(
                rt.create_habitat("h", options),
                Err(RuntimeError::Habitat(
                    HabitatError::InvalidStatsInterval { .. }
                ))
            ),
            "{interval:?}"
        );
    }
    let h = rt
        .create_habitat("h", HabitatOptions::rate(1.0 / 3600.0).clock(Clock::Manual))
        .unwrap();
    for hz in [1e-20, 1e-11, 1e-19, f64::INFINITY, -1.0] {
        assert!(
            matches!(h.set_rate(hz), Err(HabitatError::InvalidRate { .. })),
            "{hz} Hz"
        );
    }
    h.start().unwrap();
    for _ in 0..3 {
        h.step().unwrap();
    }
    assert_eq!(h.stats().samples, 3);
}

/// Sleeps through every sample.
struct Sleepy(Duration);

impl SampleModule for Sleepy {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        std::thread::sleep(self.0);
        Ok(())
    }
}

#[test]
fn a_switch_waits_only_for_the_habitats_it_changes() {
    let rt = Runtime::new("busy");
    rt.create_habitat("fast", HabitatOptions::rate(1000.0))
        .unwrap();
    rt.create_habitat("slow", HabitatOptions::rate(1.0))
        .unwrap();
    rt.create_mat(CsMat::from_row_slice("x", 1, 1, &[1.0]).unwrap())
        .unwrap();
    rt.group("gain", "one", &["one"]).unwrap();
    rt.group("gain", "two", &["two"]).unwrap();
    rt.configuration("double", &[("gain", "two")]).unwrap();
    rt.install("fast", "one", |b| Gain::new(b, "x", "y", 1.0))
        .unwrap();
    rt.install("fast", "two", |b| Gain::new(b, "x", "y", 2.0))
        .unwrap();
    rt.install("slow", "sleepy", |_| Ok(Sleepy(Duration::from_secs(3))))
        .unwrap();
    rt.start_all().unwrap();
    std::thread::sleep(Duration::from_millis(300)); // the slow habitat is inside its sample
    let rt2 = rt.clone();
    let took = within(Duration::from_secs(10), move || {
        let started = std::time::Instant::now();
        rt2.switch("double").unwrap();
        started.elapsed()
    });
    assert!(
        took < Duration::from_millis(1500),
        "the switch waited {took:?} for a habitat it does not change"
    );
    assert!(common::eventually(Duration::from_secs(2), || rt
        .mat("y")
        .value(0, 0)
        == 2.0));
    within(Duration::from_secs(10), move || rt.stop_all());
}

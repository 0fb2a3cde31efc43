//! The ControlShell paper's configuration example (section 5) as a test: a "controllers"
//! category with groups "PD" (a low-pass filter and a PD controller) and "LQG" (a Kalman
//! estimator and LQR state feedback), a "sensors" category with "joint" and "endpoint", and the
//! configurations "JointPD" and "endptLQG", closing the loop on a simulated arm. Every entry
//! routine call is recorded, so the tests assert the exact call sequence of a switch.

#[path = "../examples/arm_controller.rs"]
#[allow(dead_code)]
mod arm_controller;

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use arm_controller::{ARM, position_only, weights};
use ndds_components::{Estimator, Gain, LowPass, MassSpringDamper, Pd, StateFeedback, design_lqg};
use ndds_runtime::{
    Binder, Clock, CsMat, HabitatOptions, ModuleError, RoutineResult, Runtime, SampleContext,
    SampleModule,
};

type Log = Arc<Mutex<Vec<(String, &'static str, u64)>>>;

/// Records every routine call of the module it wraps.
struct Recorded<M> {
    name: String,
    log: Log,
    inner: M,
}

impl<M> Recorded<M> {
    fn note(&self, routine: &'static str, ctx: &SampleContext) {
        self.log
            .lock()
            .unwrap()
            .push((self.name.clone(), routine, ctx.sample));
    }
}

macro_rules! recorded {
    ($($routine:ident),*) => {
        impl<M: SampleModule> SampleModule for Recorded<M> {
            $(fn $routine(&mut self, ctx: &SampleContext) -> RoutineResult {
                self.note(stringify!($routine), ctx);
                self.inner.$routine(ctx)
            })*
            fn terminate(&mut self) {
                self.log.lock().unwrap().push((self.name.clone(), "terminate", 0));
                self.inner.terminate();
            }
        }
    };
}
recorded!(
    execute,
    state_update,
    enable,
    disable,
    startup,
    shutdown,
    timing_changed,
    reset
);

fn add<M: SampleModule>(
    rt: &Runtime,
    log: &Log,
    name: &str,
    build: impl FnOnce(&mut Binder<'_>) -> Result<M, ModuleError>,
) {
    rt.install("servo", name, |b| {
        Ok(Recorded {
            name: name.to_owned(),
            log: log.clone(),
            inner: build(b)?,
        })
    })
    .unwrap();
}

const HZ: f64 = 200.0;

/// The paper's system in habitat "servo", configured as JointPD.
fn build(clock: Clock, hz: f64) -> (Runtime, Log) {
    let rt = Runtime::new("paper");
    let log: Log = Arc::default();
    rt.create_mat(CsMat::from_row_slice("reference", 1, 1, &[0.1]).unwrap())
        .unwrap();
    rt.create_habitat("servo", HabitatOptions::rate(hz).clock(clock))
        .unwrap();
    rt.group("sensors", "joint", &["joint_sensor"]).unwrap();
    rt.group("sensors", "endpoint", &["endpoint_sensor"])
        .unwrap();
    rt.group("controllers", "PD", &["pd_filter", "pd"]).unwrap();
    rt.group("controllers", "LQG", &["estimator", "lqr"])
        .unwrap();
    rt.configuration("JointPD", &[("sensors", "joint"), ("controllers", "PD")])
        .unwrap();
    rt.configuration(
        "endptLQG",
        &[("sensors", "endpoint"), ("controllers", "LQG")],
    )
    .unwrap();
    add(&rt, &log, "arm", |b| {
        MassSpringDamper::new(b, "force", "tip", "angle", ARM)
    });
    add(&rt, &log, "joint_sensor", |b| {
        Gain::new(b, "angle", "measured", ARM.length)
    });
    add(&rt, &log, "endpoint_sensor", |b| {
        Gain::new(b, "tip", "measured", 1.0)
    });
    add(&rt, &log, "pd_filter", |b| {
        LowPass::new(b, "measured", "filtered", 0.004)
    });
    add(&rt, &log, "pd", |b| {
        Pd::new(b, "filtered", "reference", "force", 400.0, 40.0)
    });
    let (a, b) = ARM.model();
    let lqg = design_lqg(&a, &b, &position_only(), 1.0 / hz, &weights()).unwrap();
    add(&rt, &log, "estimator", |bb| {
        Estimator::new(
            bb, "measured", "force", "estimate", &lqg.ad, &lqg.bd, &lqg.c, &lqg.l,
        )
    });
    add(&rt, &log, "lqr", |bb| {
        StateFeedback::new(bb, "estimate", "reference", "force", &lqg.k, &lqg.n)
    });
    rt.switch("JointPD").unwrap();
    let report = rt.verify();
    assert!(report.is_ok(), "{report}");
    (rt, log)
}

fn take(log: &Log) -> Vec<(String, &'static str, u64)> {
    std::mem::take(&mut *log.lock().unwrap())
}

fn calls(entries: &[(String, &'static str, u64)]) -> Vec<String> {
    entries.iter().map(|(m, r, _)| format!("{r} {m}")).collect()
}

fn strs(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| (*s).to_owned()).collect()
}

fn steps(rt: &Runtime, n: usize) {
    let servo = rt.habitat("servo");
    for _ in 0..n {
        servo.step().unwrap();
    }
}

#[test]
fn switching_configurations_calls_the_right_routines_at_a_sample_boundary() {
    let (rt, log) = build(Clock::Manual, HZ);
    let servo = rt.habitat("servo");
    assert_eq!(servo.order(), ["arm", "joint_sensor", "pd_filter", "pd"]);
    servo.start().unwrap();
    assert_eq!(
        calls(&take(&log)),
        strs(&[
            // startup: every installed module, in installation order ...
            "startup arm",
            "startup joint_sensor",
            "startup endpoint_sensor",
            "startup pd_filter",
            "startup pd",
            "startup estimator",
            "startup lqr",
            // ... then enable: the active set, in execution order.
            "enable arm",
            "enable joint_sensor",
            "enable pd_filter",
            "enable pd",
        ])
    );

    // JointPD closes the loop: PD leaves the steady-state error kp / (k + kp).
    steps(&rt, 600);
    let tip = rt.mat("tip").value(0, 0);
    let pd_final = 0.1 * 400.0 / (400.0 + ARM.stiffness);
    assert!((tip - pd_final).abs() < 0.002, "JointPD settles at {tip}");
    let one_sample = take(&log);
    assert_eq!(
        calls(&one_sample[one_sample.len() - 8..]),
        strs(&[
            "execute arm",
            "execute joint_sensor",
            "execute pd_filter",
            "execute pd",
            "state_update arm",
            "state_update joint_sensor",
            "state_update pd_filter",
            "state_update pd",
        ])
    );
    let force_before = rt.mat("force").value(0, 0);

    // The switch: entering modules enabled in the new order (prepared while the old set
    // samples), then leaving ones disabled in execution order after their last sample, all
    // between sample 599 and sample 600 (a manual habitat is stepped by this thread).
    rt.switch("endptLQG").unwrap();
    let switch = take(&log);
    assert_eq!(
        calls(&switch),
        strs(&[
            "enable endpoint_sensor",
            "enable estimator",
            "enable lqr",
            "disable joint_sensor",
            "disable pd_filter",
            "disable pd",
        ])
    );
    assert!(switch.iter().all(|(_, _, sample)| *sample == 600));
    assert_eq!(rt.current_configuration().as_deref(), Some("endptLQG"));
    assert_eq!(
        servo.order(),
        ["arm", "endpoint_sensor", "estimator", "lqr"]
    );

    // The very next sample runs the new set, and the force is the LQG law's.
    steps(&rt, 1);
    assert_eq!(
        calls(&take(&log)),
        strs(&[
            "execute arm",
            "execute endpoint_sensor",
            "execute estimator",
            "execute lqr",
            "state_update arm",
            "state_update endpoint_sensor",
            "state_update estimator",
            "state_update lqr",
        ])
    );
    let (k, n) = (rt.mat("lqr.K").snapshot(), rt.mat("lqr.N").snapshot());
    let estimate = rt.mat("estimate").snapshot();
    let expected = n.get(0, 0).unwrap() * 0.1
        - k.get(0, 0).unwrap() * estimate.get(0, 0).unwrap()
        - k.get(0, 1).unwrap() * estimate.get(1, 0).unwrap();
    let force_after = rt.mat("force").value(0, 0);
    assert!(
        (force_after - expected).abs() < 1e-9,
        "{force_after} vs {expected}"
    );
    // Bumpless: the estimator's enable read the outgoing sensor's measurement, so the first
    // LQG command is close to the last PD one (an estimator starting from zero would command
    // N·r, tens of newtons here).
    assert!(
        (estimate.get(0, 0).unwrap() - tip).abs() < 0.002,
        "estimate {estimate:?} starts at the measured {tip}"
    );
    assert!(
        (force_after - force_before).abs() < 2.0,
        "bump from {force_before} N to {force_after} N"
    );
    assert!(n.get(0, 0).unwrap() * 0.1 > 10.0, "N·r would be a bump");

    // LQG removes the steady-state error.
    steps(&rt, 600);
    let tip = rt.mat("tip").value(0, 0);
    assert!((tip - 0.1).abs() < 0.001, "endptLQG settles at {tip}");

    take(&log);
    rt.switch("JointPD").unwrap();
    assert_eq!(
        calls(&take(&log)),
        strs(&[
            "enable joint_sensor",
            "enable pd_filter",
            "enable pd",
            "disable endpoint_sensor",
            "disable estimator",
            "disable lqr",
        ])
    );

    servo.stop();
    assert_eq!(
        calls(&take(&log)),
        strs(&[
            "disable arm",
            "disable joint_sensor",
            "disable pd_filter",
            "disable pd",
            "shutdown arm",
            "shutdown joint_sensor",
            "shutdown endpoint_sensor",
            "shutdown pd_filter",
            "shutdown pd",
            "shutdown estimator",
            "shutdown lqr",
        ])
    );
    drop(servo);
    drop(rt);
    let terminated: BTreeSet<String> = take(&log)
        .into_iter()
        .filter(|(_, r, _)| *r == "terminate")
        .map(|(m, _, _)| m)
        .collect();
    assert_eq!(terminated.len(), 7, "{terminated:?}");
}

#[test]
fn switching_while_sampling_never_mixes_two_configurations_in_one_sample() {
    let hz = 500.0;
    let (rt, log) = build(Clock::Timer, hz);
    let servo = rt.habitat("servo");
    servo.start().unwrap();
    let configurations = ["endptLQG", "JointPD"];
    for round in 0..6 {
        std::thread::sleep(Duration::from_millis(150));
        rt.switch(configurations[round % 2]).unwrap();
    }
    std::thread::sleep(Duration::from_millis(1500));
    servo.stop();
    let entries = take(&log);

    let pd: BTreeSet<&str> = ["arm", "joint_sensor", "pd_filter", "pd"].into();
    let lqg: BTreeSet<&str> = ["arm", "endpoint_sensor", "estimator", "lqr"].into();
    let mut per_sample: std::collections::BTreeMap<u64, BTreeSet<&str>> = Default::default();
    for (module, routine, sample) in &entries {
        if *routine == "execute" {
            per_sample.entry(*sample).or_default().insert(module);
        }
    }
    assert!(per_sample.len() > 500, "{} samples", per_sample.len());
    let mut changes = 0;
    let mut previous: Option<&BTreeSet<&str>> = None;
    for (sample, set) in &per_sample {
        assert!(set == &pd || set == &lqg, "sample {sample} ran {set:?}");
        if previous.is_some_and(|p| p != set) {
            changes += 1;
        }
        previous = Some(set);
    }
    assert_eq!(changes, 6, "one change of active set per switch");
    // A module executes only while enabled: its `enable` (run off the habitat thread while
    // the old set samples) comes before its first sample, its `disable` after its last.
    let mut enabled: BTreeSet<&str> = BTreeSet::new();
    let mut enables = 0;
    for (module, routine, sample) in &entries {
        match *routine {
            "enable" => {
                assert!(enabled.insert(module.as_str()), "{module} enabled twice");
                enables += 1;
            }
            "disable" => {
                assert!(
                    enabled.remove(module.as_str()),
                    "{module} disabled while not enabled"
                );
            }
            "execute" => assert!(
                enabled.contains(module.as_str()),
                "{module} executed in sample {sample} while not enabled"
            ),
            _ => {}
        }
    }
    assert_eq!(
        enables,
        4 + 6 * 3,
        "the start's four, then three per switch"
    );
    // Ended in JointPD after 1.5 s: settled near the PD value.
    let tip = rt.mat("tip").value(0, 0);
    assert!((tip - 0.099).abs() < 0.005, "settled at {tip}");
}

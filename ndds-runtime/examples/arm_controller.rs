//! The controller half of the ControlShell paper's PD/LQG example, at 200 Hz: two sensor
//! groups ("joint": the lever angle, "endpoint": the tip position) and two controller groups
//! ("PD": a low-pass filter and a PD controller, "LQG": a Kalman estimator and LQR state
//! feedback), switched as the configurations "JointPD" and "endptLQG" — every 4 s here, or
//! from the network with `ndds pub cs/arm-controller/configure '"endptLQG"'`.
//!
//! ```text
//! cargo run -p ndds-runtime --example arm_plant &
//! cargo run -p ndds-runtime --example arm_controller [SECONDS]
//! ```

use std::time::{Duration, Instant};

use nalgebra::{DMatrix, DVector};
use ndds_client::{ConsumerQos, Participant, ProducerQos};
use ndds_components::{
    Estimator, Gain, LowPass, LqgWeights, Pd, Physical, StateFeedback, design_lqg,
};
use ndds_runtime::{CsMat, HabitatOptions, Runtime, RuntimeError};

const HZ: f64 = 200.0;

/// Installs the sensors, both controllers, their groups and the two configurations in
/// `habitat`: reads CSMats `tip` and `angle`, writes `force`, tracks `reference`.
pub fn install_controller(rt: &Runtime, habitat: &str, dt: f64) -> Result<(), RuntimeError> {
    // Groups first: a module installed into an inactive group never conflicts with the
    // active one writing the same CSMat.
    rt.group("sensors", "joint", &["joint_sensor"])?;
    rt.group("sensors", "endpoint", &["endpoint_sensor"])?;
    rt.group("controllers", "PD", &["pd_filter", "pd"])?;
    rt.group("controllers", "LQG", &["estimator", "lqr"])?;
    rt.configuration("JointPD", &[("sensors", "joint"), ("controllers", "PD")])?;
    rt.configuration(
        "endptLQG",
        &[("sensors", "endpoint"), ("controllers", "LQG")],
    )?;

    rt.install(habitat, "joint_sensor", |b| {
        Gain::new(b, "angle", "measured", 0.5)
    })?;
    rt.install(habitat, "endpoint_sensor", |b| {
        Gain::new(b, "tip", "measured", 1.0)
    })?;
    rt.install(habitat, "pd_filter", |b| {
        LowPass::new(b, "measured", "filtered", 0.004)
    })?;
    rt.install(habitat, "pd", |b| {
        Pd::new(b, "filtered", "reference", "force", 400.0, 40.0)
    })?;

    // LQG designed on the plant's model (1 kg, 4 N/m, 0.4 N·s/m), discretised at dt.
    let (a, b) = ARM.model();
    let lqg = design_lqg(&a, &b, &position_only(), dt, &weights())
        .expect("the arm is controllable and observable");
    rt.install(habitat, "estimator", |b| {
        Estimator::new(
            b, "measured", "force", "estimate", &lqg.ad, &lqg.bd, &lqg.c, &lqg.l,
        )
    })?;
    rt.install(habitat, "lqr", |b| {
        StateFeedback::new(b, "estimate", "reference", "force", &lqg.k, &lqg.n)
    })?;
    rt.switch("JointPD")
}

/// The arm's model, as the plant example simulates it.
pub const ARM: Physical = Physical {
    mass: 1.0,
    stiffness: 4.0,
    damping: 0.4,
    length: 0.5,
};

/// Only the position is measured.
pub fn position_only() -> DMatrix<f64> {
    DMatrix::from_row_slice(1, 2, &[1.0, 0.0])
}

/// LQG weights: stiff on position, light on force; a precise position sensor.
pub fn weights() -> LqgWeights {
    let diag = |v: &[f64]| DMatrix::from_diagonal(&DVector::from_row_slice(v));
    LqgWeights {
        q: diag(&[4000.0, 10.0]),
        r: diag(&[0.01]),
        process_noise: diag(&[1e-6, 1e-4]),
        measurement_noise: diag(&[1e-6]),
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    tracing_subscriber::fmt().with_env_filter("info").init();
    let seconds: Option<f64> = std::env::args().nth(1).map(|s| s.parse()).transpose()?;
    let rt = Runtime::with_participant("arm-controller", &Participant::connect()?)?;
    rt.create_habitat("control", HabitatOptions::rate(HZ))?;
    rt.subscribe("control", "tip", (1, 1), "arm/tip", ConsumerQos::default())?;
    rt.subscribe(
        "control",
        "angle",
        (1, 1),
        "arm/angle",
        ConsumerQos::default(),
    )?;
    rt.create_mat(CsMat::from_row_slice("reference", 1, 1, &[0.1])?)?;
    install_controller(&rt, "control", 1.0 / HZ)?;
    rt.publish("control", "force", "arm/force", ProducerQos::default())?;
    rt.start_all()?;
    let (start, mut last_switch) = (Instant::now(), Instant::now());
    while seconds.is_none_or(|s| start.elapsed().as_secs_f64() < s) {
        std::thread::sleep(Duration::from_millis(250));
        if seconds.is_none() && last_switch.elapsed() > Duration::from_secs(4) {
            let next = match rt.current_configuration().as_deref() {
                Some("JointPD") => "endptLQG",
                _ => "JointPD",
            };
            rt.switch(next)?;
            last_switch = Instant::now();
        }
        let tip = rt.mat("measured").value(0, 0);
        let force = rt.mat("force").value(0, 0);
        let config = rt.current_configuration().unwrap_or_default();
        println!("{config:>9}  measured {tip:+.4} m  force {force:+8.3} N");
    }
    rt.stop_all();
    Ok(())
}

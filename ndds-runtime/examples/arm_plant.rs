//! The plant half of the ControlShell paper's PD/LQG example: a simulated mass on a spring,
//! sampled at 500 Hz, publishing its position (`arm/tip`) and lever angle (`arm/angle`) and
//! taking its force from `arm/force`. Run `arm_controller` next to it (same host or another).
//!
//! ```text
//! cargo run -p ndds-runtime --example arm_plant [SECONDS]
//! ```

use std::time::Duration;

use ndds_client::{ConsumerQos, Participant, ProducerQos};
use ndds_components::{MassSpringDamper, Physical};
use ndds_runtime::{HabitatOptions, Runtime};

/// The arm: 1 kg on 4 N/m with 0.4 N·s/m of damping, read through a 0.5 m lever.
pub const ARM: Physical = Physical {
    mass: 1.0,
    stiffness: 4.0,
    damping: 0.4,
    length: 0.5,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    tracing_subscriber::fmt().with_env_filter("info").init();
    let seconds: Option<f64> = std::env::args().nth(1).map(|s| s.parse()).transpose()?;
    let rt = Runtime::with_participant("arm-plant", &Participant::connect()?)?;
    rt.create_habitat("plant", HabitatOptions::rate(500.0))?;
    rt.subscribe(
        "plant",
        "force",
        (1, 1),
        "arm/force",
        ConsumerQos::default(),
    )?;
    rt.install("plant", "arm", |b| {
        MassSpringDamper::new(b, "force", "tip", "angle", ARM)
    })?;
    rt.publish("plant", "tip", "arm/tip", ProducerQos::default())?;
    rt.publish("plant", "angle", "arm/angle", ProducerQos::default())?;
    rt.start_all()?;
    println!("arm-plant: sampling at 500 Hz; stats on cs/arm-plant/plant/stats");
    let start = std::time::Instant::now();
    while seconds.is_none_or(|s| start.elapsed().as_secs_f64() < s) {
        std::thread::sleep(Duration::from_millis(100));
    }
    rt.stop_all();
    Ok(())
}

//! The PD/LQG controller of `arm_controller` under a state machine (`arm_supervisor.toml`)
//! instead of a timer: stimuli sent from any process switch its configurations.
//!
//! ```text
//! cargo run -p ndds-runtime --example arm_plant &
//! cargo run -p ndds-runtime --example arm_supervised &
//! cargo run -p ndds-cli -- fsm send arm Object=Visible Precise
//! cargo run -p ndds-cli -- fsm show arm
//! ```

#[path = "arm_controller.rs"]
#[allow(dead_code)]
mod arm_controller;

use std::time::{Duration, Instant};

use ndds_client::{ConsumerQos, Participant, ProducerQos};
use ndds_runtime::fsm::{ActionSet, Program, StateMachine};
use ndds_runtime::{CsMat, HabitatOptions, Runtime};

/// The state program.
pub const SUPERVISOR: &str = include_str!("arm_supervisor.toml");

fn main() -> Result<(), Box<dyn std::error::Error>> {
    tracing_subscriber::fmt().with_env_filter("info").init();
    let seconds: Option<f64> = std::env::args().nth(1).map(|s| s.parse()).transpose()?;
    let participant = Participant::connect()?;
    let rt = Runtime::with_participant("arm-controller", &participant)?;
    rt.create_habitat("control", HabitatOptions::rate(200.0))?;
    let latest = ConsumerQos::default;
    rt.subscribe("control", "tip", (1, 1), "arm/tip", latest())?;
    rt.subscribe("control", "angle", (1, 1), "arm/angle", latest())?;
    rt.create_mat(CsMat::from_row_slice("reference", 1, 1, &[0.1])?)?;
    arm_controller::install_controller(&rt, "control", 1.0 / 200.0)?;
    rt.publish("control", "force", "arm/force", ProducerQos::default())?;
    rt.start_all()?;
    let program = Program::from_toml(SUPERVISOR)?;
    let fsm = StateMachine::start_on(program, ActionSet::runtime(&rt), &participant)?;
    let start = Instant::now();
    while seconds.is_none_or(|s| start.elapsed().as_secs_f64() < s) {
        std::thread::sleep(Duration::from_millis(500));
        let state = fsm.snapshot();
        let config = rt.current_configuration().unwrap_or_default();
        let tip = rt.mat("measured").value(0, 0);
        println!("{:>9}  {config:>9}  measured {tip:+.4} m", state.state);
    }
    rt.stop_all();
    Ok(())
}

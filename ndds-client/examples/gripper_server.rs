//! The owner side of the ports example: a gripper driver that owns port `gripper` (commands:
//! `send` / `receive` / `reply`, replies given when the motion is done) and answers queries on
//! `gripper.status` with a response handler. Run `gripper_client` next to it.
//!
//! ```text
//! cargo run -p ndds-client --example gripper_server [SECONDS] &
//! cargo run -p ndds-client --example gripper_client
//! ```

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ndds_client::Participant;
use ndds_client::ports::{PortError, PortOwner, Responder, Restrictions, Usage};
use serde::{Deserialize, Serialize};

/// A command to the gripper.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Command {
    /// Open to this width (m).
    Open(f64),
    /// Close until this force (N).
    Close(f64),
    /// Hold still for this many seconds, then reply.
    Hold(f64),
}

/// What the gripper reports.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// Current width (m).
    pub width: f64,
    /// Commands done so far.
    pub done: u32,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seconds: Option<f64> = std::env::args().nth(1).map(|s| s.parse()).transpose()?;
    let participant = Participant::connect()?;
    let status = Arc::new(Mutex::new(Status {
        width: 0.08,
        done: 0,
    }));
    // The owner receives (and replies): its users may only send.
    let restrictions = Restrictions {
        usages: vec![Usage::Receive],
        timeout_ms: Some(5_000),
        ..Restrictions::default()
    };
    let commands = PortOwner::<Command, Status>::declare_with(
        &participant,
        "gripper",
        "driver",
        restrictions,
    )?;
    let mut responder = Responder::new(&participant, "driver")?;
    let shared = Arc::clone(&status);
    responder.handle("gripper.status", 5, move |_: ()| {
        shared.lock().unwrap_or_else(|p| p.into_inner()).clone()
    })?;
    println!("gripper_server: owns `gripper` and answers `gripper.status`");
    let start = Instant::now();
    while seconds.is_none_or(|s| start.elapsed().as_secs_f64() < s) {
        let (command, reply) = match commands.receive(Duration::from_millis(200)) {
            Ok(request) => request,
            Err(PortError::Timeout { .. }) => continue,
            Err(err) => return Err(err.into()),
        };
        std::thread::sleep(Duration::from_millis(20)); // the motion
        if let Command::Hold(seconds) = command {
            std::thread::sleep(Duration::from_secs_f64(seconds.clamp(0.0, 3600.0)));
        }
        let mut s = status.lock().unwrap_or_else(|p| p.into_inner());
        s.width = match command {
            Command::Open(width) => width,
            Command::Close(_) => 0.0,
            Command::Hold(_) => s.width,
        };
        s.done += 1;
        println!(
            "{} asked {command:?}: width now {:.3} m",
            reply.sender(),
            s.width
        );
        reply.reply(&s)?;
    }
    Ok(())
}

//! The user side of the ports example: sends commands to the `gripper` port (each `send`
//! blocks until the driver replies) and queries `gripper.status`.
//!
//! ```text
//! cargo run -p ndds-client --example gripper_server &
//! cargo run -p ndds-client --example gripper_client [TASK]
//! ```

#[path = "gripper_server.rs"]
#[allow(dead_code)]
mod gripper_server;

use std::time::Duration;

use gripper_server::{Command, Status};
use ndds_client::Participant;
use ndds_client::ports::{PortUser, Usage};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let task = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "picker".to_owned());
    let participant = Participant::connect()?;
    let gripper = PortUser::<Command, Status>::declare(&participant, "gripper", &task)?;
    let status = PortUser::<(), Status>::declare_with(
        &participant,
        "gripper.status",
        &task,
        &[Usage::Query],
    )?;
    let wait = Duration::from_secs(5);
    for command in [
        Command::Open(0.06),
        Command::Close(15.0),
        Command::Open(0.08),
    ] {
        let done = gripper.send(&command, wait)?;
        println!("{task}: {command:?} done, width {:.3} m", done.width);
    }
    let now = status.query(&(), wait)?;
    println!("{task}: status {now:?}");
    Ok(())
}

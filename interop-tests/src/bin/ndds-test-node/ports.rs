//! Port roles of the test node: `own` (receive N requests, then reply to them in reverse
//! order), `send` (one request, print the reply) and `waitfor` (rounds of a rendezvous).

use std::time::Duration;

use ndds_client::Participant;
use ndds_client::ports::{PortOwner, PortUser, Rendezvous};
use serde_json::json;

use crate::report::emit;

/// Options of the port roles.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The port (or rendezvous) name.
    #[arg(long)]
    pub port: String,
    /// This task's name.
    #[arg(long)]
    pub task: String,
    /// `own`: requests to take before replying (in reverse order).
    #[arg(long, default_value_t = 1)]
    pub hold: usize,
    /// `send`: the value to send; `waitfor`: this task's base value.
    #[arg(long, default_value_t = 0)]
    pub value: u64,
    /// `waitfor`: every task of the rendezvous, comma-separated.
    #[arg(long, default_value = "")]
    pub tasks: String,
    /// `waitfor`: rounds.
    #[arg(long, default_value_t = 1)]
    pub rounds: u64,
    /// Seconds any single operation may take.
    #[arg(long, default_value_t = 20.0)]
    pub timeout: f64,
}

/// Which port role.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Mode {
    /// Own the port.
    Own,
    /// Send one request.
    Send,
    /// Take part in a rendezvous.
    Waitfor,
}

/// Runs a port role.
pub fn run(participant: &Participant, mode: Mode, args: &Args) -> anyhow::Result<()> {
    let timeout = Duration::from_secs_f64(args.timeout);
    match mode {
        Mode::Own => {
            let owner = PortOwner::<u64, String>::declare(participant, &args.port, &args.task)?;
            emit(json!({"event": "ready", "pid": std::process::id()}));
            let mut held = Vec::new();
            for _ in 0..args.hold {
                let (value, reply) = owner.receive(timeout)?;
                emit(json!({"event": "received", "value": value, "from": reply.sender()}));
                held.push((value, reply));
            }
            for (value, reply) in held.into_iter().rev() {
                let sender = reply.sender().to_owned();
                reply.reply(&format!("{} got {value} from {}", sender, args.task))?;
                emit(json!({"event": "replied", "to": sender}));
            }
            // Stay until the replies are delivered (reliable stream).
            std::thread::sleep(Duration::from_millis(500));
        }
        Mode::Send => {
            let user = PortUser::<u64, String>::declare(participant, &args.port, &args.task)?;
            emit(json!({"event": "ready", "pid": std::process::id()}));
            let reply = user.send(&args.value, timeout)?;
            emit(json!({"event": "reply", "reply": reply}));
        }
        Mode::Waitfor => {
            let tasks: Vec<&str> = args.tasks.split(',').filter(|t| !t.is_empty()).collect();
            let rv = Rendezvous::<u64>::join(participant, &args.port, &args.task, &tasks)?;
            emit(json!({"event": "ready", "pid": std::process::id()}));
            for round in 0..args.rounds {
                let combined = rv.wait(&(args.value + round), timeout, |all| {
                    all.iter()
                        .map(|(t, v)| format!("{t}={v}"))
                        .collect::<Vec<_>>()
                        .join(",")
                })?;
                emit(json!({"event": "combined", "round": round, "all": combined}));
            }
        }
    }
    emit(json!({"event": "done"}));
    Ok(())
}

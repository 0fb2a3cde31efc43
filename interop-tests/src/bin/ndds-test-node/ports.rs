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
    /// Answer queries with a response handler (value × 2) for `--timeout` seconds.
    Respond,
    /// Query once, print the response.
    Query,
    /// Own the port and `sendall` `--value` once `--hold` users are matched.
    Sendall,
    /// Answer one message sent to all users.
    ReceiveAll,
    /// Own `<port>.low` (priority 0) and `<port>.high` (priority 5); once `--hold` requests
    /// wait in all, serve them in `select` order.
    Select,
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
        Mode::Respond => {
            let mut responder = ndds_client::ports::Responder::new(participant, &args.task)?;
            responder.handle(&args.port, 0, |n: u64| n * 2)?;
            emit(json!({"event": "ready", "pid": std::process::id()}));
            std::thread::sleep(timeout);
        }
        Mode::Query => {
            let user = PortUser::<u64, u64>::declare_with(
                participant,
                &args.port,
                &args.task,
                &[ndds_client::ports::Usage::Query],
            )?;
            emit(json!({"event": "ready", "pid": std::process::id()}));
            let response = user.query(&args.value, timeout)?;
            emit(json!({"event": "response", "response": response}));
        }
        Mode::Sendall => {
            let owner = PortOwner::<u64, String>::declare(participant, &args.port, &args.task)?;
            emit(json!({"event": "ready", "pid": std::process::id()}));
            let deadline = std::time::Instant::now() + timeout;
            while owner.users() < args.hold && std::time::Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(10));
            }
            let replies = owner.sendall(&args.value, timeout)?;
            let mut all = vec![replies.first().0.clone()];
            while all.len() < args.hold {
                match replies.next(timeout) {
                    Some(reply) => all.push(reply?.0),
                    None => break,
                }
            }
            all.sort();
            emit(json!({"event": "replies", "from": all}));
        }
        Mode::ReceiveAll => {
            let user = PortUser::<u64, String>::declare_with(
                participant,
                &args.port,
                &args.task,
                &[ndds_client::ports::Usage::ReceiveAll],
            )?;
            emit(json!({"event": "ready", "pid": std::process::id()}));
            let task = args.task.clone();
            let value = user.receive_all(timeout, move |v| format!("{task} saw {v}"))?;
            emit(json!({"event": "received", "value": value}));
            std::thread::sleep(Duration::from_millis(500));
        }
        Mode::Select => {
            use ndds_client::ports::{Selectable, select};
            let low = PortOwner::<u64, String>::declare(
                participant,
                &format!("{}.low", args.port),
                &args.task,
            )?;
            let high = PortOwner::<u64, String>::declare(
                participant,
                &format!("{}.high", args.port),
                &args.task,
            )?;
            high.set_priority(5);
            emit(json!({"event": "ready", "pid": std::process::id()}));
            let ports: [&dyn Selectable; 2] = [&low, &high];
            let deadline = std::time::Instant::now() + timeout;
            while ports.iter().map(|p| p.waiting()).sum::<usize>() < args.hold
                && std::time::Instant::now() < deadline
            {
                std::thread::sleep(Duration::from_millis(5));
            }
            for _ in 0..args.hold {
                let index = select(&ports, timeout)?;
                let (value, reply) = if index == 0 {
                    low.receive(timeout)?
                } else {
                    high.receive(timeout)?
                };
                emit(json!({"event": "served", "port": ports[index].port(), "value": value}));
                reply.reply(&format!("served {value}"))?;
            }
            std::thread::sleep(Duration::from_millis(500));
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

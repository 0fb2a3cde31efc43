//! A Rust program with a `Pose` type, for trying Rust and Python (`ndds-python`) on one topic:
//! the Python suite declares a dataclass `Pose` of the same shape and talks to this program
//! both ways.
//!
//! ```text
//! pose_peer publish TOPIC COUNT        write COUNT poses (i = 0..COUNT) once a consumer matched
//! pose_peer echo IN OUT COUNT          take COUNT poses from IN, write each to OUT with x + 1
//! pose_peer owner PORT COUNT           own PORT (Pose -> f64, the reply is x + y), serve COUNT
//! pose_peer user PORT                  send Pose{x: 2, y: 3, ...} to PORT, print the reply
//! ```
//!
//! It connects as any client does (`NDDS_DOMAIN`, `NDDS_SOCKET`), prints `ready` when its
//! endpoints are declared, and one line per sample or reply.

use std::time::Duration;

use ndds_client::ports::{PortOwner, PortUser};
use ndds_client::{ConsumerQos, Participant, ProducerQos, Reliability, TypeDescription};
use serde::{Deserialize, Serialize};

/// A robot mode: a unit-variant enum (Python: an `enum.Enum` with the same member names).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
enum Mode {
    Idle,
    Moving,
    Fault,
}

/// The Python suite's `Pose` has these fields, in this order, with these types.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
struct Pose {
    x: f64,
    y: f64,
    theta: f32,
    frame: String,
    seq: u32,
    tags: Vec<String>,
    covariance: Option<[f64; 3]>,
    mode: Mode,
}

fn pose(i: u32) -> Pose {
    let even = i.is_multiple_of(2);
    Pose {
        x: f64::from(i),
        y: -f64::from(i),
        theta: 0.5,
        frame: "map".to_owned(),
        seq: i,
        tags: vec!["rust".to_owned()],
        covariance: even.then_some([0.1, 0.2, 0.3]),
        mode: if even { Mode::Moving } else { Mode::Idle },
    }
}

fn reliable() -> Reliability {
    Reliability::Reliable { depth: 256 }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let participant = Participant::builder().name("pose_peer").connect()?;
    let timeout = Duration::from_secs(20);
    match args.as_slice() {
        ["fingerprint"] => {
            let desc = TypeDescription::of::<Pose>();
            println!("{:016x} {}", desc.fingerprint(), desc.canonical_text());
        }
        ["publish", topic, count] => {
            let count: u32 = count.parse()?;
            let qos = ProducerQos {
                reliability: reliable(),
                ..ProducerQos::default()
            };
            let producer = participant.producer::<Pose>(topic, qos)?;
            println!("ready");
            if !producer.wait_for_consumers(1, timeout) {
                return Err("no consumer matched".into());
            }
            for i in 0..count {
                producer.write(&pose(i))?;
            }
            producer.wait_for_acknowledgments(timeout);
            println!("published {count}");
        }
        ["echo", input, output, count] => {
            let count: u32 = count.parse()?;
            let consumer = participant.consumer::<Pose>(
                input,
                ConsumerQos {
                    reliability: reliable(),
                    ..ConsumerQos::default()
                },
            )?;
            let producer = participant.producer::<Pose>(
                output,
                ProducerQos {
                    reliability: reliable(),
                    ..ProducerQos::default()
                },
            )?;
            println!("ready");
            for _ in 0..count {
                let mut sample = consumer.recv_timeout(timeout)?.value;
                println!("got {sample:?}");
                sample.x += 1.0;
                producer.write(&sample)?;
            }
            producer.wait_for_acknowledgments(timeout);
        }
        ["owner", port, count] => {
            let count: u32 = count.parse()?;
            let owner = PortOwner::<Pose, f64>::declare(&participant, port, "rust_owner")?;
            println!("ready");
            for _ in 0..count {
                let (request, reply) = owner.receive(timeout)?;
                println!("request {request:?} from {}", reply.sender());
                reply.reply(&(request.x + request.y))?;
            }
            // Let the last reply reach its sender before the owner goes.
            std::thread::sleep(Duration::from_millis(500));
        }
        ["user", port] => {
            let user = PortUser::<Pose, f64>::declare(&participant, port, "rust_user")?;
            println!("ready");
            let mut request = pose(2);
            request.y = 3.0;
            let reply = user.send(&request, timeout)?;
            println!("reply {reply}");
        }
        _ => {
            return Err(
                "usage: pose_peer fingerprint | publish TOPIC COUNT | echo IN OUT COUNT | \
                 owner PORT COUNT | user PORT"
                    .into(),
            );
        }
    }
    Ok(())
}

//! Ports between processes under two daemons on loopback: the `gripper_server` example owns
//! the ports, two `gripper_client` processes use them at once, and the test process itself is
//! a third user whose sends must time out when the owner is killed mid-operation.

use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use interop_tests::{TestDomain, binary};
use ndds_client::ports::{PortError, PortUser};
use ndds_client::{EmbeddedPolicy, Participant};
use serde::{Deserialize, Serialize};

/// The example's command type, as the test speaks it (same layout, so same fingerprint).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename = "Command")]
enum GripperCommand {
    Open(f64),
    Close(f64),
    Hold(f64),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename = "Status")]
struct Status {
    width: f64,
    done: u32,
}

struct Program(Child);

impl Drop for Program {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn spawn(domain: &TestDomain, daemon: &str, name: &str, args: &[&str]) -> Child {
    Command::new(binary(name))
        .args(args)
        .env("NDDS_SOCKET", domain.socket(daemon))
        .env("NDDS_EMBEDDED", "never")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start the example program")
}

#[test]
fn clients_in_two_processes_use_a_server_in_a_third_and_time_out_when_it_dies() {
    let domain = TestDomain::new();
    let _a = domain.daemon("server-host");
    let _b = domain.daemon("client-host");
    let mut server = Program(spawn(&domain, "server-host", "gripper_server", &["60"]));

    // Two client processes at once: each gets its own replies.
    let clients: Vec<Child> = ["picker", "placer"]
        .iter()
        .map(|task| spawn(&domain, "client-host", "gripper_client", &[task]))
        .collect();
    for (client, task) in clients.into_iter().zip(["picker", "placer"]) {
        let out = client.wait_with_output().unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{task}: {text}");
        for line in [
            format!("{task}: Open(0.06) done, width 0.060 m"),
            format!("{task}: Close(15.0) done, width 0.000 m"),
            format!("{task}: Open(0.08) done, width 0.080 m"),
        ] {
            assert!(text.contains(&line), "{line} in {text}");
        }
        assert!(text.contains(&format!("{task}: status Status")), "{text}");
    }

    // The test process as a third user: two sends block on a long Hold; the owner is
    // killed; each send fails with the timeout, named, within its bound.
    let me = Participant::builder()
        .socket(domain.socket("client-host"))
        .embedded(EmbeddedPolicy::Never)
        .name("operator")
        .connect()
        .unwrap();
    let user =
        Arc::new(PortUser::<GripperCommand, Status>::declare(&me, "gripper", "operator").unwrap());
    let senders: Vec<_> = (0..2)
        .map(|_| {
            let user = Arc::clone(&user);
            std::thread::spawn(move || {
                let started = Instant::now();
                (
                    user.send(&GripperCommand::Hold(60.0), Duration::from_secs(3)),
                    started.elapsed(),
                )
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(1000));
    server.0.kill().unwrap();
    for sender in senders {
        let (result, took) = sender.join().unwrap();
        match result {
            Err(PortError::Timeout { port, owner, .. }) => {
                assert_eq!(port, "gripper");
                assert_eq!(owner.as_deref(), Some("driver"));
            }
            other => panic!("expected a timeout, got {other:?}"),
        }
        assert!(
            took < Duration::from_secs(6),
            "bounded by the timeout: {took:?}"
        );
    }
}

//! Shared by the tests that run the SDK's example programs (`runtime_*.rs`): starting one
//! under a test daemon, and waiting for the simulated arm to settle.

#![allow(dead_code)]

use std::process::{Child, Command, Stdio};
use std::time::Duration;

use interop_tests::{TestDomain, binary, wait_until};
use ndds_client::Consumer;
use ndds_runtime::CsMat;

/// How long an example may take to reach a state.
pub const WAIT: Duration = Duration::from_secs(15);

/// An example program, killed when the test ends, however it ends.
pub struct Program(pub Child);

impl Drop for Program {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts example binary `name` (for at most 60 s) under the daemon called `daemon`.
pub fn program(domain: &TestDomain, daemon: &str, name: &str) -> Program {
    let child = Command::new(binary(name))
        .arg("60")
        .env("NDDS_SOCKET", domain.socket(daemon))
        .env("NDDS_EMBEDDED", "never")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start the example program");
    Program(child)
}

/// Waits until the last 100 tip positions received are all within `tolerance` of `target`.
pub fn settles(tips: &Consumer<CsMat>, target: f64, tolerance: f64) -> bool {
    let mut inside = 0;
    wait_until(WAIT, || {
        while let Ok(sample) = tips.try_recv() {
            let tip = sample.value.get(0, 0).unwrap_or(f64::NAN);
            inside = if (tip - target).abs() < tolerance {
                inside + 1
            } else {
                0
            };
        }
        inside >= 100
    })
    .is_some()
}

//! `ndds run` on two simulated hosts (network namespaces; needs root, `ip` and `nft`): the
//! plant half of the PD/LQG example on one host, the controller half on the other, each a
//! plain `ndds run FILE` against its host's daemon. They form one system: the supervisor
//! switches to endptLQG, the tip reaches the endpoint goal, `ndds topics` and `ndds echo` on
//! either host see it, and Ctrl-C stops each half cleanly.

mod support;

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::Duration;

use interop_tests::netns::Cluster;
use interop_tests::{binary, wait_until};
use ndds_client::ConsumerQos;
use ndds_runtime::CsMat;
use ndds_runtime::fsm::MachineState;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use support::exclusive;

const WAIT: Duration = Duration::from_secs(30);

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name)
}

/// `ndds run FILE` on `host`, its output in `log`; killed when dropped.
struct Run {
    child: Child,
    log: PathBuf,
}

impl Run {
    fn start(cluster: &Cluster, host: usize, file: &str, log: PathBuf) -> Self {
        let out = std::fs::File::create(&log).unwrap();
        let child = cluster
            .host(host)
            .exec(binary("ndds"))
            .arg("--socket")
            .arg(cluster.socket(host))
            .args(["run", "--no-embedded", "--plain", "--seconds", "120"])
            .arg(example(file))
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(Stdio::inherit())
            .spawn()
            .expect("ndds run starts");
        Self { child, log }
    }

    fn output(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Ctrl-C, then the exit status and everything it printed.
    fn interrupt(mut self) -> (bool, String) {
        kill(Pid::from_raw(self.child.id() as i32), Signal::SIGINT).unwrap();
        let exited = wait_until(WAIT, || matches!(self.child.try_wait(), Ok(Some(_))));
        assert!(
            exited.is_some(),
            "ndds run ignored Ctrl-C:\n{}",
            self.output()
        );
        let ok = self.child.wait().unwrap().success();
        (ok, self.output())
    }
}

impl Drop for Run {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn plant_and_controller_on_two_hosts_form_one_system() {
    if support::skipped() {
        return;
    }
    let _turn = exclusive();
    let cluster = Cluster::new(2);
    let logs = tempfile::tempdir().unwrap();
    let plant = Run::start(&cluster, 0, "arm/plant.toml", logs.path().join("plant.log"));
    let controller = Run::start(
        &cluster,
        1,
        "arm/controller.toml",
        logs.path().join("controller.log"),
    );

    // Watched from the plant's host: the supervisor on the other host reaches Endpoint, and
    // the tip settles at the endpoint goal.
    let tool = cluster.tool(0);
    let states = tool
        .consumer::<MachineState>("fsm/arm/state", ConsumerQos::default())
        .unwrap();
    let tips = tool
        .consumer::<CsMat>("arm/endpoint", ConsumerQos::default())
        .unwrap();
    let endpoint = wait_until(WAIT, || {
        std::iter::from_fn(|| states.try_recv().ok()).any(|s| s.value.state == "Endpoint")
    });
    assert!(
        endpoint.is_some(),
        "the supervisor never switched to endpoint control\nplant:\n{}\ncontroller:\n{}",
        plant.output(),
        controller.output()
    );
    let mut inside = 0;
    let settled = wait_until(WAIT, || {
        while let Ok(tip) = tips.try_recv() {
            let (x, y) = (tip.value.get(0, 0).unwrap(), tip.value.get(1, 0).unwrap());
            let close = (x - 0.91).abs() < 1e-3 && (y - 1.30).abs() < 1e-3;
            inside = if close { inside + 1 } else { 0 };
        }
        inside >= 200
    });
    assert!(settled.is_some(), "the tip never settled at (0.91, 1.30)");

    // Both hosts' tools see both ends of the topics.
    for host in [0, 1] {
        let out = cluster.ndds(host, &["topics", "--all"], WAIT);
        let text = &out.stdout;
        for topic in ["arm/torque", "arm/angles", "arm/endpoint", "fsm/arm/state"] {
            assert!(text.contains(topic), "host {host}: no {topic} in\n{text}");
        }
        let out = cluster.ndds(
            host,
            &["echo", "arm/endpoint", "--count", "1", "--wait", "5"],
            WAIT,
        );
        let text = &out.stdout;
        assert!(
            out.code == Some(0) && text.contains('x') && text.contains('m'),
            "host {host}: ndds echo arm/endpoint printed\n{text}"
        );
    }

    // Ctrl-C: each half stops through its shutdown routines and says so.
    for run in [controller, plant] {
        let (ok, output) = run.interrupt();
        assert!(ok, "ndds run failed:\n{output}");
        assert!(output.contains("interrupted"), "{output}");
        assert!(
            output.contains("shutdown routines ran; 0 module errors"),
            "{output}"
        );
    }
}

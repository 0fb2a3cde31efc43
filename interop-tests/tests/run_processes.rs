//! `ndds run` as a user runs it, on loopback: a broken file is refused with its problems and
//! starts nothing; `--check` verifies; a system runs under a daemon, prints its status, and
//! stops cleanly on Ctrl-C.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use interop_tests::{TestDomain, binary, wait_until};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name)
}

fn ndds(domain: &TestDomain, daemon: &str) -> Command {
    let mut command = Command::new(binary("ndds"));
    command.arg("--socket").arg(domain.socket(daemon));
    command
}

#[test]
fn a_broken_file_is_refused_with_every_problem_and_nothing_starts() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("host");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("broken.toml");
    std::fs::write(
        &file,
        "[[habitat]]\nname = \"h\"\nrate = 100\n\n[[component]]\nname = \"f\"\n\
         type = \"lowpass\"\nhabitat = \"h\"\ninput = \"nowhere\"\noutput = \"y\"\n\
         tau = \"slow\"\n\n[[publish]]\nmat = \"y\"\ntopic = \"broken/y\"\nhabitat = \"h\"\n",
    )
    .unwrap();
    for check in [true, false] {
        let mut command = ndds(&domain, "host");
        command.arg("run");
        if check {
            command.arg("--check");
        }
        let out = command.arg(&file).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{err}");
        assert!(err.contains("(2 problems); nothing was started"), "{err}");
        assert!(
            err.contains("broken.toml:9:9: unknown CSMat `nowhere`"),
            "{err}"
        );
        assert!(
            err.contains("broken.toml:11:7: parameter `tau` is a string; expected a number"),
            "{err}"
        );
    }
    // Nothing was declared on the network.
    let out = ndds(&domain, "host").arg("topics").output().unwrap();
    assert!(!String::from_utf8_lossy(&out.stdout).contains("broken/y"));
}

#[test]
fn check_prints_the_execution_lists() {
    let out = Command::new(binary("ndds"))
        .args(["run", "--check"])
        .arg(example("multirate.toml"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.contains("system `multirate`: verified, nothing started"),
        "{text}"
    );
    assert!(text.contains("habitat servo at 1000"), "{text}");
    let servo = text
        .lines()
        .find(|l| l.contains("habitat servo"))
        .expect("the servo habitat's list");
    let position = |module: &str| servo.find(module).unwrap_or_else(|| panic!("{servo}"));
    // Data flow, not file order: the plan is copied in before the servo reads it.
    assert!(
        position("plan_to_servo.out") < position("servo_pd"),
        "{servo}"
    );
}

#[test]
fn a_system_runs_under_a_daemon_and_stops_cleanly_on_ctrl_c() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("host");
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("run.log");
    let mut child = ndds(&domain, "host")
        .args(["run", "--no-embedded", "--plain", "--seconds", "60"])
        .arg(example("arm.toml"))
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&log).unwrap())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let output = || std::fs::read_to_string(&log).unwrap_or_default();
    // The status reaches endptLQG with the tip error printed near zero.
    let switched = wait_until(Duration::from_secs(30), || {
        output()
            .lines()
            .any(|l| l.starts_with("arm ") && l.ends_with("configuration endptLQG"))
    });
    assert!(switched.is_some(), "never switched:\n{}", output());
    let out = ndds(&domain, "host")
        .args([
            "echo",
            "cs/arm/control/stats",
            "--count",
            "1",
            "--wait",
            "5",
        ])
        .output()
        .unwrap();
    let stats = String::from_utf8_lossy(&out.stdout);
    assert!(stats.contains("endptLQG"), "{stats}");

    kill(Pid::from_raw(child.id() as i32), Signal::SIGINT).unwrap();
    let exited = wait_until(Duration::from_secs(10), || {
        matches!(child.try_wait(), Ok(Some(_)))
    });
    assert!(exited.is_some(), "Ctrl-C did not stop it:\n{}", output());
    assert!(child.wait().unwrap().success());
    let text = output();
    assert!(text.contains("ndds run: interrupted"), "{text}");
    assert!(
        text.contains("ndds run: stopped `arm`") && text.contains("0 module errors"),
        "{text}"
    );
    assert!(text.contains("fsm arm      state Endpoint"), "{text}");
    assert!(text.contains("tip_error = ["), "{text}");
}

//! A closed stdout is a normal end for every printing command: `ndds topics -v | head -1`
//! exits 0, without a "failed printing to stdout: Broken pipe" panic.
//!
//! Two ways the reader goes away, as `head` does: after the first line (streaming commands,
//! and `topics -v` with more output than a small pipe holds), or before the command printed
//! anything (one-shot commands, whose whole output would otherwise fit in the pipe's buffer).

mod common;

use std::io::{BufRead as _, BufReader, Read as _};
use std::os::fd::AsRawFd as _;
use std::process::{Child, ChildStderr, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use common::{RUN_LIMIT, SETTLE, World};
use ndds_client::ProducerQos;
use ndds_runtime::fsm::MachineState;

/// `ndds --socket SOCKET ARGS...` with its stdout and stderr piped.
fn command(world: &World, args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_ndds"));
    command
        .arg("--socket")
        .arg(world.socket())
        .args(args)
        .env_remove("NDDS_DOMAIN")
        .env_remove("NDDS_SOCKET")
        .env_remove("NDDS_EMBEDDED")
        .env_remove("RUST_LOG")
        .stdin(Stdio::null())
        .stderr(Stdio::piped());
    command
}

/// Starts the command with a stdout nobody reads: the pipe's read end is closed before it
/// starts, so its first line already meets a broken pipe.
fn spawn_into_closed_pipe(world: &World, args: &[&str]) -> Child {
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    command(world, args)
        .stdout(writer)
        .spawn()
        .expect("the ndds binary starts")
}

/// Starts the command, reads its first line from a pipe that holds at most one page, and
/// closes the pipe; returns the child and the line.
fn spawn_and_read_first_line(world: &World, args: &[&str]) -> (Child, String) {
    let (reader, writer) = std::io::pipe().expect("a pipe");
    // The smallest pipe Linux allows, so a few kilobytes of output fill it.
    // SAFETY: F_SETPIPE_SZ on a pipe descriptor we own; a failure leaves the default size.
    unsafe { libc::fcntl(writer.as_raw_fd(), libc::F_SETPIPE_SZ, 4096) };
    let child = command(world, args)
        .stdout(writer)
        .spawn()
        .expect("the ndds binary starts");
    let mut reader = BufReader::new(reader);
    let mut line = String::new();
    reader.read_line(&mut line).expect("reading the first line");
    drop(reader);
    (child, line)
}

/// Waits (at most [`RUN_LIMIT`]) for the child to exit, calling `meanwhile` every 20 ms (to
/// keep samples coming); returns its status and stderr.
fn wait(mut child: Child, mut meanwhile: impl FnMut()) -> (ExitStatus, String) {
    let deadline = Instant::now() + RUN_LIMIT;
    let status = loop {
        meanwhile();
        if let Some(status) = child.try_wait().expect("waiting for ndds") {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("ndds kept running after its stdout was closed");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    (status, stderr(child.stderr.take()))
}

fn stderr(pipe: Option<ChildStderr>) -> String {
    let mut text = String::new();
    if let Some(mut pipe) = pipe {
        let _ = pipe.read_to_string(&mut text);
    }
    text
}

/// Asserts a quiet, successful end.
fn assert_quiet_success(args: &[&str], (status, stderr): (ExitStatus, String)) {
    assert!(
        status.success(),
        "`ndds {}` into a closed pipe: {status}\n{stderr}",
        args.join(" ")
    );
    assert!(
        !stderr.contains("panicked") && !stderr.contains("Broken pipe"),
        "`ndds {}`: {stderr}",
        args.join(" ")
    );
}

#[test]
fn listing_commands_end_quietly_when_stdout_is_closed_before_they_print() {
    let world = World::start();
    let participant = world.participant("closed-pipe-lists");
    let _producer = participant
        .producer::<u64>("pipe/numbers", ProducerQos::default())
        .unwrap();
    assert!(world.graph_until(&participant, |g| {
        g.endpoints.iter().any(|e| e.info.topic == "pipe/numbers")
    }));
    for args in [
        &["topics"][..],
        &["topics", "-v"],
        &["topics", "--json"],
        &["nodes"],
        &["nodes", "--json"],
        &["ports", "--listen", "0"],
        &["ports", "--listen", "0", "--json"],
        &["modules", "--listen", "0"],
        &["modules", "--listen", "0", "--json"],
    ] {
        let child = spawn_into_closed_pipe(&world, args);
        assert_quiet_success(args, wait(child, || {}));
    }
}

#[test]
fn topics_verbose_ends_quietly_after_the_first_line() {
    let world = World::start();
    let participant = world.participant("closed-pipe-topics");
    // About 150 bytes per topic: well over the 4 KiB pipe.
    let producers: Vec<_> = (0..60)
        .map(|i| {
            participant
                .producer::<u64>(&format!("pipe/many/{i:03}"), ProducerQos::default())
                .unwrap()
        })
        .collect();
    assert!(world.graph_until(&participant, |g| {
        g.endpoints
            .iter()
            .filter(|e| e.info.topic.starts_with("pipe/many/"))
            .count()
            == producers.len()
    }));
    let args = ["topics", "-v"];
    let (child, line) = spawn_and_read_first_line(&world, &args);
    assert!(line.starts_with("pipe/many/000"), "{line}");
    assert_quiet_success(&args, wait(child, || {}));
}

#[test]
fn streaming_commands_end_quietly_after_the_first_line() {
    let world = World::start();
    let participant = world.participant("closed-pipe-streams");
    let producer = participant
        .producer::<u64>("pipe/stream", ProducerQos::default())
        .unwrap();
    for args in [
        &["echo", "pipe/stream", "--wait", "10"][..],
        &["hz", "pipe/stream", "--wait", "10", "--every", "0.05"],
        &[
            "hz",
            "pipe/stream",
            "--wait",
            "10",
            "--every",
            "0.05",
            "--json",
        ],
    ] {
        let (reader, writer) = std::io::pipe().expect("a pipe");
        let child = command(&world, args).stdout(writer).spawn().unwrap();
        assert!(producer.wait_for_consumers(1, SETTLE), "{args:?}");
        producer.write(&1).unwrap();
        let mut reader = BufReader::new(reader);
        let mut line = String::new();
        reader.read_line(&mut line).unwrap();
        assert!(!line.is_empty(), "{args:?}");
        drop(reader);
        let (status, stderr) = wait(child, || {
            let _ = producer.write(&2);
        });
        assert_quiet_success(args, (status, stderr));
        // The next command's consumer must not be mistaken for this one's.
        assert!(common::eventually(SETTLE, || !producer.wait_for_consumers(1, Duration::ZERO)));
    }
}

#[test]
fn fsm_show_ends_quietly_when_stdout_is_closed() {
    let world = World::start();
    let participant = world.participant("closed-pipe-fsm");
    let producer = participant
        .producer::<MachineState>("fsm/pipe_arm/state", ProducerQos::default())
        .unwrap();
    let state = MachineState {
        machine: "pipe_arm".into(),
        state: "Idle".into(),
        ..MachineState::default()
    };
    for args in [
        &["fsm", "show", "pipe_arm", "--wait", "10"][..],
        &["fsm", "show", "pipe_arm", "--wait", "10", "--json"],
    ] {
        let child = spawn_into_closed_pipe(&world, args);
        assert_quiet_success(
            args,
            wait(child, || {
                let _ = producer.write(&state);
            }),
        );
    }
}

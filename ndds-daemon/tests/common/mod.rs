//! Shared by the daemon's process tests: running `ndds-daemon` with flags that keep it to
//! itself (its own ports and group, on loopback), talking to it as a tool, stopping it.

#![allow(dead_code)]

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use ndds_core::ipc::{self, ClientMessage, DaemonMessage, Graph, Hello, IPC_VERSION, Role};

pub const DAEMON: &str = env!("CARGO_BIN_EXE_ndds-daemon");
pub const WAIT: Duration = Duration::from_secs(10);

/// Runs `ndds-daemon` to completion, killing it if it is still running after [`WAIT`].
pub fn run(args: &[&str]) -> Output {
    let mut child = Command::new(DAEMON)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run ndds-daemon");
    let deadline = Instant::now() + WAIT;
    while child.try_wait().expect("wait for ndds-daemon").is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let out = child
                .wait_with_output()
                .expect("collect ndds-daemon output");
            panic!(
                "ndds-daemon {args:?} still ran after {WAIT:?}; stderr:\n{}",
                stderr(&out)
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child
        .wait_with_output()
        .expect("collect ndds-daemon output")
}

pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Flags that keep a test daemon to itself: its own ports and group, on loopback.
pub fn isolated(dir: &Path) -> Vec<String> {
    let mut rng = fastrand::Rng::new();
    vec![
        "--socket".into(),
        dir.join("d.sock").display().to_string(),
        "--interface".into(),
        "127.0.0.1".into(),
        "--discovery-port".into(),
        rng.u16(20_000..60_000).to_string(),
        "--multicast-group".into(),
        format!("239.255.{}.{}", rng.u8(100..=254), rng.u8(1..=254)),
    ]
}

/// A daemon process that is killed when the handle drops, also when a test panics.
pub struct Spawned(Child);

impl std::ops::Deref for Spawned {
    type Target = Child;

    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for Spawned {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

impl Drop for Spawned {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

pub fn spawn(args: &[String]) -> Spawned {
    Spawned(
        Command::new(DAEMON)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start ndds-daemon"),
    )
}

pub fn connect(socket: &Path) -> UnixStream {
    let deadline = Instant::now() + WAIT;
    loop {
        match UnixStream::connect(socket) {
            Ok(stream) => return stream,
            Err(err) if Instant::now() > deadline => panic!("daemon never listened: {err}"),
            Err(_) => std::thread::sleep(Duration::from_millis(10)),
        }
    }
}

pub fn read_frame(stream: &mut UnixStream) -> DaemonMessage {
    let mut prefix = [0u8; 4];
    stream.read_exact(&mut prefix).expect("frame length");
    let mut body = vec![0u8; u32::from_be_bytes(prefix) as usize];
    stream.read_exact(&mut body).expect("frame body");
    ipc::decode_body(&body).expect("frame decodes")
}

/// Opens a tool session by hand and asks for the graph.
pub fn graph(socket: &Path) -> Graph {
    let mut stream = connect(socket);
    stream.set_read_timeout(Some(WAIT)).unwrap();
    let hello = ClientMessage::Hello(Hello {
        ipc_version: IPC_VERSION,
        participant: 42,
        pid: std::process::id(),
        name: "daemon-cli-test".into(),
        role: Role::Tool,
    });
    stream
        .write_all(&ipc::encode_frame(&hello).unwrap())
        .unwrap();
    assert!(matches!(read_frame(&mut stream), DaemonMessage::Welcome(_)));
    let query = ClientMessage::QueryGraph {
        request: 1,
        after: None,
    };
    stream
        .write_all(&ipc::encode_frame(&query).unwrap())
        .unwrap();
    match read_frame(&mut stream) {
        DaemonMessage::Graph {
            request: 1,
            graph,
            next: None,
        } => graph,
        other => panic!("unexpected answer {other:?}"),
    }
}

pub fn terminate(child: &mut Child) -> Option<i32> {
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
    let deadline = Instant::now() + WAIT;
    while Instant::now() < deadline {
        if let Some(status) = child.try_wait().unwrap() {
            return status.code();
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = child.kill();
    None
}

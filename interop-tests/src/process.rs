//! Child processes owned by a test: killed and reaped when dropped.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use crate::{TestDomain, binary};

/// How long a daemon may take to accept clients after it is started.
const START_TIMEOUT: Duration = Duration::from_secs(10);

/// The result of a short-lived command.
#[derive(Debug)]
pub struct Output {
    /// Exit code (`None` if killed by a signal or at the timeout).
    pub code: Option<i32>,
    /// Standard output.
    pub stdout: String,
    /// Standard error.
    pub stderr: String,
}

/// Runs a command to completion, killing it at `timeout`.
pub fn run(program: &Path, args: &[String], timeout: Duration) -> Output {
    let mut child = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|err| panic!("cannot start {}: {err}", program.display()));
    let stdout = drain(child.stdout.take());
    let stderr = drain(child.stderr.take());
    let deadline = Instant::now() + timeout;
    let code = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status.code(),
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(5)),
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
        }
    };
    Output {
        code,
        stdout: stdout.join().unwrap_or_default(),
        stderr: stderr.join().unwrap_or_default(),
    }
}

fn drain(pipe: Option<impl Read + Send + 'static>) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut text = String::new();
        if let Some(mut pipe) = pipe {
            let _ = pipe.read_to_string(&mut text);
        }
        text
    })
}

fn signal(child: &Child, signal: Signal) {
    let pid = Pid::from_raw(i32::try_from(child.id()).expect("pid fits i32"));
    let _ = kill(pid, signal);
}

/// A running `ndds-daemon`; killed (SIGKILL) on drop unless it already exited.
#[derive(Debug)]
pub struct DaemonProcess {
    child: Child,
    /// Its socket path.
    pub socket: PathBuf,
    /// Its log (stderr) file.
    pub log: PathBuf,
}

impl DaemonProcess {
    /// Starts a daemon in `domain` and waits until its socket accepts connections.
    pub fn start(domain: &TestDomain, name: &str) -> Self {
        let log = domain.path(&format!("{name}.log"));
        let log_file = std::fs::File::create(&log).expect("daemon log file");
        let child = Command::new(binary("ndds-daemon"))
            .args(domain.daemon_args(name))
            .env("RUST_LOG", "debug")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log_file)
            .spawn()
            .expect("start ndds-daemon");
        let daemon = DaemonProcess {
            child,
            socket: domain.socket(name),
            log,
        };
        let started = crate::wait_until(START_TIMEOUT, || {
            std::os::unix::net::UnixStream::connect(&daemon.socket).is_ok()
        });
        assert!(
            started.is_some(),
            "daemon {name} did not start; its log:\n{}",
            daemon.log_text()
        );
        daemon
    }

    /// Process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Everything the daemon logged so far.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Freezes the process (SIGSTOP): it stays alive but silent.
    pub fn stop(&self) {
        signal(&self.child, Signal::SIGSTOP);
    }

    /// Resumes a frozen process (SIGCONT).
    pub fn resume(&self) {
        signal(&self.child, Signal::SIGCONT);
    }

    /// Asks the daemon to shut down (SIGTERM) and waits for it to exit; returns its exit code.
    pub fn terminate(&mut self, timeout: Duration) -> Option<i32> {
        signal(&self.child, Signal::SIGTERM);
        wait_exit(&mut self.child, timeout)
    }
}

impl Drop for DaemonProcess {
    fn drop(&mut self) {
        signal(&self.child, Signal::SIGCONT);
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn wait_exit(child: &mut Child, timeout: Duration) -> Option<i32> {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        if let Ok(Some(status)) = child.try_wait() {
            return status.code();
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    None
}

/// A running `ndds-test-node` (or other client) whose stdout lines can be read; killed on drop.
#[derive(Debug)]
pub struct ClientProcess {
    child: Child,
    lines: Receiver<String>,
}

impl ClientProcess {
    /// Starts `ndds-test-node` with `args`, connected to the daemon at `socket`.
    pub fn test_node(socket: &Path, args: &[&str]) -> Self {
        let mut child = Command::new(binary("ndds-test-node"))
            .args(args)
            .env("NDDS_SOCKET", socket)
            .env("NDDS_EMBEDDED", "never")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start ndds-test-node");
        let stdout = child.stdout.take().expect("piped stdout");
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        ClientProcess { child, lines }
    }

    /// Process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The next stdout line, or `None` at the timeout or end of output.
    pub fn line(&self, timeout: Duration) -> Option<String> {
        self.lines.recv_timeout(timeout).ok()
    }

    /// The next stdout line that parses as JSON with `"event": event`.
    pub fn event(&self, event: &str, timeout: Duration) -> Option<serde_json::Value> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = self.line(left)?;
            if let Ok(value) = serde_json::from_str::<serde_json::Value>(&line)
                && value["event"] == event
            {
                return Some(value);
            }
        }
    }

    /// Kills the process with SIGKILL (a crash: no goodbye of any kind).
    pub fn kill9(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Waits for the process to exit; returns its exit code.
    pub fn wait(&mut self, timeout: Duration) -> Option<i32> {
        wait_exit(&mut self.child, timeout)
    }
}

impl Drop for ClientProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

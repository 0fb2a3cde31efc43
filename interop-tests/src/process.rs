//! Child processes owned by a test: killed and reaped when dropped.
//!
//! Each kind starts either in this network namespace or inside a simulated host
//! ([`Host`]), through the [`Command`] the host builds (`ip netns exec HOST ...`, which execs
//! the program itself: the child's pid is the program's).

use std::io::{BufRead, BufReader, Read};
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use crate::netns::Host;
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

/// Runs a program to completion, killing it at `timeout`.
pub fn run(program: &Path, args: &[String], timeout: Duration) -> Output {
    let mut command = Command::new(program);
    command.args(args);
    run_command(command, timeout)
}

/// Runs a prepared command to completion, killing it at `timeout`.
pub fn run_command(mut command: Command, timeout: Duration) -> Output {
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|err| panic!("cannot start {command:?}: {err}"));
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

/// Resident memory of a process, from `/proc/PID/status`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Memory {
    /// Resident set size now (`VmRSS`), KiB.
    pub rss_kib: u64,
    /// Largest resident set size so far (`VmHWM`), KiB.
    pub peak_kib: u64,
}

/// The resident memory of process `pid`, or `None` when it is gone (or not readable).
pub fn memory(pid: u32) -> Option<Memory> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| {
        status
            .lines()
            .find_map(|line| line.strip_prefix(name))
            .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
    };
    Some(Memory {
        rss_kib: field("VmRSS:")?,
        peak_kib: field("VmHWM:")?,
    })
}

fn running(child: &mut Child) -> bool {
    matches!(child.try_wait(), Ok(None))
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
    /// Starts a daemon in `domain` on loopback and waits until its socket accepts connections.
    pub fn start(domain: &TestDomain, name: &str) -> Self {
        let command = Command::new(binary("ndds-daemon"));
        Self::launch(command, domain, name, Ipv4Addr::LOCALHOST)
    }

    /// Starts a daemon in `domain` on loopback with `env` in its environment (for example
    /// `NDDS_KEY_FILE`), and waits until its socket accepts connections.
    pub fn start_with_env(domain: &TestDomain, name: &str, env: &[(&str, &Path)]) -> Self {
        let mut command = Command::new(binary("ndds-daemon"));
        command.envs(env.iter().map(|(k, v)| (*k, *v)));
        Self::launch(command, domain, name, Ipv4Addr::LOCALHOST)
    }

    /// Starts a daemon in `domain` inside `host`, bound to the host's address, and waits until
    /// its socket accepts connections. The socket lives in the domain's directory, which every
    /// host shares.
    pub fn start_on(host: &Host, domain: &TestDomain, name: &str) -> Self {
        let command = host.exec(binary("ndds-daemon"));
        Self::launch(command, domain, name, host.ip())
    }

    fn launch(mut command: Command, domain: &TestDomain, name: &str, interface: Ipv4Addr) -> Self {
        let log = domain.path(&format!("{name}.log"));
        // Appended to: a daemon restarted under the same name keeps its predecessor's log.
        let log_file = std::fs::File::options()
            .create(true)
            .append(true)
            .open(&log)
            .expect("daemon log file");
        let child = command
            .args(domain.daemon_args_on(name, interface))
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

    /// True while the process runs (it has not exited nor been killed).
    pub fn is_running(&mut self) -> bool {
        running(&mut self.child)
    }

    /// Its resident memory, `None` once it is gone.
    pub fn memory(&self) -> Option<Memory> {
        memory(self.pid())
    }

    /// Everything the daemon logged so far.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Freezes the process (SIGSTOP): it stays alive but silent.
    pub fn stop(&self) {
        signal(&self.child, Signal::SIGSTOP);
    }

    /// Kills the process with SIGKILL (a crash: no goodbye of any kind) and reaps it. Its
    /// socket file stays behind, as after a real crash.
    pub fn kill9(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
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
        Self::spawn(Command::new(binary("ndds-test-node")), socket, args)
    }

    /// Starts the workspace binary `name` (an example program built as one) with `args`,
    /// connected to the daemon at `socket`; its stdout lines can be read.
    pub fn program(name: &str, socket: &Path, args: &[&str]) -> Self {
        Self::spawn(Command::new(binary(name)), socket, args)
    }

    /// As [`program`](Self::program), inside `host` (the daemon at `socket` must run there).
    pub fn program_on(host: &Host, name: &str, socket: &Path, args: &[&str]) -> Self {
        Self::spawn(host.exec(binary(name)), socket, args)
    }

    /// Sends SIGINT (Ctrl-C) to the process.
    pub fn interrupt(&self) {
        let _ = kill(Pid::from_raw(self.child.id() as i32), Signal::SIGINT);
    }

    /// Starts `ndds-test-node` with `args` and `env` in its environment, connected to the
    /// daemon at `socket`.
    pub fn test_node_with_env(socket: &Path, args: &[&str], env: &[(&str, &Path)]) -> Self {
        let mut command = Command::new(binary("ndds-test-node"));
        command.envs(env.iter().map(|(k, v)| (*k, *v)));
        Self::spawn(command, socket, args)
    }

    /// Starts `ndds-test-node` with `args` inside `host`, connected to the daemon at `socket`
    /// (which must run in the same host: the client binds its data socket to the daemon's
    /// interface).
    pub fn test_node_on(host: &Host, socket: &Path, args: &[&str]) -> Self {
        Self::spawn(host.exec(binary("ndds-test-node")), socket, args)
    }

    /// As [`test_node_on`](Self::test_node_on), with `env` in its environment.
    pub fn test_node_on_with_env(
        host: &Host,
        socket: &Path,
        args: &[&str],
        env: &[(&str, &Path)],
    ) -> Self {
        let mut command = host.exec(binary("ndds-test-node"));
        command.envs(env.iter().map(|(k, v)| (*k, *v)));
        Self::spawn(command, socket, args)
    }

    fn spawn(mut command: Command, socket: &Path, args: &[&str]) -> Self {
        let mut child = command
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

    /// True while the process runs (it has not exited nor been killed).
    pub fn is_running(&mut self) -> bool {
        running(&mut self.child)
    }

    /// Its resident memory, `None` once it is gone.
    pub fn memory(&self) -> Option<Memory> {
        memory(self.pid())
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

    /// The JSON lines read until `until` (lines that are not JSON are skipped; lines still
    /// queued at `until` stay for the next read).
    pub fn events_until(&self, until: Instant) -> Vec<serde_json::Value> {
        let mut events = Vec::new();
        while let Some(left) = until.checked_duration_since(Instant::now()) {
            let Some(line) = self.line(left) else { break };
            if let Ok(value) = serde_json::from_str(&line) {
                events.push(value);
            }
        }
        events
    }

    /// Discards the lines already printed; returns how many there were.
    pub fn drain(&self) -> usize {
        self.lines.try_iter().count()
    }

    /// Kills the process with SIGKILL (a crash: no goodbye of any kind).
    pub fn kill9(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Freezes the process (SIGSTOP): it stays alive but silent.
    pub fn stop(&self) {
        signal(&self.child, Signal::SIGSTOP);
    }

    /// Resumes a frozen process (SIGCONT).
    pub fn resume(&self) {
        signal(&self.child, Signal::SIGCONT);
    }

    /// Waits for the process to exit; returns its exit code.
    pub fn wait(&mut self, timeout: Duration) -> Option<i32> {
        wait_exit(&mut self.child, timeout)
    }
}

impl Drop for ClientProcess {
    fn drop(&mut self) {
        signal(&self.child, Signal::SIGCONT);
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

//! Shared set-up of the `ndds` command tests: a daemon embedded in the test process on a
//! configuration unique to the test (domain, discovery port, multicast group, socket), and the
//! real `ndds` binary run against its socket, always with a time limit.

#![allow(dead_code)]

use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use ndds_client::{DaemonConfig, EmbeddedPolicy, Participant};
use ndds_daemon::EmbeddedDaemon;

/// How long any `ndds` run may take before the test kills it.
pub const RUN_LIMIT: Duration = Duration::from_secs(20);

/// How long to wait for discovery (matches, graph entries) to settle.
pub const SETTLE: Duration = Duration::from_secs(10);

/// A daemon configuration unique to one test, on loopback, with fast timers.
pub fn unique_config(dir: &Path) -> DaemonConfig {
    let mut rng = fastrand::Rng::new();
    let domain = rng.u16(1..=232);
    let mut config = DaemonConfig::new(domain, Ipv4Addr::LOCALHOST);
    config.socket = dir.join("ndds.sock");
    config.port = rng.u16(20_000..60_000);
    config.group = Ipv4Addr::new(239, 255, rng.u8(100..=254), rng.u8(1..=254));
    config.announce_period = Duration::from_millis(200);
    config.lease = Duration::from_millis(1000);
    config
}

/// One test's world: a temporary directory and a daemon embedded in the test process.
pub struct World {
    /// The daemon's configuration.
    pub config: DaemonConfig,
    daemon: EmbeddedDaemon,
    _dir: tempfile::TempDir,
}

impl World {
    /// Starts a daemon on a fresh unique configuration.
    pub fn start() -> World {
        let dir = tempfile::tempdir().expect("temporary directory");
        let config = unique_config(dir.path());
        let daemon = EmbeddedDaemon::start(config.clone()).expect("embedded daemon starts");
        World {
            config,
            daemon,
            _dir: dir,
        }
    }

    /// The daemon's socket path.
    pub fn socket(&self) -> &Path {
        &self.config.socket
    }

    /// The daemon's node id.
    pub fn node_id(&self) -> u64 {
        self.daemon.node_id()
    }

    /// A participant of the test process, connected to this daemon (never an embedded one).
    pub fn participant(&self, name: &str) -> Participant {
        Participant::builder()
            .socket(self.socket())
            .embedded(EmbeddedPolicy::Never)
            .name(name)
            .connect()
            .expect("participant connects to the test daemon")
    }

    /// Runs `ndds --socket SOCKET ARGS...` to completion (killed after [`RUN_LIMIT`]).
    pub fn ndds(&self, args: &[&str]) -> Run {
        ndds_at(self.socket(), args)
    }

    /// Starts `ndds --socket SOCKET ARGS...` in the background.
    pub fn spawn(&self, args: &[&str]) -> Running {
        Running::spawn(self.socket(), args)
    }

    /// Polls the daemon's graph until `check` holds or [`SETTLE`] passes.
    pub fn graph_until(
        &self,
        participant: &Participant,
        mut check: impl FnMut(&ndds_client::Graph) -> bool,
    ) -> bool {
        eventually(SETTLE, || participant.graph().is_ok_and(|g| check(&g)))
    }
}

/// Runs `ndds --socket SOCKET ARGS...` to completion (killed after [`RUN_LIMIT`]).
pub fn ndds_at(socket: &Path, args: &[&str]) -> Run {
    Running::spawn(socket, args).finish(RUN_LIMIT)
}

/// A finished `ndds` run.
#[derive(Debug)]
pub struct Run {
    /// Exit status (`None` if the test had to kill it).
    pub status: Option<ExitStatus>,
    /// Standard output.
    pub stdout: String,
    /// Standard error.
    pub stderr: String,
    /// The command line, for messages.
    pub command: String,
}

impl Run {
    /// True when it exited by itself with status 0.
    pub fn success(&self) -> bool {
        self.status.is_some_and(|s| s.success())
    }

    /// True when it exited by itself with a non-zero status.
    pub fn failed(&self) -> bool {
        self.status
            .is_some_and(|s| !s.success() && s.code().is_some())
    }

    /// Asserts success and returns stdout.
    pub fn ok(&self) -> &str {
        assert!(self.success(), "expected success: {self}");
        &self.stdout
    }

    /// Asserts failure and returns stderr.
    pub fn err(&self) -> &str {
        assert!(self.failed(), "expected failure: {self}");
        &self.stderr
    }

    /// Stdout parsed as one JSON document.
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_str(self.ok())
            .unwrap_or_else(|err| panic!("stdout is not one JSON document ({err}): {self}"))
    }
}

impl std::fmt::Display for Run {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "`{}` -> {}\n--- stdout\n{}--- stderr\n{}---",
            self.command,
            match self.status {
                Some(status) => status.to_string(),
                None => "killed after the time limit".to_owned(),
            },
            self.stdout,
            self.stderr
        )
    }
}

/// An `ndds` process running in the background; killed when dropped.
pub struct Running {
    child: Child,
    stdout: Option<JoinHandle<String>>,
    stderr: Option<JoinHandle<String>>,
    command: String,
}

impl Running {
    /// Starts `ndds --socket SOCKET ARGS...` with a clean ndds environment.
    pub fn spawn(socket: &Path, args: &[&str]) -> Running {
        let mut command = Command::new(env!("CARGO_BIN_EXE_ndds"));
        command
            .arg("--socket")
            .arg(socket)
            .args(args)
            .env_remove("NDDS_DOMAIN")
            .env_remove("NDDS_SOCKET")
            .env_remove("NDDS_EMBEDDED")
            .env_remove("RUST_LOG")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        Running::from_command(
            command,
            &format!("ndds --socket {} {}", socket.display(), args.join(" ")),
        )
    }

    /// Starts `ndds ARGS...` with no `--socket` and a clean ndds environment.
    pub fn spawn_without_socket(args: &[&str]) -> Running {
        let mut command = Command::new(env!("CARGO_BIN_EXE_ndds"));
        command
            .args(args)
            .env_remove("NDDS_DOMAIN")
            .env_remove("NDDS_SOCKET")
            .env_remove("NDDS_EMBEDDED")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        Running::from_command(command, &format!("ndds {}", args.join(" ")))
    }

    /// Starts a prepared command with piped output; `shown` names it in messages.
    pub fn from_command(mut command: Command, shown: &str) -> Running {
        let mut child = command.spawn().expect("the ndds binary starts");
        let stdout = child.stdout.take().map(drain);
        let stderr = child.stderr.take().map(drain);
        Running {
            child,
            stdout,
            stderr,
            command: shown.to_owned(),
        }
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Whether it is still running.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Waits for it to exit, killing it after `limit`, and collects its output.
    pub fn finish(mut self, limit: Duration) -> Run {
        let deadline = Instant::now() + limit;
        let mut status = None;
        while Instant::now() < deadline {
            match self.child.try_wait() {
                Ok(Some(exit)) => {
                    status = Some(exit);
                    break;
                }
                Ok(None) => std::thread::sleep(Duration::from_millis(10)),
                Err(err) => panic!("waiting for `{}`: {err}", self.command),
            }
        }
        if status.is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
        Run {
            status,
            stdout: join(self.stdout.take()),
            stderr: join(self.stderr.take()),
            command: self.command.clone(),
        }
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

fn drain(mut pipe: impl std::io::Read + Send + 'static) -> JoinHandle<String> {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = pipe.read_to_end(&mut bytes);
        String::from_utf8_lossy(&bytes).into_owned()
    })
}

fn join(handle: Option<JoinHandle<String>>) -> String {
    handle.and_then(|h| h.join().ok()).unwrap_or_default()
}

/// A socket path in a fresh temporary directory where no daemon runs.
pub fn dead_socket() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("nobody-home.sock");
    (dir, path)
}

/// Polls `check` every 10 ms until it holds or `timeout` passes.
pub fn eventually(timeout: Duration, mut check: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        if check() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    check()
}

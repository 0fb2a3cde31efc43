//! One simulated host: a network namespace with one address on the test bridge.

use std::ffi::OsStr;
use std::fs::File;
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::Duration;

use ndds_client::{EmbeddedPolicy, Participant};
use nix::sched::{CloneFlags, setns};

use super::LINK;
use super::command::{ip_path, nft_in};
use super::faults::{self, Faults, TABLE};
use super::meter::{self, METER_TABLE, Traffic};
use crate::TestDomain;
use crate::process::{self, ClientProcess, DaemonProcess, Output};

/// Where `ip netns` keeps its namespace handles.
const NETNS_DIR: &str = "/var/run/netns";

/// A host of a [`Network`](super::Network).
#[derive(Debug)]
pub struct Host {
    name: String,
    ip: Ipv4Addr,
    faults: Mutex<Faults>,
}

impl Host {
    pub(super) fn new(name: String, ip: Ipv4Addr) -> Self {
        Host {
            name,
            ip,
            faults: Mutex::new(Faults::default()),
        }
    }

    /// Name of its network namespace.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Its address on the bridge.
    pub fn ip(&self) -> Ipv4Addr {
        self.ip
    }

    /// A command that runs `program` inside this host (`ip netns exec NAME program`; `ip`
    /// execs the program, so the child's pid is the program's).
    pub fn exec(&self, program: impl AsRef<OsStr>) -> Command {
        let mut command = Command::new(ip_path());
        command.args(["netns", "exec", &self.name]).arg(program);
        command
    }

    /// Runs `program args` inside this host to completion, killing it at `timeout`.
    pub fn run(&self, program: &Path, args: &[String], timeout: Duration) -> Output {
        let mut command = self.exec(program);
        command.args(args);
        process::run_command(command, timeout)
    }

    /// Runs `f` on a thread inside this host's network namespace: the sockets it opens, and
    /// the threads it spawns, belong to the host.
    pub fn enter<T: Send>(&self, f: impl FnOnce() -> T + Send) -> T {
        let path = PathBuf::from(NETNS_DIR).join(&self.name);
        let netns =
            File::open(&path).unwrap_or_else(|err| panic!("cannot open {}: {err}", path.display()));
        std::thread::scope(|scope| {
            let thread = scope.spawn(move || {
                setns(&netns, CloneFlags::CLONE_NEWNET)
                    .unwrap_or_else(|err| panic!("cannot enter {}: {err}", path.display()));
                f()
            });
            thread
                .join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
        })
    }

    /// Starts the daemon `name` of `domain` inside this host, bound to the host's address;
    /// returns once it accepts clients.
    pub fn daemon(&self, domain: &TestDomain, name: &str) -> DaemonProcess {
        DaemonProcess::start_on(self, domain, name)
    }

    /// Starts `ndds-test-node ARGS` inside this host, as a client of the daemon at `socket`
    /// (which must run in this host).
    pub fn test_node(&self, socket: &Path, args: &[&str]) -> ClientProcess {
        ClientProcess::test_node_on(self, socket, args)
    }

    /// A tool session with the daemon at `socket` (which must run in this host), for reading
    /// its graph from the test process.
    pub fn tool(&self, socket: &Path) -> Participant {
        let socket = socket.to_owned();
        self.enter(move || {
            Participant::builder()
                .socket(&socket)
                .embedded(EmbeddedPolicy::Never)
                .tool()
                .name("interop-test")
                .connect()
                .unwrap_or_else(|err| panic!("tool session with {}: {err}", socket.display()))
        })
    }

    /// Runs `ndds --socket SOCKET ARGS` inside this host, killed after `timeout`.
    pub fn ndds(&self, socket: &Path, args: &[&str], timeout: Duration) -> Output {
        let mut full = vec!["--socket".to_owned(), socket.display().to_string()];
        full.extend(args.iter().map(|a| (*a).to_owned()));
        self.run(&crate::binary("ndds"), &full, timeout)
    }

    /// The faults in force on this host.
    pub fn faults(&self) -> Faults {
        self.lock_faults().clone()
    }

    /// Changes this host's faults and installs the new rule set (one nft transaction).
    pub fn change_faults(&self, change: impl FnOnce(&mut Faults)) {
        let mut faults = self.lock_faults();
        let before = faults.clone();
        change(&mut faults);
        if *faults == before {
            return;
        }
        if let Err(err) = nft_in(&self.name, &faults.script(LINK, self.ip)) {
            *faults = before;
            panic!("cannot install the faults of host {}: {err}", self.name);
        }
    }

    /// Packets the faults have dropped since they last changed (read from the nft counters).
    pub fn dropped_packets(&self) -> u64 {
        let _faults = self.lock_faults();
        let listing = nft_in(&self.name, &format!("list table inet {TABLE}")).unwrap_or_default();
        faults::dropped(&listing)
    }

    /// Starts (or restarts, from zero) counting the UDP datagrams through this host's link to
    /// the bridge; read them with [`traffic`](Self::traffic).
    pub fn start_meter(&self) {
        if let Err(err) = nft_in(&self.name, &meter::script(LINK, self.ip)) {
            panic!(
                "cannot install the traffic meter of host {}: {err}",
                self.name
            );
        }
    }

    /// The UDP traffic through this host's link since [`start_meter`](Self::start_meter)
    /// (zero if it was never started).
    pub fn traffic(&self) -> Traffic {
        let listing = nft_in(
            &self.name,
            &format!("list counters table inet {METER_TABLE}"),
        )
        .unwrap_or_default();
        meter::parse(&listing)
    }

    fn lock_faults(&self) -> std::sync::MutexGuard<'_, Faults> {
        self.faults
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

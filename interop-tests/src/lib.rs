//! # interop-tests
//!
//! A harness for tests that run the real programs: `ndds-daemon` processes standing for hosts,
//! the `ndds` CLI, and the test client `ndds-test-node`. Every [`TestDomain`] gets its own
//! domain id, discovery port, multicast group and socket directory, so tests running in
//! parallel never see each other. Processes are killed when their handles drop, even when a
//! test panics.
//!
//! Two settings:
//! - **loopback**: every daemon binds to `127.0.0.1` of the machine ([`TestDomain::daemon`]);
//! - **simulated hosts** ([`netns`]): each host is a network namespace on a bridge of its own,
//!   its daemon binds to the host's address, and faults (loss, partitions) are injected with
//!   `nft` inside the hosts. Needs root, `ip` and `nft`.
//!
//! Either way no traffic leaves the machine.
//!
//! ## Layout
//! - `lib.rs`: [`TestDomain`], binaries, polling helpers;
//! - [`process`]: child processes owned by a test (daemons, test nodes, short commands);
//! - [`netns`]: hosts as network namespaces, fault injection, a daemon per host ([`netns::Cluster`]);
//! - [`python`]: Python readers of our files (`mcap`, `jsonschema`).
//!
//! The binaries are taken from the cargo target directory of the running test; `cargo test
//! --workspace` builds them (`ndds-daemon` and `ndds` have integration tests of their own,
//! which makes cargo build them for any workspace test run).
#![warn(missing_docs)]

pub mod netns;
pub mod process;
pub mod python;

use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use ndds_client::{EmbeddedPolicy, Graph, Participant};

pub use process::{ClientProcess, DaemonProcess};

/// Announce period used by test daemons.
pub const PERIOD: Duration = Duration::from_millis(200);
/// Lease used by test daemons.
pub const LEASE: Duration = Duration::from_millis(1000);

/// Path of a binary built in this workspace's target directory.
pub fn binary(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test>-<hash>  →  target/<profile>/<name>
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("test executable lives in target/<profile>/deps");
    let path = profile_dir.join(name);
    assert!(
        path.exists(),
        "{} is missing: build the workspace binaries first (`cargo build --workspace --bins`, \
         or run the README's test command)",
        path.display()
    );
    path
}

/// One isolated domain on loopback: unique domain id, ports, group and socket directory.
#[derive(Debug)]
pub struct TestDomain {
    /// Domain id.
    pub domain: u16,
    /// Discovery multicast port.
    pub port: u16,
    /// Discovery multicast group.
    pub group: Ipv4Addr,
    dir: tempfile::TempDir,
    /// The domain's key file, in a sealed domain: daemons get `--key-file`, clients
    /// `NDDS_KEY_FILE`.
    pub key: Option<PathBuf>,
    /// More flags for the daemon of each name (an identity, a permissions document).
    pub daemon_extra: std::collections::BTreeMap<String, Vec<String>>,
}

impl TestDomain {
    /// A new isolated domain.
    pub fn new() -> Self {
        let mut rng = fastrand::Rng::new();
        TestDomain {
            domain: rng.u16(1..=232),
            port: rng.u16(20_000..60_000),
            group: Ipv4Addr::new(239, 255, rng.u8(100..=254), rng.u8(1..=254)),
            dir: tempfile::tempdir().expect("temporary directory"),
            key: None,
            daemon_extra: std::collections::BTreeMap::new(),
        }
    }

    /// A new isolated domain sealed with a new key, in the cipher `ndds key new` chooses on
    /// this processor (AEGIS-128L where it has the instructions, else AES-128-GCM or
    /// ChaCha20-Poly1305).
    pub fn sealed() -> Self {
        Self::sealed_with(ndds_daemon::keys::suggested_cipher())
    }

    /// A new isolated domain sealed with a new key in `cipher`.
    pub fn sealed_with(cipher: ndds_core::seal::Cipher) -> Self {
        let mut domain = Self::new();
        let key = domain.path("domain.key");
        ndds_daemon::keys::create(&key, cipher).expect("a new key file");
        domain.key = Some(key);
        domain
    }

    /// A new sealed domain with a permissions document signed by a new administrator key, in
    /// which each daemon of `names` has an identity of its own and is a subject (of its name)
    /// that may publish and subscribe to everything: the daemons sign and check all
    /// discovery (docs/security.md).
    pub fn with_permissions(names: &[String]) -> Self {
        use ndds_core::security::{Identity, sign};
        let mut domain = Self::sealed();
        let admin = Identity::from_secret(ndds_daemon::keys::random_bytes().expect("random"));
        let admin_pub = domain.path("admin.pub");
        std::fs::write(&admin_pub, format!("{}\n", admin.public())).expect("admin.pub");
        let mut text = format!(
            "serial = 1\ndomain = {}\nnot_before = \"2000-01-01T00:00:00Z\"\n\
             not_after = \"2100-01-01T00:00:00Z\"\n",
            domain.domain
        );
        for name in names {
            let file = domain.path(&format!("{name}.id"));
            let (identity, _) =
                ndds_daemon::security::load_or_create_identity(&file).expect("an identity");
            text.push_str(&format!(
                "\n[[subject]]\nname = \"{name}\"\nkey = \"{}\"\npublish = [\"*\"]\nsubscribe = [\"*\"]\n",
                identity.public()
            ));
            domain.daemon_extra.insert(
                name.clone(),
                vec![
                    "--identity".into(),
                    file.display().to_string(),
                    "--permissions".into(),
                    domain.path("permissions.toml").display().to_string(),
                    "--admin-key".into(),
                    admin_pub.display().to_string(),
                ],
            );
        }
        std::fs::write(domain.path("permissions.toml"), sign(&text, &admin))
            .expect("permissions.toml");
        domain
    }

    /// The socket path of the daemon called `name`.
    pub fn socket(&self, name: &str) -> PathBuf {
        self.dir.path().join(format!("{name}.sock"))
    }

    /// A file in the domain's temporary directory.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// The flags that put a daemon in this domain, on loopback, with the test timers.
    pub fn daemon_args(&self, name: &str) -> Vec<String> {
        self.daemon_args_on(name, Ipv4Addr::LOCALHOST)
    }

    /// The flags that put a daemon in this domain, bound to `interface`, with the test timers.
    pub fn daemon_args_on(&self, name: &str, interface: Ipv4Addr) -> Vec<String> {
        let key = self
            .key
            .iter()
            .flat_map(|path| ["--key-file".into(), path.display().to_string()]);
        let mut args: Vec<String> = vec![
            "--domain".into(),
            self.domain.to_string(),
            "--socket".into(),
            self.socket(name).display().to_string(),
            "--interface".into(),
            interface.to_string(),
            "--multicast-group".into(),
            self.group.to_string(),
            "--discovery-port".into(),
            self.port.to_string(),
            "--announce-period-ms".into(),
            PERIOD.as_millis().to_string(),
            "--lease-ms".into(),
            LEASE.as_millis().to_string(),
        ];
        args.extend(key);
        args.extend(self.daemon_extra.get(name).into_iter().flatten().cloned());
        args
    }

    /// Starts a daemon called `name` on loopback and waits until it accepts clients.
    pub fn daemon(&self, name: &str) -> DaemonProcess {
        DaemonProcess::start(self, name)
    }

    /// A tool session with the daemon called `name`, for reading its graph.
    pub fn tool(&self, name: &str) -> Participant {
        Participant::builder()
            .socket(self.socket(name))
            .embedded(EmbeddedPolicy::Never)
            .tool()
            .name("interop-test")
            .connect()
            .expect("tool session with the test daemon")
    }

    /// Runs `ndds` with `args` against the daemon called `name`; returns (status, stdout,
    /// stderr). Killed after `timeout`.
    pub fn ndds(&self, name: &str, args: &[&str], timeout: Duration) -> process::Output {
        let mut full = vec![
            "--socket".to_owned(),
            self.socket(name).display().to_string(),
        ];
        full.extend(args.iter().map(|a| (*a).to_owned()));
        process::run(&binary("ndds"), &full, timeout)
    }
}

impl Default for TestDomain {
    fn default() -> Self {
        Self::new()
    }
}

/// A participant of this test process, a client of the daemon at `socket` (never an
/// embedded daemon), named `name`.
pub fn participant(socket: &Path, name: &str) -> Participant {
    Participant::builder()
        .socket(socket)
        .embedded(EmbeddedPolicy::Never)
        .name(name)
        .connect()
        .unwrap_or_else(|err| {
            panic!(
                "{name}: connect to the test daemon at {}: {err}",
                socket.display()
            )
        })
}

/// One test of this test binary at a time while the guard lives: tests that measure timing,
/// or that must not fork while another copies a binary, take turns. Each test binary is its own
/// process, so the turns are per file.
pub fn exclusive() -> std::sync::MutexGuard<'static, ()> {
    static TURN: std::sync::Mutex<()> = std::sync::Mutex::new(());
    TURN.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Polls `check` every 5 ms until it holds; returns how long that took, or `None` at the
/// timeout.
pub fn wait_until(timeout: Duration, mut check: impl FnMut() -> bool) -> Option<Duration> {
    let start = Instant::now();
    loop {
        if check() {
            return Some(start.elapsed());
        }
        if start.elapsed() >= timeout {
            return None;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// True when `graph` lists an endpoint on `topic` owned by process `pid`.
pub fn has_endpoint(graph: &Graph, topic: &str, pid: u32) -> bool {
    graph
        .endpoints
        .iter()
        .any(|e| e.info.topic == topic && e.info.pid == pid)
}

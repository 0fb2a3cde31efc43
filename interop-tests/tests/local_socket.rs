//! The local socket with real daemon processes: where it is made and with which modes, who
//! the daemon says its clients are (the kernel's word), and an unprivileged local user who
//! squats the path, refused by the daemon and by clients alike.
//!
//! The squatting tests run processes as other users, so they need root; like the multi-host
//! tests they skip without it, and fail instead under CI (`support::skipped`).

mod support;

use std::fs;
use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
use std::os::unix::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use interop_tests::{TestDomain, binary, process, wait_until};
use ndds_client::{ConnectError, EmbeddedPolicy, Participant};

// The tests of this file take turns: one copies the daemon binary while another could fork,
// and a child holding the copy's open file makes running it fail ("text file busy").
use interop_tests::exclusive as turn;

/// The unprivileged user who squats.
const SQUATTER: u32 = 65534;
/// Another unprivileged user, whose daemon finds its directory squatted.
const VICTIM: u32 = 65533;

fn is_socket(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt as _;
    fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_socket())
}

/// A directory every user may create files in, like `/tmp` (sticky, 1777), holding a copy of
/// the daemon binary that every user may run (the build directory may be private).
struct Shared {
    dir: tempfile::TempDir,
    daemon: PathBuf,
}

impl Shared {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        fs::set_permissions(dir.path(), fs::Permissions::from_mode(0o1777)).unwrap();
        let daemon = dir.path().join("ndds-daemon");
        fs::copy(binary("ndds-daemon"), &daemon).unwrap();
        fs::set_permissions(&daemon, fs::Permissions::from_mode(0o755)).unwrap();
        Shared { dir, daemon }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// A daemon command of `domain` on loopback, without a socket flag.
    fn daemon(&self, domain: &TestDomain) -> Command {
        let mut args = domain.daemon_args("unused");
        let at = args.iter().position(|a| a == "--socket").unwrap();
        args.drain(at..at + 2);
        let mut command = Command::new(&self.daemon);
        command
            .args(args)
            .env_remove("NDDS_SOCKET")
            .env_remove("XDG_RUNTIME_DIR");
        command
    }
}

struct Running(Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn spawn(mut command: Command) -> Running {
    Running(
        command
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start ndds-daemon"),
    )
}

#[test]
fn the_default_socket_is_private_and_the_daemon_knows_its_clients_from_the_kernel() {
    let _turn = turn();
    let domain = TestDomain::new();
    let runtime = domain.path("runtime");
    fs::create_dir(&runtime).unwrap();
    let mut command = Command::new(binary("ndds-daemon"));
    let mut args = domain.daemon_args("unused");
    let at = args.iter().position(|a| a == "--socket").unwrap();
    args.drain(at..at + 2);
    command
        .args(args)
        .env_remove("NDDS_SOCKET")
        .env("XDG_RUNTIME_DIR", &runtime);
    let _daemon = spawn(command);
    let socket = runtime.join(format!("ndds/ndds-{}.sock", domain.domain));
    assert!(
        wait_until(support::WAIT, || is_socket(&socket)).is_some(),
        "no socket at {}",
        socket.display()
    );
    let dir_mode = fs::metadata(runtime.join("ndds")).unwrap().mode() & 0o7777;
    let socket_mode = fs::metadata(&socket).unwrap().mode() & 0o7777;
    assert_eq!((dir_mode, socket_mode), (0o700, 0o660));

    let tool = Participant::builder()
        .socket(&socket)
        .embedded(EmbeddedPolicy::Never)
        .tool()
        .name("local-socket-test")
        .connect()
        .expect("a session with our own daemon");
    let graph = tool.graph().expect("graph");
    let me = graph
        .clients
        .iter()
        .find(|c| c.name == "local-socket-test")
        .expect("this tool among the daemon's clients");
    assert_eq!(me.pid, std::process::id());
    assert_eq!(me.uid, nix::unistd::geteuid().as_raw());
}

#[test]
fn a_squatted_socket_path_is_refused_by_daemon_and_clients() {
    if support::skipped() {
        return;
    }
    let _turn = turn();
    let domain = TestDomain::new();
    let shared = Shared::new();
    let path = shared.path("robot.sock");
    let mut squat = shared.daemon(&domain);
    squat.arg("--socket").arg(&path).uid(SQUATTER).gid(SQUATTER);
    let _squatter = spawn(squat);
    assert!(
        wait_until(support::WAIT, || is_socket(&path)).is_some(),
        "the squatter's daemon did not bind {}",
        path.display()
    );

    // Our daemon: the lock file beside the path is the squatter's.
    let mut ours = shared.daemon(&domain);
    ours.arg("--socket").arg(&path);
    let refused = process::run_command(ours, Duration::from_secs(20));
    assert_ne!(refused.code, Some(0), "{refused:?}");
    assert!(
        refused.stderr.contains(&format!("uid {SQUATTER}")) && refused.stderr.contains("squatting"),
        "the daemon names the squatter: {}",
        refused.stderr
    );

    // Without the lock file, the socket itself is the squatter's.
    fs::remove_file(shared.path("robot.sock.lock")).unwrap();
    let mut ours = shared.daemon(&domain);
    ours.arg("--socket").arg(&path);
    let refused = process::run_command(ours, Duration::from_secs(20));
    assert_ne!(refused.code, Some(0), "{refused:?}");
    assert!(
        refused
            .stderr
            .contains(&format!("{} belongs to uid {SQUATTER}", path.display())),
        "the daemon names the squatted socket and its owner: {}",
        refused.stderr
    );
    assert!(is_socket(&path), "the squatter's socket is left alone");

    // A client (root here) refuses the squatter's daemon before sending anything, whether or
    // not it may start an embedded daemon.
    for policy in [EmbeddedPolicy::Never, EmbeddedPolicy::Auto] {
        match Participant::builder()
            .socket(&path)
            .domain(domain.domain)
            .embedded(policy)
            .name("victim")
            .connect()
        {
            Err(err @ ConnectError::Socket(_)) => {
                let text = err.to_string();
                assert!(text.contains(&format!("runs as uid {SQUATTER}")), "{text}");
            }
            Err(other) => panic!("expected a refused socket, got {other}"),
            Ok(_) => panic!("connected to the squatter's daemon ({policy:?})"),
        }
    }
    let tool = process::run(
        &binary("ndds"),
        &[
            "--socket".into(),
            path.display().to_string(),
            "topics".into(),
        ],
        Duration::from_secs(20),
    );
    assert_ne!(tool.code, Some(0), "{tool:?}");
    assert!(
        tool.stderr.contains(&format!("uid {SQUATTER}")),
        "ndds names the squatter: {}",
        tool.stderr
    );
}

#[test]
fn a_squatted_private_directory_is_refused() {
    if support::skipped() {
        return;
    }
    let _turn = turn();
    let domain = TestDomain::new();
    let shared = Shared::new();
    // The victim's default directory, made first by the squatter.
    let dir = shared.path(&format!("ndds-{VICTIM}"));
    fs::create_dir(&dir).unwrap();
    nix::unistd::chown(
        &dir,
        Some(nix::unistd::Uid::from_raw(SQUATTER)),
        Some(nix::unistd::Gid::from_raw(SQUATTER)),
    )
    .unwrap();
    let mut victim = shared.daemon(&domain);
    victim
        .env("TMPDIR", shared.dir.path())
        .uid(VICTIM)
        .gid(VICTIM);
    let refused = process::run_command(victim, Duration::from_secs(20));
    assert_ne!(refused.code, Some(0), "{refused:?}");
    assert!(
        refused
            .stderr
            .contains(&format!("{} belongs to uid {SQUATTER}", dir.display())),
        "the daemon names the squatted directory and its owner: {}",
        refused.stderr
    );
    assert!(
        fs::read_dir(&dir).unwrap().next().is_none(),
        "nothing was created in the squatter's directory"
    );

    // The same user in a clean directory gets its private one.
    fs::remove_dir(&dir).unwrap();
    let mut victim = shared.daemon(&domain);
    victim
        .env("TMPDIR", shared.dir.path())
        .uid(VICTIM)
        .gid(VICTIM);
    let _daemon = spawn(victim);
    let socket = dir.join(format!("ndds-{}.sock", domain.domain));
    assert!(
        wait_until(support::WAIT, || is_socket(&socket)).is_some(),
        "no socket at {}",
        socket.display()
    );
    let meta = fs::metadata(&dir).unwrap();
    assert_eq!((meta.uid(), meta.mode() & 0o7777), (VICTIM, 0o700));
}

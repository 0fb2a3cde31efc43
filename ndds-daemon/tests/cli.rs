//! The `ndds-daemon` binary: flags, config file, errors, stale sockets, shutdown.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use ndds_core::ipc::{self, ClientMessage, DaemonMessage, Graph, Hello, IPC_VERSION, Role};

const DAEMON: &str = env!("CARGO_BIN_EXE_ndds-daemon");
const WAIT: Duration = Duration::from_secs(10);

fn run(args: &[&str]) -> Output {
    Command::new(DAEMON)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run ndds-daemon")
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Flags that keep a test daemon to itself: its own ports and group, on loopback.
fn isolated(dir: &Path) -> Vec<String> {
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

fn spawn(args: &[String]) -> Child {
    Command::new(DAEMON)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start ndds-daemon")
}

fn connect(socket: &Path) -> UnixStream {
    let deadline = Instant::now() + WAIT;
    loop {
        match UnixStream::connect(socket) {
            Ok(stream) => return stream,
            Err(err) if Instant::now() > deadline => panic!("daemon never listened: {err}"),
            Err(_) => std::thread::sleep(Duration::from_millis(10)),
        }
    }
}

fn read_frame(stream: &mut UnixStream) -> DaemonMessage {
    let mut prefix = [0u8; 4];
    stream.read_exact(&mut prefix).expect("frame length");
    let mut body = vec![0u8; u32::from_be_bytes(prefix) as usize];
    stream.read_exact(&mut body).expect("frame body");
    ipc::decode_body(&body).expect("frame decodes")
}

/// Opens a tool session by hand and asks for the graph.
fn graph(socket: &Path) -> Graph {
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
    let query = ClientMessage::QueryGraph { request: 1 };
    stream
        .write_all(&ipc::encode_frame(&query).unwrap())
        .unwrap();
    match read_frame(&mut stream) {
        DaemonMessage::Graph { request: 1, graph } => graph,
        other => panic!("unexpected answer {other:?}"),
    }
}

fn terminate(child: &mut Child) -> Option<i32> {
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

#[test]
fn help_documents_the_interface_default() {
    let out = run(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for expected in [
        "--interface",
        "127.0.0.1",
        "--config",
        "NDDS_DOMAIN",
        "NDDS_SOCKET",
    ] {
        assert!(text.contains(expected), "--help lacks {expected}:\n{text}");
    }
}

#[test]
fn bad_settings_are_refused_with_a_precise_message() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("bad.toml");
    std::fs::write(&config, "domain = 3\nlease_msec = 9000\n").unwrap();
    let out = run(&["--config", config.to_str().unwrap()]);
    assert!(!out.status.success());
    let text = stderr(&out);
    assert!(
        text.contains("bad.toml") && text.contains("lease_msec") && text.contains("line 2"),
        "{text}"
    );

    let out = run(&["--interface", "no-such-nic9"]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("no-such-nic9") && stderr(&out).contains("lo 127.0.0.1"),
        "{}",
        stderr(&out)
    );

    let out = run(&["--domain", "500"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("out of range"), "{}", stderr(&out));

    let out = run(&["--announce-period-ms", "2000", "--lease-ms", "1000"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("lease"), "{}", stderr(&out));
}

#[test]
fn config_file_settings_apply_and_flags_override_them() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = isolated(dir.path());
    let config = dir.path().join("daemon.toml");
    std::fs::write(
        &config,
        "domain = 12\nannounce_period_ms = 300\nlease_ms = 2000\nsocket = \"/nonexistent/overridden.sock\"\n",
    )
    .unwrap();
    args.extend(["--config".into(), config.display().to_string()]);
    args.extend(["--lease-ms".into(), "2500".into()]);
    let mut daemon = spawn(&args);
    let graph = graph(&dir.path().join("d.sock"));
    assert_eq!(graph.local.info.announce_period_ms, 300, "from the file");
    assert_eq!(graph.local.info.lease_ms, 2500, "the flag wins");
    assert_eq!(graph.local.interface, [127, 0, 0, 1]);
    assert_eq!(terminate(&mut daemon), Some(0));
}

#[test]
fn a_stale_socket_file_is_replaced_and_removed_on_exit() {
    let dir = tempfile::tempdir().unwrap();
    let socket = dir.path().join("d.sock");
    // A socket file nobody listens on, as a crashed daemon leaves behind.
    drop(std::os::unix::net::UnixListener::bind(&socket).unwrap());
    assert!(socket.exists());
    let mut daemon = spawn(&isolated(dir.path()));
    let graph = graph(&socket);
    assert!(graph.nodes.is_empty());
    assert_eq!(terminate(&mut daemon), Some(0));
    assert!(!socket.exists(), "socket removed on exit");
    let mut log = String::new();
    daemon
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut log)
        .unwrap();
    assert!(log.contains("removing stale daemon socket"), "{log}");
    assert!(log.contains("SIGTERM"), "{log}");
}

#[test]
fn a_socket_path_that_is_not_a_socket_is_left_alone() {
    let dir = tempfile::tempdir().unwrap();
    let notes = dir.path().join("d.sock");
    std::fs::write(&notes, "precious").unwrap();
    let out = Command::new(DAEMON)
        .args(isolated(dir.path()))
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("is not a socket"), "{}", stderr(&out));
    assert_eq!(std::fs::read_to_string(&notes).unwrap(), "precious");
}

#[test]
fn frames_queued_behind_a_refusal_open_no_session() {
    let dir = tempfile::tempdir().unwrap();
    let mut daemon = spawn(&isolated(dir.path()));
    let socket = dir.path().join("d.sock");
    let hello = |participant| {
        ipc::encode_frame(&ClientMessage::Hello(Hello {
            ipc_version: IPC_VERSION,
            participant,
            pid: std::process::id(),
            name: "refusal-test".into(),
            role: Role::Client,
        }))
        .unwrap()
    };
    // A query before Hello is refused; the Hello written right behind it must not count.
    let mut stream = connect(&socket);
    stream.set_read_timeout(Some(WAIT)).unwrap();
    let mut bytes = ipc::encode_frame(&ClientMessage::QueryGraph { request: 1 }).unwrap();
    bytes.extend(hello(77));
    stream.write_all(&bytes).unwrap();
    assert!(matches!(
        read_frame(&mut stream),
        DaemonMessage::Refused { .. }
    ));
    // The same participant id is free for a proper session.
    let mut again = connect(&socket);
    again.set_read_timeout(Some(WAIT)).unwrap();
    again.write_all(&hello(77)).unwrap();
    assert!(
        matches!(read_frame(&mut again), DaemonMessage::Welcome(_)),
        "participant 77 was not left registered by the refused connection"
    );
    assert_eq!(terminate(&mut daemon), Some(0));
}

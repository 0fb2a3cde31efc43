//! The `ndds-daemon` binary: flags, config file, errors, stale sockets, shutdown.

mod common;

use std::io::{Read, Write};
use std::process::{Command, Stdio};

use ndds_core::ipc::{self, ClientMessage, DaemonMessage, Hello, IPC_VERSION, Role};

use common::*;

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
        "--peers",
        "--no-multicast",
        "7850 + DOMAIN",
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
    let mut bytes = ipc::encode_frame(&ClientMessage::QueryGraph {
        request: 1,
        after: None,
    })
    .unwrap();
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

#[test]
fn a_daemon_whose_stderr_reader_is_gone_still_stops_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let mut daemon = spawn(&isolated(dir.path()));
    let socket = dir.path().join("d.sock");
    drop(connect(&socket));
    // The parent that read its log went away: every later log line fails to write.
    drop(daemon.stderr.take());
    assert_eq!(
        terminate(&mut daemon),
        Some(0),
        "no panic on a closed stderr"
    );
    assert!(!socket.exists(), "socket removed on exit");
}

//! The daemons this process embeds: started on demand by [`crate::Participant::connect`] when
//! no daemon answers on the socket (or later, to take the role over from a process that
//! exited), kept for the life of the process (so other processes on the host can keep using
//! them), and stopped explicitly with [`stop_embedded_daemons`] or when the process exits.
//!
//! **At exit.** The first embedded daemon registers an exit hook (`atexit`) that stops every
//! embedded daemon when the process ends normally (`main` returns, or `std::process::exit`):
//! each says goodbye to the domain and removes its socket file. A hook, and not the drop of the
//! last participant, because the daemon serves the other processes of the host too: stopping it
//! while this process still runs would take it from them for nothing, and a program may exit
//! with participants still alive (held in a static, or `process::exit` from anywhere), which no
//! drop would see. A process killed by a signal runs no hook: its socket file stays, and the
//! next daemon (or a survivor taking the role over) removes it as stale.

use std::path::{Path, PathBuf};
use std::sync::Once;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use ndds_daemon::{DaemonConfig, DaemonError, EmbedError, EmbeddedDaemon};

use crate::error::ConnectError;
use crate::sync::lock;

/// Embedded daemons of this process, by socket path.
static EMBEDDED: std::sync::Mutex<Vec<(PathBuf, EmbeddedDaemon, Instant)>> =
    std::sync::Mutex::new(Vec::new());

/// Set by the exit hook: the process is ending, no daemon may start any more (participants
/// whose session ends with it must not take the role over on their way out).
static EXITING: AtomicBool = AtomicBool::new(false);

/// Registers [`at_exit`] once.
static EXIT_HOOK: Once = Once::new();

/// Whether a daemon served the path, as [`ensure`] found it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Ensured {
    /// One of this process's embedded daemons serves it (found, or started now).
    Ours,
    /// Another process's daemon claimed the path meanwhile (it may still be starting).
    Theirs,
}

/// Makes sure a daemon serves `config.socket`: one of ours (found or started now), or one
/// another process started meanwhile.
pub(crate) fn ensure(config: &DaemonConfig) -> Result<Ensured, ConnectError> {
    let mut daemons = lock(&EMBEDDED);
    if EXITING.load(Ordering::Acquire) {
        return Err(ConnectError::Exiting);
    }
    // A daemon whose thread ended (it failed) no longer serves its path.
    daemons.retain(|(_, daemon, _)| daemon.is_running());
    if daemons.iter().any(|(path, _, _)| *path == config.socket) {
        return Ok(Ensured::Ours);
    }
    match EmbeddedDaemon::start(config.clone()) {
        Ok(daemon) => {
            tracing::info!(
                socket = %config.socket.display(),
                interface = %config.interface,
                "started an embedded ndds daemon"
            );
            daemons.push((config.socket.clone(), daemon, Instant::now()));
            EXIT_HOOK.call_once(register_exit_hook);
            Ok(Ensured::Ours)
        }
        Err(EmbedError::Daemon(DaemonError::AlreadyRunning { .. })) => Ok(Ensured::Theirs),
        Err(err) => Err(err.into()),
    }
}

fn register_exit_hook() {
    // SAFETY: `at_exit` is a plain `extern "C" fn()` with no captured state; atexit only
    // stores the pointer. A failure (out of slots) leaves the hook unregistered, as before.
    let registered = unsafe { libc::atexit(at_exit) };
    if registered != 0 {
        tracing::debug!("cannot register the embedded daemon's exit hook");
    }
}

/// Stops the embedded daemons when the process exits normally (see the module docs).
extern "C" fn at_exit() {
    // Unwinding out of an `extern "C"` function aborts: never let a panic escape.
    let _ = std::panic::catch_unwind(|| {
        EXITING.store(true, Ordering::Release);
        stop_embedded_daemons();
    });
}

/// Stops the embedded daemon serving `socket`, if this process runs one: it says goodbye to
/// the domain and removes its socket. Sessions of participants on it end (their samples keep
/// flowing to the peers they know; a participant of another process that may embed takes the
/// role over). Returns whether one was stopped.
pub fn stop_embedded_daemon(socket: &Path) -> bool {
    let mut daemons = lock(&EMBEDDED);
    let Some(index) = daemons.iter().position(|(path, _, _)| path == socket) else {
        return false;
    };
    // Stopped while the registry is locked, so a concurrent connect waits for the socket to
    // be free instead of meeting the dying daemon.
    let (_, mut daemon, _) = daemons.remove(index);
    daemon.stop();
    true
}

/// Stops every embedded daemon of this process (see [`stop_embedded_daemon`]). The process's
/// exit does it too; call it earlier to hand the role over while the process keeps running.
/// Returns how many were stopped.
pub fn stop_embedded_daemons() -> usize {
    let mut daemons = lock(&EMBEDDED);
    let stopped = daemons.len();
    for (_, mut daemon, _) in daemons.drain(..) {
        daemon.stop();
    }
    stopped
}

/// How long a newly started embedded daemon takes to hear the domain: its first two
/// solicitations (at 0 and 200 ms) and the answers (jittered by at most 10 ms).
pub(crate) const FIRST_HEARING: Duration = Duration::from_millis(300);

/// Waits, if this process started the daemon serving `socket` less than [`FIRST_HEARING`]
/// ago, until that time has passed, so that its view of the domain includes the other
/// hosts' endpoints (a name that must be unique in the domain is then checked against them).
pub(crate) fn wait_first_hearing(socket: &Path) {
    let started = lock(&EMBEDDED)
        .iter()
        .find(|(path, _, _)| path == socket)
        .map(|(_, _, started)| *started);
    if let Some(started) = started {
        std::thread::sleep((started + FIRST_HEARING).saturating_duration_since(Instant::now()));
    }
}

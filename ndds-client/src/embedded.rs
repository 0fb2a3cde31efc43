//! The daemons this process embeds: started on demand by [`crate::Participant::connect`] when
//! no daemon answers on the socket, kept for the life of the process (so other processes on
//! the host can keep using them), and stopped explicitly with [`stop_embedded_daemons`].

use std::path::{Path, PathBuf};

use ndds_daemon::{DaemonConfig, DaemonError, EmbedError, EmbeddedDaemon};

use crate::error::ConnectError;
use crate::sync::lock;

/// Embedded daemons of this process, by socket path.
static EMBEDDED: std::sync::Mutex<Vec<(PathBuf, EmbeddedDaemon)>> =
    std::sync::Mutex::new(Vec::new());

/// Makes sure a daemon serves `config.socket`: one of ours (found or started now), or one
/// another process started meanwhile. Returns false only in that last case.
pub(crate) fn ensure(config: &DaemonConfig) -> Result<bool, ConnectError> {
    let mut daemons = lock(&EMBEDDED);
    // A daemon whose thread ended (it failed) no longer serves its path.
    daemons.retain(|(_, daemon)| daemon.is_running());
    if daemons.iter().any(|(path, _)| *path == config.socket) {
        return Ok(true);
    }
    match EmbeddedDaemon::start(config.clone()) {
        Ok(daemon) => {
            tracing::info!(
                socket = %config.socket.display(),
                interface = %config.interface,
                "started an embedded ndds daemon"
            );
            daemons.push((config.socket.clone(), daemon));
            Ok(true)
        }
        Err(EmbedError::Daemon(DaemonError::AlreadyRunning { .. })) => Ok(false),
        Err(err) => Err(err.into()),
    }
}

/// Stops the embedded daemon serving `socket`, if this process runs one: it says goodbye to
/// the domain and removes its socket. Sessions of participants on it end (their samples keep
/// flowing to the peers they know). Returns whether one was stopped.
pub fn stop_embedded_daemon(socket: &Path) -> bool {
    let mut daemons = lock(&EMBEDDED);
    let Some(index) = daemons.iter().position(|(path, _)| path == socket) else {
        return false;
    };
    // Stopped while the registry is locked, so a concurrent connect waits for the socket to
    // be free instead of meeting the dying daemon.
    let (_, mut daemon) = daemons.remove(index);
    daemon.stop();
    true
}

/// Stops every embedded daemon of this process (see [`stop_embedded_daemon`]); call it before
/// a program that embeds a daemon exits, so the domain hears its goodbye at once. Returns how
/// many were stopped.
pub fn stop_embedded_daemons() -> usize {
    let mut daemons = lock(&EMBEDDED);
    let stopped = daemons.len();
    for (_, mut daemon) in daemons.drain(..) {
        daemon.stop();
    }
    stopped
}

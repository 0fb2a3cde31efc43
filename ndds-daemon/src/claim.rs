//! Claiming the Unix socket path: at most one daemon per path, decided by a lock.
//!
//! Two processes may start a daemon on one path at the same moment (two survivors of a process
//! that embedded the daemon, each taking its role over). Probing a socket file and removing it
//! when nobody answers is not atomic: the loser of such a race would unlink the winner's fresh
//! socket and bind its own, leaving two daemons. So a daemon first takes an exclusive, non-
//! blocking `flock` on `<socket>.lock` and holds it for its whole life:
//!
//! | lock | daemon answering on the socket | outcome |
//! |---|---|---|
//! | held by another process | (any) | [`DaemonError::AlreadyRunning`], with the pid written in the lock file |
//! | taken | yes (a daemon that does not lock) | [`DaemonError::AlreadyRunning`] |
//! | taken | no, a socket file is there | stale (its daemon died): removed, then bound |
//! | taken | no file | bound |
//!
//! The kernel releases the lock when its process dies, however it dies, so a crashed daemon
//! never blocks its successor. The lock file itself stays: removing it would reopen the race
//! (a third process could lock a new file while the second still holds the old one).
//!
//! The claim is made before any UDP socket is opened, so a second daemon is refused before it
//! touches (or logs about) the discovery ports.
//!
//! Files of another user are never used, probed or removed: a lock file or socket at the path
//! that belongs to someone else is a squatter's, refused with its owner named
//! ([`crate::local::LocalError::Squatted`]). The socket is bound in a private (0700) directory
//! of its own, given its mode (0660) and group there, then renamed into place, so nobody can
//! connect before it is restricted, whatever the umask.

use std::fs::File;
use std::io::{Read as _, Seek as _, Write as _};
use std::os::fd::AsRawFd as _;
use std::os::unix::fs::{
    DirBuilderExt as _, FileTypeExt as _, MetadataExt as _, OpenOptionsExt as _,
};
use std::path::{Path, PathBuf};

use tokio::net::UnixListener;

use crate::daemon::DaemonError;
use crate::local;

/// The socket path, owned by this daemon until dropped; dropping it removes the socket file
/// (if it is still the one bound here) and releases the lock.
#[derive(Debug)]
pub struct SocketClaim {
    path: PathBuf,
    inode: Option<u64>,
    /// Holds the `flock` while open.
    _lock: File,
}

impl SocketClaim {
    /// Claims `path` and binds a listener on it, reachable by this user and `group`. Must be
    /// called inside a tokio runtime.
    pub fn take(
        path: &Path,
        group: Option<u32>,
    ) -> Result<(SocketClaim, UnixListener), DaemonError> {
        let listen_err = |source| DaemonError::Listen {
            path: path.to_owned(),
            source,
        };
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            // The default directories are the daemon's own; a chosen path's may be shared.
            let private = parent == local::socket_dir() || parent == Path::new(local::SYSTEM_DIR);
            local::prepare_dir(parent, group, private)?;
        }
        let lock = lock(path)?;
        if let Ok(meta) = std::fs::symlink_metadata(path) {
            local::owned_by_me(path, meta.uid())?;
        }
        if std::os::unix::net::UnixStream::connect(path).is_ok() {
            return Err(DaemonError::AlreadyRunning {
                path: path.to_owned(),
                pid: None,
            });
        }
        match std::fs::symlink_metadata(path) {
            Ok(meta) if meta.file_type().is_socket() => {
                tracing::info!(path = %path.display(), "removing stale daemon socket");
                std::fs::remove_file(path).map_err(listen_err)?;
            }
            Ok(_) => {
                return Err(DaemonError::NotASocket {
                    path: path.to_owned(),
                });
            }
            Err(_) => {}
        }
        let listener = bind(path, group)?;
        let inode = std::fs::metadata(path).ok().map(|m| m.ino());
        let claim = SocketClaim {
            path: path.to_owned(),
            inode,
            _lock: lock,
        };
        Ok((claim, listener))
    }

    /// The claimed path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for SocketClaim {
    fn drop(&mut self) {
        // Only our own file: a successor may already have bound a new one at the path.
        let current = std::fs::metadata(&self.path).ok().map(|m| m.ino());
        if current.is_some() && current == self.inode {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Binds in a private (0700) directory of its own beside `path`, gives the socket its mode and
/// group there, then renames it to `path`: nobody can connect before it is restricted, whatever
/// the umask.
fn bind(path: &Path, group: Option<u32>) -> Result<UnixListener, DaemonError> {
    let mut name = path.as_os_str().to_owned();
    name.push(format!(".{}.bind", std::process::id()));
    let private = PathBuf::from(name);
    let failed = |path: &Path| {
        let path = path.to_owned();
        move |source| DaemonError::Listen { path, source }
    };
    // Left over by a daemon of this pid that died: ours to remove.
    if let Ok(meta) = std::fs::symlink_metadata(&private) {
        local::owned_by_me(&private, meta.uid())?;
        let _ = std::fs::remove_dir_all(&private);
    }
    std::fs::DirBuilder::new()
        .mode(0o700)
        .create(&private)
        .map_err(failed(&private))?;
    let fresh = private.join("socket");
    let placed = UnixListener::bind(&fresh)
        .map_err(failed(&fresh))
        .and_then(|listener| {
            local::restrict_socket(&fresh, group)?;
            std::fs::rename(&fresh, path).map_err(failed(path))?;
            Ok(listener)
        });
    let _ = std::fs::remove_dir_all(&private);
    placed
}

/// The lock file of a socket path.
pub fn lock_path(socket: &Path) -> PathBuf {
    let mut name = socket.as_os_str().to_owned();
    name.push(".lock");
    PathBuf::from(name)
}

/// Takes the exclusive lock of `socket`'s lock file and writes this process's pid in it;
/// refuses with the holder's pid if another process holds it.
fn lock(socket: &Path) -> Result<File, DaemonError> {
    let path = lock_path(socket);
    let failed = |source| DaemonError::Listen {
        path: path.clone(),
        source,
    };
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&path)
        .map_err(failed)?;
    let meta = file.metadata().map_err(failed)?;
    local::owned_by_me(&path, meta.uid())?;
    // A hard link to some other file of ours would be truncated below.
    if !meta.file_type().is_file() || meta.nlink() != 1 {
        return Err(DaemonError::BadLockFile { path: path.clone() });
    }
    // SAFETY: flock on a file descriptor this function owns; no memory is shared.
    let locked = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
    if locked != 0 {
        let err = std::io::Error::last_os_error();
        if err.kind() != std::io::ErrorKind::WouldBlock {
            return Err(failed(err));
        }
        let mut text = String::new();
        let _ = file.read_to_string(&mut text);
        return Err(DaemonError::AlreadyRunning {
            path: socket.to_owned(),
            pid: text.trim().parse().ok(),
        });
    }
    let written = file
        .set_len(0)
        .and_then(|()| file.rewind())
        .and_then(|()| writeln!(file, "{}", std::process::id()));
    written.map_err(failed)?;
    Ok(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_held_claim_refuses_a_second_one_with_the_holder_pid() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.sock");
        let (first, _listener) = SocketClaim::take(&path, None).unwrap();
        match SocketClaim::take(&path, None) {
            Err(DaemonError::AlreadyRunning { pid, .. }) => {
                assert_eq!(pid, Some(std::process::id()));
            }
            other => panic!("expected AlreadyRunning, got {other:?}"),
        }
        drop(first);
        assert!(!path.exists(), "the socket goes with the claim");
        let (_again, _listener) = SocketClaim::take(&path, None).expect("free again");
    }

    #[tokio::test]
    async fn a_stale_socket_file_is_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.sock");
        drop(std::os::unix::net::UnixListener::bind(&path).unwrap());
        assert!(path.exists());
        let (_claim, _listener) = SocketClaim::take(&path, None).expect("stale file replaced");
        assert!(std::os::unix::net::UnixStream::connect(&path).is_ok());
    }
}

//! The local socket: where it lives, who may connect, and who is at the other end.
//!
//! **Where.** A domain's socket is `ndds-<domain>.sock` in the first of:
//!
//! | who runs the daemon | directory | mode |
//! |---|---|---|
//! | anyone, with `XDG_RUNTIME_DIR` set | `$XDG_RUNTIME_DIR/ndds/` | 0700 (0710 with a group) |
//! | root, without it (a system service) | `/run/ndds/` | 0700 (0710 with a group) |
//! | anyone else | `$TMPDIR/ndds-<uid>/` (usually `/tmp`) | 0700 (0710 with a group) |
//!
//! A client looks in its own directory first, then in `/run/ndds/`, so that the programs of
//! every user reach a system daemon whose group they are in. `--socket` / `NDDS_SOCKET` name any
//! other path.
//!
//! **Who may connect.** The socket is made 0660: its owner and, with `--socket-group`, the
//! members of that group. The directory is created private; one that exists already must
//! belong to the daemon's user and be writable by nobody else, and a socket or lock file at the
//! path that belongs to another user is refused, with its owner named ([`LocalError`]): a user
//! who binds the path first (a *squatter*) would otherwise receive every client.
//!
//! **Who is at the other end.** Both ends ask the kernel (`SO_PEERCRED`, [`peer_cred`]): the
//! daemon records each client's uid and pid from the kernel, never from its `Hello`; a client
//! refuses a daemon run by another user unless it is root ([`check_daemon`]).
//!
//! **How much.** At most [`MAX_CLIENTS`] connections at once; frames are bounded by
//! [`ndds_core::ipc::MAX_FRAME`] and a frame's buffer grows with the bytes that arrive, not
//! with the length its prefix claims.

use std::fs::{self, DirBuilder};
use std::io;
use std::os::fd::AsFd;
use std::os::unix::fs::{DirBuilderExt as _, MetadataExt as _, PermissionsExt as _};
use std::path::{Path, PathBuf};

use ndds_core::domain;
use nix::unistd::{Gid, Group, Uid, User};

/// Mode of the socket file: owner and group read and write (connect), others nothing.
pub const SOCKET_MODE: u32 = 0o660;
/// Mode of the socket directory the daemon creates.
pub const DIR_MODE: u32 = 0o700;
/// Mode of the socket directory when a group may use the socket (search, not list or write).
pub const GROUP_DIR_MODE: u32 = 0o710;
/// Where a system daemon (root, no runtime directory) puts its socket.
pub const SYSTEM_DIR: &str = "/run/ndds";
/// Connections a daemon serves at once; more are closed at once and counted.
pub const MAX_CLIENTS: usize = 512;

/// A socket path or directory that cannot be used safely.
#[derive(Debug, thiserror::Error)]
pub enum LocalError {
    /// Another user owns the path: it may be a squatter waiting for clients.
    #[error(
        "{path} belongs to {owner}, not to {me}: another user may be squatting the daemon's \
         socket; remove it (as root or its owner) or choose another --socket path"
    )]
    Squatted {
        /// The file or directory.
        path: PathBuf,
        /// Its owner, `uid N (name)`.
        owner: String,
        /// This process's user.
        me: String,
    },
    /// The directory is writable by others, who could replace the socket.
    #[error(
        "{path} is writable by other users (mode {mode:o}), who could replace the socket; \
         make it private (chmod 700) or choose another --socket path"
    )]
    Shared {
        /// The directory.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
    },
    /// Not a directory (or a symbolic link where a directory was expected).
    #[error("{path} is not a directory: remove it or choose another --socket path")]
    NotADirectory {
        /// The path.
        path: PathBuf,
    },
    /// `--socket-group` names no group.
    #[error("socket group {0:?} does not exist (create it with `groupadd`, or leave it out)")]
    UnknownGroup(String),
    /// The daemon at the other end runs as another user (and not as root).
    #[error(
        "the daemon at {path} runs as {owner}; a client talks only to a daemon of its own user \
         ({me}) or of root (another user may be squatting the socket path)"
    )]
    ForeignDaemon {
        /// The socket path.
        path: PathBuf,
        /// The daemon's user.
        owner: String,
        /// This process's user.
        me: String,
    },
    /// A file-system or socket operation failed.
    #[error("{path}: {source}")]
    Io {
        /// What it was done on.
        path: PathBuf,
        /// The OS error.
        source: io::Error,
    },
}

impl LocalError {
    fn io(path: &Path) -> impl FnOnce(io::Error) -> LocalError + '_ {
        move |source| LocalError::Io {
            path: path.to_owned(),
            source,
        }
    }
}

/// The kernel's word on the process at the other end of a Unix socket.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PeerCred {
    /// Effective user id.
    pub uid: u32,
    /// Effective group id.
    pub gid: u32,
    /// Process id (in this process's pid namespace; 0 when it has none there).
    pub pid: u32,
}

/// Asks the kernel who is at the other end of `socket` (`SO_PEERCRED`).
pub fn peer_cred(socket: &impl AsFd) -> io::Result<PeerCred> {
    let cred = nix::sys::socket::getsockopt(socket, nix::sys::socket::sockopt::PeerCredentials)
        .map_err(io::Error::from)?;
    Ok(PeerCred {
        uid: cred.uid(),
        gid: cred.gid(),
        pid: u32::try_from(cred.pid()).unwrap_or(0),
    })
}

/// `uid N (name)`, or `uid N` for a uid without an account.
pub fn describe_user(uid: u32) -> String {
    match User::from_uid(Uid::from_raw(uid)) {
        Ok(Some(user)) => format!("uid {uid} ({})", user.name),
        _ => format!("uid {uid}"),
    }
}

fn me() -> String {
    describe_user(Uid::effective().as_raw())
}

/// The directory of this user's default socket (see the module documentation).
pub fn socket_dir() -> PathBuf {
    let runtime = std::env::var_os("XDG_RUNTIME_DIR")
        .map(PathBuf::from)
        .filter(|dir| dir.is_absolute());
    match runtime {
        Some(dir) => dir.join("ndds"),
        None if Uid::effective().is_root() => PathBuf::from(SYSTEM_DIR),
        None => std::env::temp_dir().join(format!("ndds-{}", Uid::effective())),
    }
}

/// Where this user's daemon of `domain` listens by default.
pub fn default_socket(domain: u16) -> PathBuf {
    socket_dir().join(domain::socket_name(domain))
}

/// Where a client of `domain` finds its daemon: this user's default socket if a socket is
/// there, else the system daemon's if one answers there, else this user's default (where an
/// embedded daemon will listen). A system socket left by a daemon that died is passed over.
pub fn locate(domain: u16) -> PathBuf {
    let own = default_socket(domain);
    let system = Path::new(SYSTEM_DIR).join(domain::socket_name(domain));
    if !is_socket(&own) && std::os::unix::net::UnixStream::connect(&system).is_ok() {
        return system;
    }
    own
}

fn is_socket(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt as _;
    fs::symlink_metadata(path).is_ok_and(|meta| meta.file_type().is_socket())
}

/// Resolves a group name for `--socket-group`.
pub fn group(name: &str) -> Result<u32, LocalError> {
    match Group::from_name(name) {
        Ok(Some(group)) => Ok(group.gid.as_raw()),
        _ => Err(LocalError::UnknownGroup(name.to_owned())),
    }
}

/// Makes `dir` ready to hold a socket: created private if missing; if present, it must be a
/// directory of this user that nobody else can write. With `group`, the group may search it.
///
/// `private` is false for the parent of a `--socket` path the user chose: there, a directory
/// shared with a sticky bit (`/tmp`) or one of this user or root is accepted and left as it
/// is; one another user owns is refused (that user could replace the socket in it).
pub fn prepare_dir(dir: &Path, group: Option<u32>, private: bool) -> Result<(), LocalError> {
    if !dir.exists() {
        if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
            fs::create_dir_all(parent).map_err(LocalError::io(parent))?;
        }
        match DirBuilder::new().mode(DIR_MODE).create(dir) {
            Ok(()) => {}
            // Another daemon made it meanwhile: checked below like any existing directory.
            Err(err) if err.kind() == io::ErrorKind::AlreadyExists => {}
            Err(err) => return Err(LocalError::io(dir)(err)),
        }
    }
    let meta = fs::symlink_metadata(dir).map_err(LocalError::io(dir))?;
    if !meta.file_type().is_dir() {
        return Err(LocalError::NotADirectory {
            path: dir.to_owned(),
        });
    }
    let mode = meta.mode() & 0o7777;
    if !private {
        let shared = mode & 0o022 != 0;
        let sticky = mode & 0o1000 != 0;
        if shared && !sticky {
            return Err(LocalError::Shared {
                path: dir.to_owned(),
                mode,
            });
        }
        if !sticky && meta.uid() != 0 {
            owned_by_me(dir, meta.uid())?;
        }
        return Ok(());
    }
    owned_by_me(dir, meta.uid())?;
    if mode & 0o022 != 0 {
        return Err(LocalError::Shared {
            path: dir.to_owned(),
            mode,
        });
    }
    let wanted = if group.is_some() {
        GROUP_DIR_MODE
    } else {
        DIR_MODE
    };
    if let Some(gid) = group {
        nix::unistd::chown(dir, None, Some(Gid::from_raw(gid)))
            .map_err(|err| LocalError::io(dir)(err.into()))?;
    }
    if mode != wanted {
        fs::set_permissions(dir, fs::Permissions::from_mode(wanted))
            .map_err(LocalError::io(dir))?;
    }
    Ok(())
}

/// Refuses a file or directory that another user owns.
pub fn owned_by_me(path: &Path, owner: u32) -> Result<(), LocalError> {
    if owner == Uid::effective().as_raw() {
        return Ok(());
    }
    Err(LocalError::Squatted {
        path: path.to_owned(),
        owner: describe_user(owner),
        me: me(),
    })
}

/// Gives a freshly bound socket file its mode and group.
pub fn restrict_socket(path: &Path, group: Option<u32>) -> Result<(), LocalError> {
    if let Some(gid) = group {
        nix::unistd::chown(path, None, Some(Gid::from_raw(gid)))
            .map_err(|err| LocalError::io(path)(err.into()))?;
    }
    fs::set_permissions(path, fs::Permissions::from_mode(SOCKET_MODE)).map_err(LocalError::io(path))
}

/// The client's check of the daemon at `path`: run by this user or by root.
pub fn check_daemon(path: &Path, daemon: PeerCred) -> Result<(), LocalError> {
    let mine = Uid::effective().as_raw();
    if daemon.uid == mine || daemon.uid == 0 {
        return Ok(());
    }
    Err(LocalError::ForeignDaemon {
        path: path.to_owned(),
        owner: describe_user(daemon.uid),
        me: me(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_directory_is_created_private() {
        let base = tempfile::tempdir().unwrap();
        let dir = base.path().join("a/ndds");
        prepare_dir(&dir, None, true).unwrap();
        let mode = fs::metadata(&dir).unwrap().mode() & 0o7777;
        assert_eq!(mode, DIR_MODE);
    }

    #[test]
    fn a_directory_writable_by_others_is_refused() {
        let base = tempfile::tempdir().unwrap();
        let dir = base.path().join("ndds");
        fs::create_dir(&dir).unwrap();
        fs::set_permissions(&dir, fs::Permissions::from_mode(0o777)).unwrap();
        match prepare_dir(&dir, None, true) {
            Err(LocalError::Shared { mode, .. }) => assert_eq!(mode, 0o777),
            other => panic!("expected Shared, got {other:?}"),
        }
        // The parent of a chosen path may be shared if it is sticky, like /tmp.
        fs::set_permissions(&dir, fs::Permissions::from_mode(0o1777)).unwrap();
        prepare_dir(&dir, None, false).unwrap();
        fs::set_permissions(&dir, fs::Permissions::from_mode(0o777)).unwrap();
        assert!(matches!(
            prepare_dir(&dir, None, false),
            Err(LocalError::Shared { .. })
        ));
    }

    #[test]
    fn a_chosen_directory_of_another_user_is_refused() {
        // Root can hand the directory to another user; others cannot make this case.
        if !Uid::effective().is_root() {
            return;
        }
        let base = tempfile::tempdir().unwrap();
        let dir = base.path().join("theirs");
        fs::create_dir(&dir).unwrap();
        fs::set_permissions(&dir, fs::Permissions::from_mode(0o755)).unwrap();
        nix::unistd::chown(&dir, Some(Uid::from_raw(4242)), None).unwrap();
        match prepare_dir(&dir, None, false) {
            Err(err @ LocalError::Squatted { .. }) => {
                assert!(err.to_string().contains("uid 4242"), "{err}");
            }
            other => panic!("expected Squatted, got {other:?}"),
        }
        // Root's own directories (/run) and sticky shared ones (/tmp) are fine.
        nix::unistd::chown(&dir, Some(Uid::from_raw(0)), None).unwrap();
        prepare_dir(&dir, None, false).unwrap();
        nix::unistd::chown(&dir, Some(Uid::from_raw(4242)), None).unwrap();
        fs::set_permissions(&dir, fs::Permissions::from_mode(0o1777)).unwrap();
        prepare_dir(&dir, None, false).unwrap();
    }

    #[test]
    fn a_file_where_the_directory_goes_is_refused() {
        let base = tempfile::tempdir().unwrap();
        let dir = base.path().join("ndds");
        fs::write(&dir, b"x").unwrap();
        assert!(matches!(
            prepare_dir(&dir, None, true),
            Err(LocalError::NotADirectory { .. })
        ));
    }

    #[test]
    fn a_loose_private_directory_is_tightened() {
        let base = tempfile::tempdir().unwrap();
        let dir = base.path().join("ndds");
        fs::create_dir(&dir).unwrap();
        fs::set_permissions(&dir, fs::Permissions::from_mode(0o755)).unwrap();
        prepare_dir(&dir, None, true).unwrap();
        assert_eq!(fs::metadata(&dir).unwrap().mode() & 0o7777, DIR_MODE);
    }

    #[test]
    fn the_daemon_of_another_user_is_refused_unless_root() {
        let path = Path::new("/x.sock");
        let me = Uid::effective().as_raw();
        let cred = |uid| PeerCred {
            uid,
            gid: 0,
            pid: 1,
        };
        check_daemon(path, cred(me)).unwrap();
        check_daemon(path, cred(0)).unwrap();
        let other = if me == 4242 { 4243 } else { 4242 };
        match check_daemon(path, cred(other)) {
            Err(err @ LocalError::ForeignDaemon { .. }) => {
                assert!(err.to_string().contains(&format!("uid {other}")), "{err}");
            }
            other => panic!("expected ForeignDaemon, got {other:?}"),
        }
    }

    #[test]
    fn peer_credentials_name_this_process() {
        let (a, _b) = std::os::unix::net::UnixStream::pair().unwrap();
        let cred = peer_cred(&a).unwrap();
        assert_eq!(cred.uid, Uid::effective().as_raw());
        assert_eq!(cred.pid, std::process::id());
    }

    #[test]
    fn names_and_paths() {
        assert!(default_socket(7).ends_with("ndds-7.sock"));
        assert!(describe_user(0).starts_with("uid 0"));
        assert!(matches!(
            group("no-such-group-ndds"),
            Err(LocalError::UnknownGroup(_))
        ));
    }
}

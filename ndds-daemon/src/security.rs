//! A daemon's identity file and its domain's permissions document (see
//! [`ndds_core::security`] for what they mean, `docs/security.md` for the set-up).
//!
//! The identity is generated on first use into the daemon's state directory
//! ([`default_identity_path`]) unless one is given. The document is TOML, signed by the
//! administrator (`ndds security sign`); reading it needs the `cli` feature (the SDK's
//! embedded daemons read no TOML, so a domain with permissions needs standalone daemons).

use std::io::Write as _;
use std::os::unix::fs::{DirBuilderExt as _, OpenOptionsExt as _};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use ndds_core::security::{
    Identity, IdentityFileError, KeyTextError, Permissions, PermissionsError, PublicId,
};

/// What a daemon of a domain with permissions runs with.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Security {
    /// Signs everything the daemon sends.
    pub identity: Identity,
    /// Where the identity lives.
    pub identity_file: PathBuf,
    /// The document, verified.
    pub permissions: Arc<Permissions>,
    /// Where it was read from.
    pub permissions_file: PathBuf,
    /// The administrator key that signs documents.
    pub admin: PublicId,
}

impl Security {
    /// The engine's guard for one run of a daemon: the document's end converted to the
    /// monotonic clock, and the identity with an agreement key drawn for this run (an error
    /// only if the operating system's random source cannot be read).
    pub fn guard(&self) -> Result<ndds_core::security::Guard, std::io::Error> {
        // The agreement key is this run's, drawn here and never written: a stolen identity
        // file opens nothing recorded (forward secrecy per run, docs/security.md).
        let session = crate::keys::random_bytes()?;
        Ok(ndds_core::security::Guard {
            identity: self.identity.clone().with_session_agreement(session),
            permissions: self.permissions.clone(),
            valid_until: valid_until(&self.permissions),
        })
    }
}

/// When `permissions` stops being valid, on the monotonic clock (`None`: not within any
/// time this process will see).
pub fn valid_until(permissions: &Permissions) -> Option<Instant> {
    let left = permissions.not_after.saturating_sub(unix_now());
    Instant::now().checked_add(Duration::from_secs(left))
}

/// Seconds since the Unix epoch.
pub fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// Why an identity or a document could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SecurityError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The identity file is not one.
    #[error("identity file {path}: {source}")]
    Identity {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        source: IdentityFileError,
    },
    /// The identity file can be read by others.
    #[error(
        "identity file {0} is readable by other users (mode {1:o}): `chmod 600` it, and make a new identity if others may have read it"
    )]
    Exposed(PathBuf, u32),
    /// The administrator key is not a key.
    #[error("administrator key: {0}")]
    AdminKey(#[from] KeyTextError),
    /// The document is not signed, or not by the administrator, or breaks its own rules.
    #[error("permissions document {path}: {source}")]
    Permissions {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        source: PermissionsError,
    },
    /// The document is not TOML of the expected shape.
    #[error("permissions document {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message.
        message: String,
    },
    /// The document is for another domain.
    #[error(
        "permissions document {path} is for domain {document}, this daemon serves domain {daemon}"
    )]
    OtherDomain {
        /// The file.
        path: PathBuf,
        /// Its domain.
        document: u16,
        /// Ours.
        daemon: u16,
    },
    /// The document is not valid now.
    #[error(
        "permissions document {path} is valid from {from} until {until}, not now ({now}): the administrator must sign a new one"
    )]
    NotValidNow {
        /// The file.
        path: PathBuf,
        /// Its start.
        from: String,
        /// Its end.
        until: String,
        /// Now.
        now: String,
    },
    /// Permissions without a domain key.
    #[error(
        "a permissions document needs a domain key (--key-file): the seal refuses replayed datagrams, which signatures alone do not"
    )]
    NeedsKey,
    /// No administrator key given.
    #[error(
        "a permissions document needs the administrator's public key to check it (--admin-key ed25519:... or the path of admin.pub)"
    )]
    NeedsAdmin,
    /// Documents need the `cli` feature.
    #[error(
        "permissions documents are read by the ndds-daemon binary (the `cli` feature), not by embedded daemons"
    )]
    NoParser,
}

/// Where a daemon keeps its identity when none is given: `/var/lib/ndds/identity` as root,
/// else `$XDG_STATE_HOME/ndds/identity` (`~/.local/state/ndds/identity`).
pub fn default_identity_path() -> PathBuf {
    if nix::unistd::geteuid().is_root() {
        return PathBuf::from("/var/lib/ndds/identity");
    }
    let state = std::env::var_os("XDG_STATE_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| std::env::var_os("HOME").map(|home| PathBuf::from(home).join(".local/state")))
        .unwrap_or_else(std::env::temp_dir);
    state.join("ndds/identity")
}

/// Reads the identity at `path`, or makes one there (mode 0600, its directory 0700) when the
/// file does not exist; true when it was made.
pub fn load_or_create_identity(path: &Path) -> Result<(Identity, bool), SecurityError> {
    let io = |source| SecurityError::Io {
        path: path.to_owned(),
        source,
    };
    match std::fs::read_to_string(path) {
        Ok(text) => {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(path).map_err(io)?.permissions().mode() & 0o777;
            if mode & 0o077 != 0 {
                return Err(SecurityError::Exposed(path.to_owned(), mode));
            }
            let identity = Identity::parse(&text).map_err(|source| SecurityError::Identity {
                path: path.to_owned(),
                source,
            })?;
            Ok((identity, false))
        }
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => {
            let identity = Identity::from_secret(crate::keys::random_bytes().map_err(io)?);
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::DirBuilder::new()
                    .recursive(true)
                    .mode(0o700)
                    .create(dir)
                    .map_err(io)?;
            }
            write_text(path, &identity.to_file_text(), 0o600, false).map_err(io)?;
            Ok((identity, true))
        }
        Err(err) => Err(io(err)),
    }
}

/// Writes `text` to `path` with `mode`: to a new file (`replace` false: an existing one is an
/// error), or to a temporary file beside it renamed over it (`replace` true: a reader sees the
/// old or the new file, never half of one).
pub fn write_text(path: &Path, text: &str, mode: u32, replace: bool) -> std::io::Result<()> {
    let target = if replace {
        let mut temporary = path.as_os_str().to_owned();
        temporary.push(".new");
        let temporary = PathBuf::from(temporary);
        let _ = std::fs::remove_file(&temporary);
        temporary
    } else {
        path.to_owned()
    };
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(mode)
        .open(&target)?;
    file.write_all(text.as_bytes())?;
    file.sync_all()?;
    if replace {
        std::fs::rename(&target, path)?;
    }
    Ok(())
}

/// The administrator key from its text (`ed25519:...`) or from a file holding it.
pub fn admin_key(spec: &str) -> Result<PublicId, SecurityError> {
    if spec.trim().starts_with(ndds_core::security::KEY_PREFIX) {
        return Ok(spec.parse()?);
    }
    let path = Path::new(spec);
    let text = std::fs::read_to_string(path).map_err(|source| SecurityError::Io {
        path: path.to_owned(),
        source,
    })?;
    let key = text
        .lines()
        .map(str::trim)
        .find(|line| !line.is_empty() && !line.starts_with('#'))
        .unwrap_or_default();
    Ok(key.parse()?)
}

/// Reads a signed document, checks its signature with `admin`, parses it and checks that it
/// is for `domain` and valid now.
#[cfg(feature = "cli")]
pub fn load_permissions(
    path: &Path,
    admin: &PublicId,
    domain: u16,
) -> Result<Permissions, SecurityError> {
    let text = std::fs::read_to_string(path).map_err(|source| SecurityError::Io {
        path: path.to_owned(),
        source,
    })?;
    let bad = |source| SecurityError::Permissions {
        path: path.to_owned(),
        source,
    };
    let body = ndds_core::security::verify_signed(&text, admin).map_err(bad)?;
    let permissions = document::parse(body).map_err(|message| SecurityError::Parse {
        path: path.to_owned(),
        message,
    })?;
    if let Some(document) = permissions.domain.filter(|d| *d != domain) {
        return Err(SecurityError::OtherDomain {
            path: path.to_owned(),
            document,
            daemon: domain,
        });
    }
    let now = unix_now();
    if !permissions.valid_at(now) {
        return Err(SecurityError::NotValidNow {
            path: path.to_owned(),
            from: document::time_text(permissions.not_before),
            until: document::time_text(permissions.not_after),
            now: document::time_text(now),
        });
    }
    Ok(permissions)
}

/// Watches the permissions document so that a new version (signed, copied to the host) takes
/// effect without a restart, as key rotation steps do ([`crate::keys::KeyWatch`]). Checked
/// every [`crate::keys::KEY_CHECK`] by the daemon's loop.
#[cfg(feature = "cli")]
#[derive(Debug)]
pub struct PermissionsWatch {
    path: PathBuf,
    admin: PublicId,
    domain: u16,
    stamp: Option<(SystemTime, u64, u64)>,
    current: Arc<Permissions>,
}

#[cfg(feature = "cli")]
impl PermissionsWatch {
    /// Watches the document `security` was read from. The first check reads it again, so a
    /// version written between loading and watching is not missed.
    pub fn new(security: &Security, domain: u16) -> Self {
        PermissionsWatch {
            path: security.permissions_file.clone(),
            admin: security.admin,
            domain,
            stamp: None,
            current: security.permissions.clone(),
        }
    }

    /// The new document to put in force, when the file changed and holds another valid,
    /// signed one. A file that cannot be used is logged (once per change), and the document
    /// in force stays.
    pub fn poll(&mut self) -> Option<Arc<Permissions>> {
        let now = crate::keys::stamp(&self.path);
        if now == self.stamp {
            return None;
        }
        self.stamp = now;
        match load_permissions(&self.path, &self.admin, self.domain) {
            Ok(permissions) if permissions == *self.current => None,
            Ok(permissions) => {
                tracing::info!(
                    path = %self.path.display(),
                    serial = permissions.serial,
                    subjects = permissions.subjects.len(),
                    "permissions document changed: the new version is in force"
                );
                self.current = Arc::new(permissions);
                Some(self.current.clone())
            }
            Err(err) => {
                tracing::error!(%err, "permissions document changed but cannot be used; the version in force stays");
                None
            }
        }
    }
}

/// The permissions document's TOML form.
#[cfg(feature = "cli")]
pub mod document {
    use std::time::{Duration, SystemTime};

    use ndds_core::security::{Permissions, PublicId, Subject};
    use serde::Deserialize;

    /// The file as written.
    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct DocumentFile {
        serial: u64,
        #[serde(default)]
        domain: Option<u16>,
        not_before: String,
        not_after: String,
        /// Informational: the key expected to sign it (checked when present).
        #[serde(default)]
        admin: Option<PublicId>,
        #[serde(default)]
        subject: Vec<Subject>,
    }

    /// Parses a document's text (its signature line, a comment, is ignored).
    pub fn parse(text: &str) -> Result<Permissions, String> {
        let file: DocumentFile = toml::from_str(text).map_err(|err| err.to_string())?;
        let permissions = Permissions {
            serial: file.serial,
            domain: file.domain,
            not_before: time(&file.not_before, "not_before")?,
            not_after: time(&file.not_after, "not_after")?,
            subjects: file.subject,
        };
        permissions.validate().map_err(|err| err.to_string())?;
        Ok(permissions)
    }

    /// The administrator key a document names, if it names one.
    pub fn admin_of(text: &str) -> Option<PublicId> {
        toml::from_str::<DocumentFile>(text).ok()?.admin
    }

    fn time(text: &str, field: &str) -> Result<u64, String> {
        let at = humantime::parse_rfc3339_weak(text).map_err(|err| {
            format!("`{field}` = {text:?}: {err} (write it as 2027-01-31T00:00:00Z)")
        })?;
        Ok(at
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()))
    }

    /// A Unix time as RFC 3339 text.
    pub fn time_text(unix: u64) -> String {
        SystemTime::UNIX_EPOCH
            .checked_add(Duration::from_secs(unix))
            .map_or_else(
                || format!("Unix time {unix}"),
                |at| humantime::format_rfc3339_seconds(at).to_string(),
            )
    }
}

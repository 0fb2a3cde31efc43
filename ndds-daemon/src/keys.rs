//! Domain key files: reading one (refusing one that others may read), and writing a new one.
//!
//! The format is [`ndds_core::seal::Keyring`]'s; the file must be the owner's alone (mode
//! 0600 or stricter), as an SSH private key must.

use std::io::Write as _;
use std::os::unix::fs::{OpenOptionsExt as _, PermissionsExt as _};
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use ndds_core::seal::{Cipher, DomainKey, KeyFileError, Keyring, SealMode, SealSetup};

/// A key file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// The file could not be read or written.
    #[error("key file {path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error (in the message, so not also a `source`).
        error: std::io::Error,
    },
    /// Group or others may read or write it.
    #[error(
        "key file {path} is accessible to other users (mode {mode:03o}); run `chmod 600 {path}`"
    )]
    Exposed {
        /// The file.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
    },
    /// Its content is not a key file.
    #[error("key file {path}: {error}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the line (in the message, so not also a `source`).
        error: KeyFileError,
    },
    /// A new key file would replace an existing one.
    #[error("{path} exists; a new key would lock its hosts out (remove it first)")]
    Exists {
        /// The file.
        path: PathBuf,
    },
}

/// Reads the key file at `path`.
pub fn load(path: &Path) -> Result<Keyring, KeyError> {
    let io = |error| KeyError::Io {
        path: path.to_owned(),
        error,
    };
    let metadata = std::fs::metadata(path).map_err(io)?;
    let mode = metadata.permissions().mode() & 0o777;
    if mode & 0o077 != 0 {
        return Err(KeyError::Exposed {
            path: path.to_owned(),
            mode,
        });
    }
    let text = std::fs::read_to_string(path).map_err(io)?;
    Keyring::parse(&text).map_err(|error| KeyError::Format {
        path: path.to_owned(),
        error,
    })
}

/// Writes a new key file at `path` (mode 0600, never over an existing file) holding one
/// 256-bit key of epoch 1 from the operating system's random source, for `cipher`.
pub fn create(path: &Path, cipher: Cipher) -> Result<Keyring, KeyError> {
    let io = |error| KeyError::Io {
        path: path.to_owned(),
        error,
    };
    let keyring = Keyring::new(1, random_key().map_err(io)?).with_cipher(cipher);
    write_new(path, &keyring).map_err(|source| match source.kind() {
        std::io::ErrorKind::AlreadyExists => KeyError::Exists {
            path: path.to_owned(),
        },
        _ => io(source),
    })?;
    Ok(keyring)
}

/// Replaces the key file at `path` with `keyring` (a rotation step): written to a private
/// temporary file beside it, then renamed over it, so a reader sees the old or the new file,
/// never half of one.
pub fn save(path: &Path, keyring: &Keyring) -> Result<(), KeyError> {
    let io = |error| KeyError::Io {
        path: path.to_owned(),
        error,
    };
    let mut temporary = path.as_os_str().to_owned();
    temporary.push(".new");
    let temporary = PathBuf::from(temporary);
    let _ = std::fs::remove_file(&temporary);
    write_new(&temporary, keyring)
        .and_then(|()| std::fs::rename(&temporary, path))
        .map_err(io)
}

/// Writes `keyring` to a file that must not exist yet, readable by its owner only, and
/// flushes it to the disk.
fn write_new(path: &Path, keyring: &Keyring) -> std::io::Result<()> {
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)?;
    file.write_all(keyring.to_file_text().as_bytes())?;
    file.sync_all()
}

/// How often daemons and participants look at their key file for a rotation step.
pub const KEY_CHECK: std::time::Duration = std::time::Duration::from_secs(1);

/// Watches a key file so that a rotation step (`ndds key rotate`, `use`, `retire`) takes
/// effect without a restart: [`KeyWatch::poll`] reads the file again when its modification
/// time, size or inode moved (the tools replace it by renaming, so the inode moves).
#[derive(Debug)]
pub struct KeyWatch {
    path: PathBuf,
    stamp: Option<(std::time::SystemTime, u64, u64)>,
    current: Keyring,
}

impl KeyWatch {
    /// Watches `path`, whose contents were `current` when read. The first check reads the
    /// file again whatever its stamp: a step written between that read and this watch is not
    /// missed.
    pub fn new(path: &Path, current: Keyring) -> Self {
        KeyWatch {
            path: path.to_owned(),
            stamp: None,
            current,
        }
    }

    /// The watched file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The new keys to put in force, when the file changed and holds different ones. Both
    /// outcomes of a change are logged: new keys, or a file that cannot be used (then the keys
    /// in force stay).
    pub fn poll(&mut self) -> Option<Keyring> {
        match self.changed()? {
            Ok(keyring) => {
                tracing::info!(
                    path = %self.path.display(),
                    sealing_epoch = keyring.send_epoch(),
                    accepted = ?keyring.epochs().collect::<Vec<_>>(),
                    "key file changed: new keys in force"
                );
                Some(keyring)
            }
            Err(err) => {
                tracing::error!(%err, "key file changed but cannot be used; the keys in force stay");
                None
            }
        }
    }

    /// The new keys when the file changed and holds different ones; an error (once per
    /// change) when it changed and cannot be used: the keys in force stay.
    fn changed(&mut self) -> Option<Result<Keyring, KeyError>> {
        let now = stamp(&self.path);
        if now == self.stamp {
            return None;
        }
        self.stamp = now;
        match load(&self.path) {
            Ok(keyring) if keyring == self.current => None,
            Ok(keyring) => {
                self.current = keyring.clone();
                Some(Ok(keyring))
            }
            Err(err) => Some(Err(err)),
        }
    }
}

/// What tells a file's versions apart cheaply: its modification time, size and inode.
pub(crate) fn stamp(path: &Path) -> Option<(std::time::SystemTime, u64, u64)> {
    use std::os::unix::fs::MetadataExt as _;
    let meta = std::fs::metadata(path).ok()?;
    Some((meta.modified().ok()?, meta.len(), meta.ino()))
}

/// A new random key (from the operating system's random source).
pub fn random_key() -> Result<DomainKey, std::io::Error> {
    let mut bytes = random_bytes()?;
    let key = DomainKey::from_bytes(bytes);
    bytes.fill(0);
    Ok(key)
}

/// 32 bytes from the operating system's random source.
pub fn random_bytes() -> Result<[u8; 32], std::io::Error> {
    let mut bytes = [0u8; 32];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut random| std::io::Read::read_exact(&mut random, &mut bytes))?;
    Ok(bytes)
}

/// Whether `cipher` runs in hardware on this processor, fast and constant-time.
/// ChaCha20-Poly1305 needs nothing. AES-GCM needs AES and carry-less multiply instructions
/// (x86's AES-NI and PCLMULQDQ, ARMv8's AES and PMULL). AEGIS-128L needs AES instructions,
/// and on x86 AVX too (libaegis takes its AES-NI code only with AVX, so Atom-class processors
/// with AES-NI and no AVX run it in software). Without them those ciphers run in a slower
/// software form and ChaCha20-Poly1305 is the faster choice.
pub fn fast_here(cipher: Cipher) -> bool {
    // Whether AES-GCM runs in hardware here, and whether AEGIS-128L does.
    #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
    let (gcm, aegis) = {
        let aes = std::arch::is_x86_feature_detected!("aes");
        (
            aes && std::arch::is_x86_feature_detected!("pclmulqdq"),
            aes && std::arch::is_x86_feature_detected!("avx"),
        )
    };
    #[cfg(target_arch = "aarch64")]
    let (gcm, aegis) = {
        let aes = std::arch::is_aarch64_feature_detected!("aes");
        (aes && std::arch::is_aarch64_feature_detected!("pmull"), aes)
    };
    #[cfg(not(any(target_arch = "x86", target_arch = "x86_64", target_arch = "aarch64")))]
    let (gcm, aegis) = (false, false);
    match cipher {
        Cipher::ChaCha20Poly1305 => true,
        Cipher::Aes128Gcm | Cipher::Aes256Gcm => gcm,
        Cipher::Aegis128L => aegis,
    }
}

/// The cipher a new domain gets when none is named: the first of AEGIS-128L, AES-128-GCM and
/// ChaCha20-Poly1305 that runs in hardware here ([`fast_here`]). AEGIS-128L seals 8 KiB in
/// about half the time of AES-128-GCM where both do (0.53 against 0.91 µs on the x86 of
/// docs/benchmarks.md), which keeps sealed 8 KiB samples within 15 % of open ones where
/// AES-GCM stays at 0.76-0.85; its 128-bit key matches the security level of the rest of the
/// domain's cryptography (X25519 and Ed25519 give about 128 bits). A site that must use NIST
/// algorithms names `aes-128-gcm`.
pub fn suggested_cipher() -> Cipher {
    [Cipher::Aegis128L, Cipher::Aes128Gcm]
        .into_iter()
        .find(|cipher| fast_here(*cipher))
        .unwrap_or(Cipher::ChaCha20Poly1305)
}

/// A warning when `cipher` is slow on this processor (an AEGIS or AES-GCM domain on a host
/// without the instructions it needs), saying what to do; `None` when it is not.
pub fn slow_cipher_warning(cipher: Cipher) -> Option<String> {
    (!fast_here(cipher)).then(|| {
        format!(
            "this processor lacks the instructions the domain's cipher {} needs, so it runs \
             in software here, several times slower than with them; a domain whose hosts lack \
             them is faster with a key made by `ndds key new FILE --cipher chacha20-poly1305`",
            cipher.name()
        )
    })
}

/// How a daemon or participant seals with `keyring`: `mode`, a session from the wall clock
/// (microseconds: it grows from one start to the next), integrity-only datagrams accepted.
pub fn setup(keyring: Keyring, mode: SealMode) -> SealSetup {
    let session = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(1, |since| {
            u64::try_from(since.as_micros()).unwrap_or(u64::MAX)
        });
    SealSetup {
        keyring,
        mode,
        session,
        require_encryption: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_key_file_is_private_loads_and_is_never_overwritten() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("domain.key");
        let made = create(&path, Cipher::default()).unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        assert_eq!(load(&path).unwrap(), made);
        assert!(matches!(
            create(&path, Cipher::default()),
            Err(KeyError::Exists { .. })
        ));
        assert_eq!(load(&path).unwrap(), made, "unchanged");
        let other = create(&dir.path().join("other.key"), Cipher::Aes256Gcm).unwrap();
        assert_ne!(other, made, "keys come from the random source");
    }

    #[test]
    fn the_suggested_cipher_follows_the_processor_and_only_aes_without_instructions_warns() {
        let suggested = suggested_cipher();
        assert!(fast_here(suggested), "{suggested:?} runs in hardware here");
        let expected = if fast_here(Cipher::Aegis128L) {
            Cipher::Aegis128L
        } else if fast_here(Cipher::Aes128Gcm) {
            Cipher::Aes128Gcm
        } else {
            Cipher::ChaCha20Poly1305
        };
        assert_eq!(suggested, expected);
        assert_eq!(
            slow_cipher_warning(suggested),
            None,
            "the suggestion is never slow"
        );
        assert!(fast_here(Cipher::ChaCha20Poly1305));
        assert_eq!(slow_cipher_warning(Cipher::ChaCha20Poly1305), None);
        for aes in [Cipher::Aegis128L, Cipher::Aes128Gcm, Cipher::Aes256Gcm] {
            let warning = slow_cipher_warning(aes);
            assert_eq!(warning.is_some(), !fast_here(aes));
            if let Some(warning) = warning {
                assert!(warning.contains("--cipher chacha20-poly1305"), "{warning}");
            }
        }
    }

    #[test]
    fn an_exposed_or_broken_key_file_is_refused_saying_what_to_do() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("domain.key");
        create(&path, Cipher::default()).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let err = load(&path).unwrap_err();
        assert!(err.to_string().contains("chmod 600"), "{err}");
        std::fs::write(&path, "ndds-key v1\nkey 1 00\n").unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        let err = load(&path).unwrap_err();
        assert!(err.to_string().contains("line 2"), "{err}");
        let err = load(&dir.path().join("missing.key")).unwrap_err();
        assert!(matches!(err, KeyError::Io { .. }), "{err}");
    }
}

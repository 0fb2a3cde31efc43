//! Domain keys and the key file that holds them.
//!
//! A key file is text, one item a line (`#` starts a comment):
//!
//! ```text
//! ndds-key v1
//! cipher aes-256-gcm
//! key 1 9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08
//! key 2 60303ae22b998861bce3b28f33eec1be758a213c86c93c076dbe9f558c11c752
//! send 2
//! ```
//!
//! Every `key EPOCH HEX` (a 256-bit key in 64 hex digits) is accepted from other senders;
//! `send EPOCH` names the one this host seals with (by default the highest epoch);
//! `cipher NAME` the AEAD of the whole domain (`chacha20-poly1305`, what a file without the
//! line means, `aegis-128l`, `aes-256-gcm` or `aes-128-gcm`: see [`Cipher`]). Rotation
//! is three edits of every host's file: add the new key, then make it the one sent, then
//! remove the old one; between the first and the last, both are accepted.

use std::fmt;

use super::Cipher;

/// A 256-bit domain key. Its `Debug` shows no key material, and it is overwritten when
/// dropped.
#[derive(Clone, PartialEq, Eq)]
pub struct DomainKey([u8; 32]);

impl DomainKey {
    /// The key made of these bytes (from the operating system's random source, for a new
    /// key).
    pub fn from_bytes(bytes: [u8; 32]) -> Self {
        DomainKey(bytes)
    }

    /// Its bytes.
    pub fn bytes(&self) -> &[u8; 32] {
        &self.0
    }

    fn from_hex(text: &str) -> Option<Self> {
        crate::hex::unhex(text).map(DomainKey)
    }

    fn to_hex(&self) -> String {
        crate::hex::hex(&self.0)
    }
}

impl fmt::Debug for DomainKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("DomainKey(..)")
    }
}

impl Drop for DomainKey {
    fn drop(&mut self) {
        // Volatile, so the compiler cannot drop the write as dead.
        for byte in &mut self.0 {
            // SAFETY: `byte` is a valid, aligned, exclusive reference.
            unsafe { std::ptr::write_volatile(byte, 0) };
        }
    }
}

/// The keys a host accepts, by epoch, and the epoch it seals with.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Keyring {
    keys: Vec<(u32, DomainKey)>,
    send: u32,
    cipher: Cipher,
}

/// What is wrong with a key file, with its line (1-based).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum KeyFileError {
    /// The first line is not `ndds-key v1`.
    #[error("line {line}: not an ndds key file (its first line must be `ndds-key v1`)")]
    NotAKeyFile {
        /// The line.
        line: usize,
    },
    /// A cipher this version does not know.
    #[error(
        "line {line}: unknown cipher `{name}` (chacha20-poly1305, aegis-128l, aes-256-gcm or aes-128-gcm)"
    )]
    UnknownCipher {
        /// The line.
        line: usize,
        /// The name given.
        name: String,
    },
    /// A line that is neither `key EPOCH HEX`, `send EPOCH` nor `cipher NAME`.
    #[error(
        "line {line}: expected `key EPOCH HEX`, `send EPOCH` or `cipher NAME`, found `{found}`"
    )]
    Syntax {
        /// The line.
        line: usize,
        /// What it said (a key's digits are not repeated).
        found: String,
    },
    /// A key that is not 64 hex digits.
    #[error("line {line}: the key of epoch {epoch} is not 64 hex digits (256 bits)")]
    BadKey {
        /// The line.
        line: usize,
        /// Its epoch.
        epoch: u32,
    },
    /// Two keys for one epoch.
    #[error("line {line}: a second key for epoch {epoch}")]
    DuplicateEpoch {
        /// The line.
        line: usize,
        /// The epoch.
        epoch: u32,
    },
    /// `send` names an epoch the file holds no key for.
    #[error("`send {epoch}`: the file holds no key of epoch {epoch}")]
    SendWithoutKey {
        /// The epoch.
        epoch: u32,
    },
    /// No `key` line.
    #[error("the file holds no key")]
    Empty,
}

impl Keyring {
    /// A keyring of one key, sealed with.
    pub fn new(epoch: u32, key: DomainKey) -> Self {
        Keyring {
            keys: vec![(epoch, key)],
            send: epoch,
            cipher: Cipher::default(),
        }
    }

    /// The same keys, sealing with `cipher`.
    pub fn with_cipher(mut self, cipher: Cipher) -> Self {
        self.cipher = cipher;
        self
    }

    /// The domain's cipher.
    pub fn cipher(&self) -> Cipher {
        self.cipher
    }

    /// The key of `epoch`, if accepted.
    pub fn key(&self, epoch: u32) -> Option<&DomainKey> {
        self.keys.iter().find(|(e, _)| *e == epoch).map(|(_, k)| k)
    }

    /// The epoch sealed with.
    pub fn send_epoch(&self) -> u32 {
        self.send
    }

    /// The key sealed with.
    pub fn send_key(&self) -> &DomainKey {
        // `send` always names a held key (every constructor and edit keeps it so).
        self.key(self.send).unwrap_or(&self.keys[0].1)
    }

    /// The epochs accepted, in the file's order.
    pub fn epochs(&self) -> impl Iterator<Item = u32> + '_ {
        self.keys.iter().map(|(epoch, _)| *epoch)
    }

    /// Accepts `key` as `epoch` too (replacing a key of that epoch).
    pub fn add(&mut self, epoch: u32, key: DomainKey) {
        self.keys.retain(|(e, _)| *e != epoch);
        self.keys.push((epoch, key));
    }

    /// Seals with `epoch` from now on; false (and nothing changed) if no key of it is held.
    pub fn set_send(&mut self, epoch: u32) -> bool {
        let held = self.key(epoch).is_some();
        if held {
            self.send = epoch;
        }
        held
    }

    /// Stops accepting `epoch`; false if it is the one sealed with (switch first) or unknown.
    pub fn retire(&mut self, epoch: u32) -> bool {
        if epoch == self.send || self.key(epoch).is_none() {
            return false;
        }
        self.keys.retain(|(e, _)| *e != epoch);
        true
    }

    /// Reads a key file's text.
    pub fn parse(text: &str) -> Result<Keyring, KeyFileError> {
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, line)| (i + 1, line.split('#').next().unwrap_or("").trim()))
            .filter(|(_, line)| !line.is_empty());
        match lines.next() {
            Some((_, "ndds-key v1")) => {}
            Some((line, _)) => return Err(KeyFileError::NotAKeyFile { line }),
            None => return Err(KeyFileError::NotAKeyFile { line: 1 }),
        }
        let mut keys: Vec<(u32, DomainKey)> = Vec::new();
        let mut send = None;
        let mut cipher = Cipher::default();
        for (line, content) in lines {
            let words: Vec<&str> = content.split_whitespace().collect();
            let syntax = || KeyFileError::Syntax {
                line,
                found: words.iter().take(2).copied().collect::<Vec<_>>().join(" "),
            };
            match words.as_slice() {
                ["key", epoch, hex] => {
                    let epoch: u32 = epoch.parse().map_err(|_| syntax())?;
                    let key =
                        DomainKey::from_hex(hex).ok_or(KeyFileError::BadKey { line, epoch })?;
                    if keys.iter().any(|(e, _)| *e == epoch) {
                        return Err(KeyFileError::DuplicateEpoch { line, epoch });
                    }
                    keys.push((epoch, key));
                }
                ["send", epoch] => send = Some(epoch.parse::<u32>().map_err(|_| syntax())?),
                ["cipher", name] => {
                    cipher =
                        Cipher::from_name(name).ok_or_else(|| KeyFileError::UnknownCipher {
                            line,
                            name: (*name).to_owned(),
                        })?;
                }
                _ => return Err(syntax()),
            }
        }
        let highest = keys
            .iter()
            .map(|(e, _)| *e)
            .max()
            .ok_or(KeyFileError::Empty)?;
        let send = send.unwrap_or(highest);
        if !keys.iter().any(|(e, _)| *e == send) {
            return Err(KeyFileError::SendWithoutKey { epoch: send });
        }
        Ok(Keyring { keys, send, cipher })
    }

    /// The key file's text for this keyring.
    pub fn to_file_text(&self) -> String {
        let mut text = String::from(
            "# ndds domain key: every host of the domain holds the same file; keep it secret\n\
             # (mode 0600). See docs/security.md.\nndds-key v1\n",
        );
        text.push_str(&format!("cipher {}\n", self.cipher.name()));
        for (epoch, key) in &self.keys {
            text.push_str(&format!("key {epoch} {}\n", key.to_hex()));
        }
        text.push_str(&format!("send {}\n", self.send));
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(byte: u8) -> DomainKey {
        DomainKey::from_bytes([byte; 32])
    }

    #[test]
    fn a_key_file_round_trips_and_shows_no_key_in_debug() {
        let mut ring = Keyring::new(1, key(0xab));
        ring.add(2, key(0x01));
        assert!(ring.set_send(2));
        let text = ring.to_file_text();
        assert!(text.contains("key 1 abab"), "{text}");
        let parsed = Keyring::parse(&text).unwrap();
        assert_eq!(parsed, ring);
        assert_eq!(parsed.send_epoch(), 2);
        assert!(!format!("{parsed:?}").contains("ab"), "{parsed:?}");
    }

    #[test]
    fn the_highest_epoch_is_sent_unless_named() {
        let text = format!(
            "ndds-key v1\nkey 7 {}\nkey 3 {} # old\n",
            "11".repeat(32),
            "22".repeat(32)
        );
        let ring = Keyring::parse(&text).unwrap();
        assert_eq!(ring.send_epoch(), 7);
        assert_eq!(ring.epochs().collect::<Vec<_>>(), vec![7, 3]);
    }

    #[test]
    fn bad_files_say_which_line_and_what_to_do() {
        let hex = "33".repeat(32);
        let cases = [
            ("hello\n", KeyFileError::NotAKeyFile { line: 1 }),
            ("", KeyFileError::NotAKeyFile { line: 1 }),
            ("ndds-key v1\n", KeyFileError::Empty),
            (
                "ndds-key v1\nkey 1 abc\n",
                KeyFileError::BadKey { line: 2, epoch: 1 },
            ),
            (
                &format!("ndds-key v1\nkey 1 {hex}\nkey 1 {hex}\n"),
                KeyFileError::DuplicateEpoch { line: 3, epoch: 1 },
            ),
            (
                &format!("ndds-key v1\nkey 1 {hex}\nsend 2\n"),
                KeyFileError::SendWithoutKey { epoch: 2 },
            ),
            (
                &format!("ndds-key v1\n\n# c\nkye 1 {hex}\n"),
                KeyFileError::Syntax {
                    line: 4,
                    found: "kye 1".into(),
                },
            ),
        ];
        for (text, expected) in cases {
            assert_eq!(Keyring::parse(text), Err(expected), "{text}");
        }
    }

    #[test]
    fn the_cipher_is_a_setting_of_the_file() {
        for cipher in Cipher::ALL {
            let ring = Keyring::new(1, key(5)).with_cipher(cipher);
            let text = ring.to_file_text();
            assert!(
                text.contains(&format!("cipher {}\n", cipher.name())),
                "{text}"
            );
            assert_eq!(Keyring::parse(&text).unwrap().cipher(), cipher);
        }
        let plain = format!("ndds-key v1\nkey 1 {}\n", "11".repeat(32));
        assert_eq!(
            Keyring::parse(&plain).unwrap().cipher(),
            Cipher::ChaCha20Poly1305
        );
        let unknown = format!("ndds-key v1\ncipher rot13\nkey 1 {}\n", "11".repeat(32));
        assert_eq!(
            Keyring::parse(&unknown),
            Err(KeyFileError::UnknownCipher {
                line: 2,
                name: "rot13".into()
            })
        );
    }

    #[test]
    fn the_sending_epoch_cannot_be_retired() {
        let mut ring = Keyring::new(1, key(1));
        ring.add(2, key(2));
        assert!(!ring.retire(1));
        assert!(ring.set_send(2));
        assert!(ring.retire(1));
        assert!(ring.key(1).is_none());
        assert!(!ring.set_send(1));
        assert!(!ring.retire(9));
    }
}

//! Sealed domains: every datagram of a domain that has a key is authenticated (and, by
//! default, encrypted) with an AEAD, the domain's [`Cipher`], before anything parses it.
//!
//! A sealed datagram keeps the fixed header in clear (receivers still sort by magic, version,
//! kind and domain before any cryptography), with the top bit of the kind byte set, and puts a
//! 20-byte seal head between the header and the body:
//!
//! ```text
//!  0               4       5       6               8                              16
//!  +---------------+-------+-------+---------------+-------------------------------+
//!  | magic "NDDS"  |version|S|C|knd| domain (u16le)|       sender id (u64le)       |
//!  +---------------+-------+-------+---------------+-------------------------------+
//!  16              20                              28                              36
//!  +---------------+-------------------------------+-------------------------------+
//!  | epoch (u32le) |       session (u64le)         |       counter (u64le)         |
//!  +---------------+-------------------------------+-------------------------------+
//!  36
//!  +-----------------------------------------------------------+-------------------+
//!  | body: encrypted, or in clear when C is set                |   tag (16 bytes)  |
//!  +-----------------------------------------------------------+-------------------+
//! ```
//!
//! - `S` (0x80 of the kind byte): sealed. `C` (0x40): integrity only — the body is in clear
//!   and the tag authenticates it with everything before it, for hosts that must stay
//!   inspectable. The low six bits are the message kind.
//! - The key: HKDF-SHA256 of the domain key of `epoch` (salt `ndds-seal-v1`), expanded with
//!   the domain, epoch, sender id and session, so every sender has keys of its own and a key
//!   is never shared by two processes.
//! - `session`: chosen by the sender when it starts (the driver gives its start time in
//!   microseconds, so a restarted sender's sessions grow); `counter` counts the sender's
//!   datagrams in the session and is the nonce (8 bytes little-endian, then 4 zero bytes; 8
//!   for AEGIS-128L's 128-bit nonce).
//!   A sender never reuses a counter: it stops sealing before the counter would wrap.
//! - Associated data: the 36 bytes of header and seal head (and, integrity only, the body).
//!
//! A receiver ([`Opener`]) drops, before parsing the body and counted by [`OpenError`], a
//! datagram that is not sealed, too short, of an epoch it does not accept, whose tag does not
//! verify, whose counter it has already accepted or that is too old for its replay window
//! ([`REPLAY_WINDOW`] counters), or of a session older than the newest one it accepted from
//! that sender. State is kept per sender only once a tag verified, so forged traffic costs a
//! receiver no memory; the number of senders remembered is bounded ([`MAX_SENDERS`]).
//!
//! The cipher is the domain's, named in its key file: ChaCha20-Poly1305 (constant-time in
//! software on every processor a robot may carry; what a file without a `cipher` line
//! means), AEGIS-128L, AES-128-GCM or AES-256-GCM (fast and safe only with AES instructions,
//! and for GCM carry-less multiply ones too, which many ARM boards lack; `ndds key new` takes
//! AEGIS-128L where its processor has them). The GCM ciphers and ChaCha20-Poly1305 take the
//! per-sender counter as their 96-bit nonce directly, AEGIS-128L as its 128-bit one (the
//! counter, then 8 zero bytes). With the `ring` feature (the daemon and the SDK turn it on)
//! GCM and ChaCha20-Poly1305 come from ring, whose assembly is several times faster than
//! RustCrypto's pure Rust; without it, from RustCrypto. The two seal the same bytes, so hosts
//! built either way share a domain. AEGIS-128L comes from the `aegis` crate (libaegis, which
//! picks its AES-NI code, used where AVX is present too, or its ARM crypto-extension code at
//! run time) either way.

mod keyring;
mod opener;
mod sealer;
pub(crate) mod window;

pub use keyring::{DomainKey, KeyFileError, Keyring};
pub use opener::{OpenStats, Opened, Opener, SESSION_IDLE};
pub use sealer::{SealError, Sealer};
pub use window::REPLAY_WINDOW;

use crate::wire::HEADER_LEN;

/// The kind byte's flag of a sealed datagram.
pub const SEALED: u8 = 0x80;
/// The kind byte's flag of an integrity-only sealed datagram (body in clear).
pub const CLEAR: u8 = 0x40;
/// Bytes of the seal head (epoch, session, counter).
pub const SEAL_HEAD_LEN: usize = 20;
/// Bytes of the tag at the end.
pub const TAG_LEN: usize = 16;
/// What sealing adds to a datagram.
pub const OVERHEAD: usize = SEAL_HEAD_LEN + TAG_LEN;
/// Senders whose replay state a receiver keeps at most (the least recently heard goes first).
pub const MAX_SENDERS: usize = 4096;

/// Where the kind byte sits in the fixed header.
const KIND_BYTE: usize = 5;
/// Header and seal head: the associated data of an encrypted datagram.
const SEALED_HEAD: usize = HEADER_LEN + SEAL_HEAD_LEN;

/// How a daemon or a participant of a domain with a key seals and opens its datagrams.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SealSetup {
    /// The domain's keys.
    pub keyring: Keyring,
    /// Encrypted, or integrity only.
    pub mode: SealMode,
    /// This start of the daemon or participant: must grow from one start to the next (the driver
    /// gives its start time in microseconds).
    pub session: u64,
    /// Refuse integrity-only datagrams.
    pub require_encryption: bool,
}

/// How a domain's datagrams are sealed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SealMode {
    /// Authenticated and encrypted.
    #[default]
    Encrypt,
    /// Authenticated only: bodies stay readable on the wire.
    IntegrityOnly,
}

/// Why a datagram was not opened; every variant is a counter of [`OpenStats`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, thiserror::Error)]
pub enum OpenError {
    /// Shorter than header, seal head and tag.
    #[error("too short to be sealed")]
    Truncated,
    /// Not sealed, in a domain that has a key.
    #[error("not sealed (a sender without the domain key?)")]
    NotSealed,
    /// Integrity only, where this receiver requires encryption.
    #[error("integrity-only datagram where encryption is required")]
    ClearRefused,
    /// Sealed with a key epoch this receiver does not hold or no longer accepts.
    #[error("unknown or retired key epoch")]
    UnknownEpoch,
    /// The tag did not verify: forged, corrupted, or sealed with another key.
    #[error("authentication failed")]
    BadTag,
    /// A counter already accepted, or too old for the replay window.
    #[error("replayed or too old")]
    Replayed,
    /// From a session older than the newest one accepted from that sender.
    #[error("stale session")]
    StaleSession,
    /// In a domain with permissions: from a sender this receiver holds no data key for (its
    /// daemon never matched the pair).
    #[error("no data key for this sender (not matched by this participant's daemon)")]
    Unkeyed,
}

impl OpenError {
    /// Every reason, for counter tables.
    pub const ALL: [OpenError; 8] = [
        OpenError::Truncated,
        OpenError::NotSealed,
        OpenError::ClearRefused,
        OpenError::UnknownEpoch,
        OpenError::BadTag,
        OpenError::Replayed,
        OpenError::StaleSession,
        OpenError::Unkeyed,
    ];

    /// Its index in [`OpenError::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Its name in counters and logs.
    pub fn name(self) -> &'static str {
        match self {
            OpenError::Truncated => "truncated",
            OpenError::NotSealed => "not_sealed",
            OpenError::ClearRefused => "clear_refused",
            OpenError::UnknownEpoch => "unknown_epoch",
            OpenError::BadTag => "bad_tag",
            OpenError::Replayed => "replayed",
            OpenError::StaleSession => "stale_session",
            OpenError::Unkeyed => "unkeyed",
        }
    }
}

/// True if `datagram` is a sealed ndds datagram of this protocol version: a whole header
/// with the magic, the version, the sealed flag and a known message kind (a receiver without
/// a key drops it and says that the domain is sealed; anything else is judged by the plain
/// header's checks, as junk is).
pub fn is_sealed(datagram: &[u8]) -> bool {
    let Some(head) = datagram.get(..HEADER_LEN) else {
        return false;
    };
    let kind = head[KIND_BYTE];
    head[..4] == crate::wire::MAGIC
        && head[4] == crate::wire::PROTOCOL_VERSION
        && kind & SEALED != 0
        && crate::wire::MessageKind::from_u8(kind & !(SEALED | CLEAR)).is_some()
}

/// The AEAD a domain seals with: a setting of its key file (`cipher NAME`), the same on every
/// host of the domain.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Cipher {
    /// ChaCha20-Poly1305 (RFC 8439): constant-time in software on any processor (the
    /// default, `chacha20-poly1305`).
    #[default]
    ChaCha20Poly1305,
    /// AES-256-GCM: several times faster where the processor has AES and carry-less multiply
    /// instructions (x86 with AES-NI, ARMv8 with the crypto extension), slow without them
    /// (`aes-256-gcm`).
    Aes256Gcm,
    /// AES-128-GCM: the same with a 128-bit key and 10 rounds instead of 14 (`aes-128-gcm`;
    /// TLS 1.3's mandatory suite, and one of DDS Security's two AES-GCM transformations): a
    /// tenth faster at 8 KiB on the x86 of docs/benchmarks.md, where GHASH costs as much as
    /// the rounds. The domain key stays 256 bits; each sender's session key is the first 16
    /// bytes of its derivation.
    Aes128Gcm,
    /// AEGIS-128L (`aegis-128l`): an AEAD built on AES rounds, of the AEGIS family (AEGIS-128
    /// is in the CAESAR competition's final portfolio; specified in the IRTF CFRG's
    /// draft-irtf-cfrg-aegis-aead; in libsodium since 1.0.19), with a 128-bit key, nonce and
    /// tag. Where the processor has AES instructions it seals 8 KiB in about half the time of
    /// AES-128-GCM (it needs no GHASH: the AES rounds authenticate as they encrypt), which is
    /// what keeps sealed 8 KiB samples within 15 % of open ones (docs/benchmarks.md); without
    /// them it runs in a slow software form, as AES-GCM does. It is not a NIST algorithm: a
    /// site that must use those takes `aes-128-gcm`. The session key is the first 16 bytes of
    /// the derivation.
    Aegis128L,
}

impl Cipher {
    /// Every cipher.
    pub const ALL: [Cipher; 4] = [
        Cipher::ChaCha20Poly1305,
        Cipher::Aes256Gcm,
        Cipher::Aes128Gcm,
        Cipher::Aegis128L,
    ];

    /// Its name in key files.
    pub fn name(self) -> &'static str {
        match self {
            Cipher::ChaCha20Poly1305 => "chacha20-poly1305",
            Cipher::Aes256Gcm => "aes-256-gcm",
            Cipher::Aes128Gcm => "aes-128-gcm",
            Cipher::Aegis128L => "aegis-128l",
        }
    }

    /// The cipher of this name.
    pub fn from_name(name: &str) -> Option<Cipher> {
        Cipher::ALL.into_iter().find(|cipher| cipher.name() == name)
    }

    /// Its byte in the key derivation (so one domain key yields unrelated keys per cipher).
    fn id(self) -> u8 {
        match self {
            Cipher::ChaCha20Poly1305 => 1,
            Cipher::Aes256Gcm => 2,
            Cipher::Aes128Gcm => 3,
            Cipher::Aegis128L => 4,
        }
    }
}

/// A session's key, ready to seal and open.
pub(crate) enum SessionKey {
    ChaCha(chacha20poly1305::ChaCha20Poly1305),
    Aes(Box<aes_gcm::Aes256Gcm>),
    Aes128(Box<aes_gcm::Aes128Gcm>),
    /// Either cipher, through ring.
    #[cfg(feature = "ring")]
    Ring(Box<ring::aead::LessSafeKey>),
    /// AEGIS-128L's key (the same with either backend).
    Aegis([u8; 16]),
}

type Tag = chacha20poly1305::Tag;

/// Whose implementation of the ciphers a key uses. Both seal the same bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Backend {
    /// RustCrypto's `chacha20poly1305` and `aes-gcm` (pure Rust).
    RustCrypto,
    /// ring's (assembly; the `ring` feature).
    #[cfg(feature = "ring")]
    Ring,
}

impl Backend {
    /// The fastest one built in.
    #[cfg(feature = "ring")]
    pub(crate) const PREFERRED: Backend = Backend::Ring;
    /// The fastest one built in.
    #[cfg(not(feature = "ring"))]
    pub(crate) const PREFERRED: Backend = Backend::RustCrypto;
}

impl SessionKey {
    /// The key `bytes` of `cipher`, with `backend`'s implementation (AES-128-GCM and
    /// AEGIS-128L take the first 16 of them; AEGIS-128L has one implementation).
    pub(crate) fn new(cipher: Cipher, bytes: &[u8; 32], backend: Backend) -> SessionKey {
        use chacha20poly1305::KeyInit;
        match backend {
            Backend::RustCrypto => match cipher {
                Cipher::ChaCha20Poly1305 => {
                    SessionKey::ChaCha(chacha20poly1305::ChaCha20Poly1305::new(&(*bytes).into()))
                }
                Cipher::Aes256Gcm => {
                    SessionKey::Aes(Box::new(aes_gcm::Aes256Gcm::new(&(*bytes).into())))
                }
                Cipher::Aes128Gcm => {
                    let short: [u8; 16] = short_key(bytes);
                    SessionKey::Aes128(Box::new(aes_gcm::Aes128Gcm::new(&short.into())))
                }
                Cipher::Aegis128L => SessionKey::Aegis(short_key(bytes)),
            },
            #[cfg(feature = "ring")]
            Backend::Ring => {
                let (algorithm, key): (_, &[u8]) = match cipher {
                    Cipher::ChaCha20Poly1305 => (&ring::aead::CHACHA20_POLY1305, bytes),
                    Cipher::Aes256Gcm => (&ring::aead::AES_256_GCM, bytes),
                    Cipher::Aes128Gcm => (&ring::aead::AES_128_GCM, &bytes[..16]),
                    Cipher::Aegis128L => return SessionKey::Aegis(short_key(bytes)),
                };
                match ring::aead::UnboundKey::new(algorithm, key) {
                    Ok(key) => SessionKey::Ring(Box::new(ring::aead::LessSafeKey::new(key))),
                    // Every key has its algorithm's length: ring refuses none; RustCrypto's
                    // stands in.
                    Err(_) => SessionKey::new(cipher, bytes, Backend::RustCrypto),
                }
            }
        }
    }

    /// Encrypts `body` in place (empty for integrity only), authenticating `aad` with it.
    fn seal(&self, counter: u64, aad: &[u8], body: &mut [u8]) -> Option<Tag> {
        use chacha20poly1305::AeadInOut;
        let nonce = nonce(counter);
        match self {
            SessionKey::ChaCha(key) => key.encrypt_inout_detached(&nonce, aad, body.into()).ok(),
            SessionKey::Aes(key) => key.encrypt_inout_detached(&nonce, aad, body.into()).ok(),
            SessionKey::Aes128(key) => key.encrypt_inout_detached(&nonce, aad, body.into()).ok(),
            #[cfg(feature = "ring")]
            SessionKey::Ring(key) => {
                let nonce = ring::aead::Nonce::assume_unique_for_key(nonce.into());
                let tag = key
                    .seal_in_place_separate_tag(nonce, ring::aead::Aad::from(aad), body)
                    .ok()?;
                Tag::try_from(tag.as_ref()).ok()
            }
            SessionKey::Aegis(key) => {
                let aegis = aegis_at(key, counter);
                Some(Tag::from(aegis.encrypt_in_place(body, aad)))
            }
        }
    }

    /// True if it can encrypt from one buffer into another ([`SessionKey::seal_apart`]).
    fn seals_apart(&self) -> bool {
        matches!(self, SessionKey::Aegis(_))
    }

    /// Encrypts the concatenation of `parts`, less its first `skip` bytes, into `body` (as
    /// long as that), authenticating `aad` with it; `None` (and nothing written) for a cipher
    /// that encrypts only in place.
    fn seal_apart(
        &self,
        counter: u64,
        aad: &[u8],
        parts: &[&[u8]],
        mut skip: usize,
        body: &mut [u8],
    ) -> Option<Tag> {
        let SessionKey::Aegis(key) = self else {
            return None;
        };
        let aegis = aegis_at(key, counter);
        let mut encryptor = aegis.encryptor(aad);
        let mut at = 0;
        for part in parts {
            let cut = skip.min(part.len());
            skip -= cut;
            let part = &part[cut..];
            let end = at + part.len();
            encryptor.update(part, body.get_mut(at..end)?);
            at = end;
        }
        (at == body.len()).then(|| Tag::from(encryptor.finalize()))
    }

    /// Verifies `tag` and decrypts `body` in place; false if the tag does not verify.
    fn open(&self, counter: u64, aad: &[u8], body: &mut [u8], tag: &Tag) -> bool {
        use chacha20poly1305::AeadInOut;
        let nonce = nonce(counter);
        match self {
            SessionKey::ChaCha(key) => key
                .decrypt_inout_detached(&nonce, aad, body.into(), tag)
                .is_ok(),
            SessionKey::Aes(key) => key
                .decrypt_inout_detached(&nonce, aad, body.into(), tag)
                .is_ok(),
            SessionKey::Aes128(key) => key
                .decrypt_inout_detached(&nonce, aad, body.into(), tag)
                .is_ok(),
            #[cfg(feature = "ring")]
            SessionKey::Ring(key) => {
                let nonce = ring::aead::Nonce::assume_unique_for_key(nonce.into());
                let tag = ring::aead::Tag::from(<[u8; TAG_LEN]>::from(*tag));
                key.open_in_place_separate_tag(nonce, ring::aead::Aad::from(aad), tag, body, 0..)
                    .is_ok()
            }
            SessionKey::Aegis(key) => {
                let aegis = aegis_at(key, counter);
                aegis
                    .decrypt_in_place(body, &<[u8; TAG_LEN]>::from(*tag), aad)
                    .is_ok()
            }
        }
    }
}

/// What a receiver does with an arriving datagram, before anything parses its body.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Route {
    /// Handle it as it is (no key here, and it is not sealed).
    Plain,
    /// Open it with the [`Opener`] (a key here; it counts what it refuses, unsealed ndds
    /// traffic as [`OpenError::NotSealed`]).
    Open,
    /// Drop it as `sealed_without_key`: sealed, and no key here.
    SealedWithoutKey,
    /// Drop it for this reason of the plain header: not ndds traffic at all, key or not.
    Junk(crate::wire::DropReason),
}

/// Where `datagram` goes at a receiver that holds a key (`keyed`) or not. Without a key,
/// anything not sealed is [`Route::Plain`], and its header checks come later as usual.
pub fn route(datagram: &[u8], keyed: bool) -> Route {
    match (keyed, is_sealed(datagram)) {
        (false, false) => Route::Plain,
        (false, true) => Route::SealedWithoutKey,
        (true, true) => Route::Open,
        (true, false) => match crate::wire::Header::parse(datagram) {
            Ok(_) => Route::Open,
            Err(reason) => Route::Junk(reason),
        },
    }
}

/// The key of one sender's session.
fn derive(
    key: &DomainKey,
    cipher: Cipher,
    domain: u16,
    epoch: u32,
    sender: u64,
    session: u64,
) -> SessionKey {
    let hkdf = hkdf::Hkdf::<sha2::Sha256>::new(Some(b"ndds-seal-v1"), key.bytes());
    let mut info = [0u8; 1 + 2 + 4 + 8 + 8];
    info[0] = cipher.id();
    info[1..3].copy_from_slice(&domain.to_le_bytes());
    info[3..7].copy_from_slice(&epoch.to_le_bytes());
    info[7..15].copy_from_slice(&sender.to_le_bytes());
    info[15..].copy_from_slice(&session.to_le_bytes());
    let mut okm = [0u8; 32];
    // 32 bytes is far below HKDF-SHA256's limit of 8160: this cannot fail.
    let _ = hkdf.expand(&info, &mut okm);
    let session_key = SessionKey::new(cipher, &okm, Backend::PREFERRED);
    okm.fill(0);
    session_key
}

/// The first 16 bytes of a derived key: an AES-128 key.
fn short_key(bytes: &[u8; 32]) -> [u8; 16] {
    let mut short = [0u8; 16];
    short.copy_from_slice(&bytes[..16]);
    short
}

/// AEGIS-128L with `key` and the 128-bit nonce of `counter`: the counter, then 8 zero bytes.
fn aegis_at(key: &[u8; 16], counter: u64) -> aegis::aegis128l::Aegis128L<TAG_LEN> {
    let mut nonce = [0u8; 16];
    nonce[..8].copy_from_slice(&counter.to_le_bytes());
    aegis::aegis128l::Aegis128L::new(key, &nonce)
}

/// The nonce of `counter`.
fn nonce(counter: u64) -> chacha20poly1305::Nonce {
    let mut nonce = [0u8; 12];
    nonce[..8].copy_from_slice(&counter.to_le_bytes());
    nonce.into()
}

#[cfg(test)]
mod tests;

//! Ed25519 identities: a daemon's, and the administrator's that signs permissions documents.

use std::fmt;
use std::str::FromStr;

use ed25519_dalek::Signer as _;

use crate::hex::{hex, unhex};

/// The text prefix of a public key (`ed25519:` then 64 hex digits).
pub const KEY_PREFIX: &str = "ed25519:";

/// An Ed25519 public key: who a daemon or an administrator is.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PublicId([u8; 32]);

impl PublicId {
    /// The key from its 32 bytes.
    pub fn from_bytes(bytes: [u8; 32]) -> Self {
        PublicId(bytes)
    }

    /// Its 32 bytes.
    pub fn as_bytes(&self) -> &[u8; 32] {
        &self.0
    }

    /// Whether `signature` is this key's signature of `message`.
    pub fn verifies(&self, message: &[u8], signature: &[u8; 64]) -> bool {
        let Ok(key) = ed25519_dalek::VerifyingKey::from_bytes(&self.0) else {
            return false;
        };
        let signature = ed25519_dalek::Signature::from_bytes(signature);
        key.verify_strict(message, &signature).is_ok()
    }

    /// The first 8 hex digits, for tables.
    pub fn short(&self) -> String {
        hex(&self.0[..4])
    }
}

impl fmt::Display for PublicId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{KEY_PREFIX}{}", hex(&self.0))
    }
}

impl fmt::Debug for PublicId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "PublicId({self})")
    }
}

/// Why a key's text form was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum KeyTextError {
    /// Not `ed25519:` followed by 64 hex digits.
    #[error("`{0}` is not a public key: expected `ed25519:` followed by 64 hex digits")]
    Malformed(String),
    /// 32 bytes that are not a point of the curve.
    #[error("`{0}` is not a valid Ed25519 public key")]
    NotAKey(String),
}

impl FromStr for PublicId {
    type Err = KeyTextError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let text = text.trim();
        let digits = text
            .strip_prefix(KEY_PREFIX)
            .ok_or_else(|| KeyTextError::Malformed(text.to_owned()))?;
        let bytes: [u8; 32] =
            unhex(digits).ok_or_else(|| KeyTextError::Malformed(text.to_owned()))?;
        ed25519_dalek::VerifyingKey::from_bytes(&bytes)
            .map_err(|_| KeyTextError::NotAKey(text.to_owned()))?;
        Ok(PublicId(bytes))
    }
}

impl serde::Serialize for PublicId {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> serde::Deserialize<'de> for PublicId {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = <std::borrow::Cow<'de, str>>::deserialize(deserializer)?;
        text.parse().map_err(serde::de::Error::custom)
    }
}

/// A secret Ed25519 key: a daemon's identity, or an administrator's signing key.
///
/// The secret never appears in `Debug` output.
#[derive(Clone)]
pub struct Identity {
    key: ed25519_dalek::SigningKey,
    /// The secret of the X25519 agreement key: derived from the identity's secret, or drawn
    /// for one run of a daemon ([`Identity::with_session_agreement`]).
    agreement_secret: [u8; 32],
    /// The public half of the agreement key (computed once: every signed datagram carries it).
    agreement: [u8; 32],
}

impl Identity {
    /// The identity whose secret is these 32 bytes (drawn from the operating system's random
    /// source by the caller: this crate does no IO).
    pub fn from_secret(secret: [u8; 32]) -> Self {
        let mut identity = Identity {
            key: ed25519_dalek::SigningKey::from_bytes(&secret),
            agreement_secret: [0; 32],
            agreement: [0; 32],
        };
        let derived = identity.derive(b"x25519 agreement");
        identity.set_agreement(derived);
        identity
    }

    /// The same identity with an agreement key of this run only, its secret `random` (32
    /// bytes from the operating system's random source, never written anywhere). A daemon
    /// takes one at each start: the secrets it shares with other daemons, and the data keys
    /// derived from them, then come from keys that die with the process, so someone who later
    /// steals the identity file cannot open data recorded before (forward secrecy, per run of
    /// the daemon). The agreement key is announced signed by the identity, so peers trust it
    /// as they trust the identity.
    pub fn with_session_agreement(mut self, random: [u8; 32]) -> Self {
        self.set_agreement(random);
        self
    }

    fn set_agreement(&mut self, secret: [u8; 32]) {
        self.agreement_secret = secret;
        self.agreement = x25519_dalek::PublicKey::from(&self.agreement_secret()).to_bytes();
    }

    /// The public half.
    pub fn public(&self) -> PublicId {
        PublicId(self.key.verifying_key().to_bytes())
    }

    /// Signs `message`.
    pub fn sign(&self, message: &[u8]) -> [u8; 64] {
        self.key.sign(message).to_bytes()
    }

    /// 32 secret bytes for `purpose`, derived from the identity's secret (HKDF-SHA256): the
    /// identity's other keys, each for one use only.
    pub fn derive(&self, purpose: &[u8]) -> [u8; 32] {
        let hkdf = hkdf::Hkdf::<sha2::Sha256>::new(Some(b"ndds-identity-v1"), self.key.as_bytes());
        let mut out = [0u8; 32];
        // 32 bytes is far below HKDF-SHA256's limit: this cannot fail.
        let _ = hkdf.expand(purpose, &mut out);
        out
    }

    /// The public half of this identity's X25519 key agreement key (announced, signed, in
    /// every `Signed` datagram).
    pub fn agreement_public(&self) -> [u8; 32] {
        self.agreement
    }

    /// The secret this identity shares with the holder of the agreement key `peer` (X25519,
    /// then HKDF with both public keys in order, so both sides derive the same bytes);
    /// `None` for a degenerate peer key (a low-order point).
    pub fn shared_secret(&self, peer: &[u8; 32]) -> Option<[u8; 32]> {
        let own = self.agreement_public();
        let shared = self
            .agreement_secret()
            .diffie_hellman(&x25519_dalek::PublicKey::from(*peer));
        if !shared.was_contributory() {
            return None;
        }
        let (low, high) = if own <= *peer {
            (own, *peer)
        } else {
            (*peer, own)
        };
        let hkdf = hkdf::Hkdf::<sha2::Sha256>::new(Some(b"ndds-pair-v1"), shared.as_bytes());
        let mut info = [0u8; 64];
        info[..32].copy_from_slice(&low);
        info[32..].copy_from_slice(&high);
        let mut out = [0u8; 32];
        let _ = hkdf.expand(&info, &mut out);
        Some(out)
    }

    fn agreement_secret(&self) -> x25519_dalek::StaticSecret {
        x25519_dalek::StaticSecret::from(self.agreement_secret)
    }

    /// 32 secret bytes for `purpose`, derived from the agreement key's secret: of this run
    /// only when the agreement key is a session's (the data keys of two participants of one
    /// daemon).
    pub fn derive_agreement(&self, purpose: &[u8]) -> [u8; 32] {
        let hkdf =
            hkdf::Hkdf::<sha2::Sha256>::new(Some(b"ndds-agreement-v1"), &self.agreement_secret);
        let mut out = [0u8; 32];
        // 32 bytes is far below HKDF-SHA256's limit: this cannot fail.
        let _ = hkdf.expand(purpose, &mut out);
        out
    }

    /// The text of an identity file: the secret and, for reading by eye, the public key.
    pub fn to_file_text(&self) -> String {
        format!(
            "# ndds identity: keep this file secret (mode 0600)\nsecret {}\npublic {}\n",
            hex(self.key.as_bytes()),
            self.public()
        )
    }

    /// Reads an identity file written by [`Identity::to_file_text`].
    pub fn parse(text: &str) -> Result<Identity, IdentityFileError> {
        let mut secret = None;
        let mut public = None;
        for (index, line) in text.lines().enumerate() {
            let line_no = index + 1;
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            match line.split_once(' ') {
                Some(("secret", value)) => {
                    let bytes: [u8; 32] =
                        unhex(value.trim()).ok_or(IdentityFileError::BadLine(line_no))?;
                    secret = Some(bytes);
                }
                Some(("public", value)) => {
                    public = Some(
                        value
                            .parse::<PublicId>()
                            .map_err(|_| IdentityFileError::BadLine(line_no))?,
                    );
                }
                _ => return Err(IdentityFileError::BadLine(line_no)),
            }
        }
        let identity = Identity::from_secret(secret.ok_or(IdentityFileError::NoSecret)?);
        if public.is_some_and(|public| public != identity.public()) {
            return Err(IdentityFileError::Mismatch);
        }
        Ok(identity)
    }
}

impl fmt::Debug for Identity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Identity")
            .field("public", &self.public())
            .finish_non_exhaustive()
    }
}

impl PartialEq for Identity {
    fn eq(&self, other: &Self) -> bool {
        self.public() == other.public()
    }
}

impl Eq for Identity {}

/// Why an identity file was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum IdentityFileError {
    /// A line that is neither `secret HEX` nor `public ed25519:HEX`.
    #[error("line {0}: expected `secret <64 hex digits>` or `public ed25519:<64 hex digits>`")]
    BadLine(usize),
    /// No `secret` line.
    #[error("no `secret` line: not an ndds identity file")]
    NoSecret,
    /// The `public` line is not the secret's public key.
    #[error("the `public` line is not the public key of the `secret` line (edited by hand?)")]
    Mismatch,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_identities_agree_on_their_secret_and_a_session_key_keeps_it_from_the_file() {
        let (a, b) = (
            Identity::from_secret([1; 32]),
            Identity::from_secret([2; 32]),
        );
        let shared = a.shared_secret(&b.agreement_public()).unwrap();
        assert_eq!(b.shared_secret(&a.agreement_public()), Some(shared));
        // A daemon's run draws its agreement key: the two runs still agree with each other ...
        let (a_run, b_run) = (
            a.clone().with_session_agreement([3; 32]),
            b.clone().with_session_agreement([4; 32]),
        );
        assert_eq!(a_run.public(), a.public(), "the identity is the same");
        let run_shared = a_run.shared_secret(&b_run.agreement_public()).unwrap();
        assert_eq!(
            b_run.shared_secret(&a_run.agreement_public()),
            Some(run_shared)
        );
        // ... and what the identity files give cannot make that secret: neither side's file
        // with the other's announced key, nor the files' own agreement keys.
        let a_file = Identity::parse(&a.to_file_text()).unwrap();
        assert_ne!(a_file.agreement_public(), a_run.agreement_public());
        assert_ne!(
            a_file.shared_secret(&b_run.agreement_public()),
            Some(run_shared)
        );
        assert_ne!(shared, run_shared);
        // Two participants of one daemon: their keys are of the run too.
        assert_ne!(
            a_run.derive_agreement(b"local data pairs"),
            a_file.derive_agreement(b"local data pairs")
        );
        // A low-order peer key gives no secret.
        assert_eq!(a_run.shared_secret(&[0; 32]), None);
    }
}

//! Sealing what one sender sends.

use super::{CLEAR, Cipher, KIND_BYTE, Keyring, SEALED, SEALED_HEAD, SealMode, SessionKey, derive};
use crate::wire::HEADER_LEN;

/// Why a datagram was not sealed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SealError {
    /// Shorter than the fixed header: not a datagram of ours.
    #[error("not a datagram (shorter than the header)")]
    NotADatagram,
    /// The session's counter is used up (2^64 datagrams): a new session is needed.
    #[error("the session's counter is used up")]
    Exhausted,
}

/// The sealing state of one sender (a daemon or a participant) for one session.
pub struct Sealer {
    domain: u16,
    sender: u64,
    session: u64,
    epoch: u32,
    mode: SealMode,
    cipher: Cipher,
    key: SessionKey,
    counter: u64,
}

impl std::fmt::Debug for Sealer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Sealer")
            .field("domain", &self.domain)
            .field("sender", &self.sender)
            .field("session", &self.session)
            .field("epoch", &self.epoch)
            .field("mode", &self.mode)
            .field("cipher", &self.cipher)
            .field("counter", &self.counter)
            .finish_non_exhaustive()
    }
}

impl Sealer {
    /// Seals as `sender` of `domain` with `keyring`'s sending key. `session` must grow from
    /// one start of the sender to the next (its start time in microseconds does).
    pub fn new(keyring: &Keyring, domain: u16, sender: u64, session: u64, mode: SealMode) -> Self {
        let epoch = keyring.send_epoch();
        Sealer {
            domain,
            sender,
            session,
            epoch,
            mode,
            cipher: keyring.cipher(),
            key: derive(
                keyring.send_key(),
                keyring.cipher(),
                domain,
                epoch,
                sender,
                session,
            ),
            counter: 0,
        }
    }

    /// Seals with `keyring`'s sending key from now on (after a rotation).
    pub fn rekey(&mut self, keyring: &Keyring) {
        if keyring.send_epoch() != self.epoch || keyring.cipher() != self.cipher {
            self.epoch = keyring.send_epoch();
            self.cipher = keyring.cipher();
            self.key = derive(
                keyring.send_key(),
                self.cipher,
                self.domain,
                self.epoch,
                self.sender,
                self.session,
            );
        }
    }

    /// The key epoch it seals with.
    pub fn epoch(&self) -> u32 {
        self.epoch
    }

    /// The session it seals for.
    pub fn session(&self) -> u64 {
        self.session
    }

    /// Encrypted, or integrity only.
    pub fn mode(&self) -> SealMode {
        self.mode
    }

    /// Datagrams sealed so far in this session.
    pub fn sealed(&self) -> u64 {
        self.counter
    }

    /// Seals `datagram` (a plain one: header and body) in place: the seal head goes after
    /// the header, the body is encrypted (or left in clear, integrity only), the tag appended.
    pub fn seal(&mut self, datagram: &mut Vec<u8>) -> Result<(), SealError> {
        self.ready(datagram.len())?;
        datagram.splice(HEADER_LEN..HEADER_LEN, [0; super::SEAL_HEAD_LEN]);
        self.seal_spaced(datagram)
    }

    /// Writes the plain datagram `parts` (pieces in order; the header may span them) into
    /// `out` (whatever it held is overwritten), sealed: the same bytes as [`Sealer::seal`] of
    /// their concatenation, without moving the body to make room for the seal head. With a
    /// cipher that writes its output apart from its input (AEGIS-128L), the body is encrypted
    /// from `parts` straight into `out` instead of being copied there first.
    pub fn seal_into(&mut self, out: &mut Vec<u8>, parts: &[&[u8]]) -> Result<(), SealError> {
        let len: usize = parts.iter().map(|part| part.len()).sum();
        self.ready(len)?;
        if self.mode == SealMode::Encrypt && self.key.seals_apart() {
            let sealed_len = len + super::SEAL_HEAD_LEN;
            // Every byte up to `sealed_len` is written below, so a recycled buffer is only
            // cut or grown, not cleared.
            out.resize(sealed_len, 0);
            let mut header_at = 0;
            for part in parts {
                let take = (HEADER_LEN - header_at).min(part.len());
                out[header_at..header_at + take].copy_from_slice(&part[..take]);
                header_at += take;
            }
            let counter = self.stamp(out);
            let (aad, body) = out.split_at_mut(SEALED_HEAD);
            let tag = self
                .key
                .seal_apart(counter, aad, parts, HEADER_LEN, body)
                .ok_or(SealError::NotADatagram)?;
            out.extend_from_slice(&tag);
            return Ok(());
        }
        out.clear();
        out.reserve(len + super::OVERHEAD);
        let mut header_left = HEADER_LEN;
        for part in parts {
            let (header, rest) = part.split_at(header_left.min(part.len()));
            out.extend_from_slice(header);
            header_left -= header.len();
            if header_left == 0 && !header.is_empty() {
                out.extend_from_slice(&[0; super::SEAL_HEAD_LEN]);
            }
            out.extend_from_slice(rest);
        }
        self.seal_spaced(out)
    }

    /// Whether a plain datagram of `len` bytes can be sealed now.
    fn ready(&self, len: usize) -> Result<(), SealError> {
        if len < HEADER_LEN {
            return Err(SealError::NotADatagram);
        }
        if self.counter == u64::MAX {
            return Err(SealError::Exhausted);
        }
        Ok(())
    }

    /// Seals a plain datagram whose header is already followed by room for the seal head.
    fn seal_spaced(&mut self, datagram: &mut Vec<u8>) -> Result<(), SealError> {
        let counter = self.stamp(datagram);
        let tag = match self.mode {
            SealMode::Encrypt => {
                let (aad, body) = datagram.split_at_mut(SEALED_HEAD);
                self.key.seal(counter, aad, body)
            }
            SealMode::IntegrityOnly => self.key.seal(counter, datagram, &mut []),
        };
        // Only messages of many GiB make this fail.
        let tag = tag.ok_or(SealError::NotADatagram)?;
        datagram.extend_from_slice(&tag);
        Ok(())
    }

    /// Takes the next counter and writes the seal flags and the seal head into `datagram`
    /// (a header followed by room for the seal head); the counter.
    fn stamp(&mut self, datagram: &mut [u8]) -> u64 {
        let counter = self.counter;
        self.counter += 1;
        datagram[KIND_BYTE] |= SEALED;
        if self.mode == SealMode::IntegrityOnly {
            datagram[KIND_BYTE] |= CLEAR;
        }
        let head = &mut datagram[HEADER_LEN..SEALED_HEAD];
        head[..4].copy_from_slice(&self.epoch.to_le_bytes());
        head[4..12].copy_from_slice(&self.session.to_le_bytes());
        head[12..].copy_from_slice(&counter.to_le_bytes());
        counter
    }
}

//! Opening what arrives: authentication, replay and session checks, before any parsing.

use std::time::{Duration, Instant};

use foldhash::HashMap;

use super::window::ReplayWindow;
use super::{
    CLEAR, KIND_BYTE, Keyring, MAX_SENDERS, OpenError, SEAL_HEAD_LEN, SEALED, SEALED_HEAD,
    SessionKey, TAG_LEN, Tag, derive,
};
use crate::wire::HEADER_LEN;

/// A sender's older session is refused while its newest one was heard within this; after it,
/// an older session may start again (a restarted sender whose clock stepped back).
pub const SESSION_IDLE: Duration = Duration::from_secs(60);

/// Counters of an [`Opener`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OpenStats {
    /// Datagrams opened.
    pub opened: u64,
    /// Datagrams dropped, by [`OpenError::index`].
    pub dropped: [u64; OpenError::ALL.len()],
    /// Senders' states forgotten to make room for another ([`MAX_SENDERS`]).
    pub evicted: u64,
}

impl OpenStats {
    /// The drop count for one reason.
    pub fn dropped(&self, reason: OpenError) -> u64 {
        self.dropped[reason.index()]
    }
}

/// An opened datagram: the plain datagram (header with the seal flags cleared, then the
/// body) inside the buffer given to [`Opener::open`].
pub type Opened<'a> = &'a [u8];

/// What a receiver remembers of one sender under one epoch.
struct SenderState {
    session: u64,
    cipher: SessionKey,
    window: ReplayWindow,
    heard: Instant,
}

/// The receiving side of a sealed domain (see the module documentation).
pub struct Opener {
    keyring: Keyring,
    /// Data keys by sender, in a domain with permissions: a sender's datagrams open with its
    /// key, never with the domain's.
    pair_keys: HashMap<u64, super::DomainKey>,
    /// Refuse senders without a data key (a participant of a domain with permissions).
    require_pairs: bool,
    domain: u16,
    require_encryption: bool,
    senders: HashMap<(u64, u32), SenderState>,
    stats: OpenStats,
}

impl std::fmt::Debug for Opener {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Opener")
            .field("domain", &self.domain)
            .field("epochs", &self.keyring.epochs().collect::<Vec<_>>())
            .field("require_encryption", &self.require_encryption)
            .field("senders", &self.senders.len())
            .field("stats", &self.stats)
            .finish()
    }
}

impl Opener {
    /// Opens datagrams of `domain` sealed with any key of `keyring`; integrity-only ones only
    /// unless `require_encryption`.
    pub fn new(keyring: Keyring, domain: u16, require_encryption: bool) -> Self {
        Opener {
            keyring,
            pair_keys: HashMap::default(),
            require_pairs: false,
            domain,
            require_encryption,
            senders: HashMap::default(),
            stats: OpenStats::default(),
        }
    }

    /// Opens `sender`'s datagrams with `key` only from now on (its data key, in a domain
    /// with permissions); at most [`super::MAX_SENDERS`] senders have one (more are refused,
    /// false).
    pub fn set_pair_key(&mut self, sender: u64, key: super::DomainKey) -> bool {
        if self.pair_keys.get(&sender) == Some(&key) {
            // The same key again (another match of the same pair): its replay state stays.
            return true;
        }
        if !self.pair_keys.contains_key(&sender) && self.pair_keys.len() >= super::MAX_SENDERS {
            return false;
        }
        self.pair_keys.insert(sender, key);
        // What was derived from the domain key for this sender no longer counts.
        self.senders.retain(|(from, _), _| *from != sender);
        true
    }

    /// Forgets `sender`'s data key and what was opened from it (its pair was unmatched a
    /// while ago).
    pub fn remove_pair_key(&mut self, sender: u64) {
        if self.pair_keys.remove(&sender).is_some() {
            self.senders.retain(|(from, _), _| *from != sender);
        }
    }

    /// Refuses every sender without a data key ([`Opener::set_pair_key`]).
    pub fn require_pair_keys(&mut self) {
        self.require_pairs = true;
    }

    /// Takes a new keyring (a rotation step): senders of epochs it no longer holds are
    /// forgotten, and their datagrams refused from now on. Senders with a data key open with
    /// it whatever their epoch: what was opened from them stays (their replay windows with
    /// it).
    pub fn set_keyring(&mut self, keyring: Keyring) {
        let pair_keys = &self.pair_keys;
        self.senders.retain(|(sender, epoch), _| {
            pair_keys.contains_key(sender) || keyring.key(*epoch).is_some()
        });
        self.keyring = keyring;
    }

    /// The keyring in force.
    pub fn keyring(&self) -> &Keyring {
        &self.keyring
    }

    /// Counters.
    pub fn stats(&self) -> &OpenStats {
        &self.stats
    }

    /// Senders whose state is kept.
    pub fn senders(&self) -> usize {
        self.senders.len()
    }

    /// Checks and opens `datagram` in place, returning the plain datagram within it; or
    /// says, and counts, why not. Never panics, allocates only for a sender whose tag
    /// verified, and spends no cryptography on replays and stale sessions.
    pub fn open<'a>(
        &mut self,
        now: Instant,
        datagram: &'a mut [u8],
    ) -> Result<Opened<'a>, OpenError> {
        match self.check(now, datagram) {
            Ok(len) => {
                self.stats.opened += 1;
                // The header moves up against the body, its seal flags cleared.
                datagram.copy_within(..HEADER_LEN, SEAL_HEAD_LEN);
                datagram[SEAL_HEAD_LEN + KIND_BYTE] &= !(SEALED | CLEAR);
                Ok(&datagram[SEAL_HEAD_LEN..SEAL_HEAD_LEN + len])
            }
            Err(error) => {
                self.stats.dropped[error.index()] += 1;
                Err(error)
            }
        }
    }

    /// Verifies and decrypts; the length of the plain datagram.
    fn check(&mut self, now: Instant, datagram: &mut [u8]) -> Result<usize, OpenError> {
        if datagram.len() < SEALED_HEAD + TAG_LEN {
            return Err(
                if super::is_sealed(datagram) || datagram.len() < HEADER_LEN {
                    OpenError::Truncated
                } else {
                    OpenError::NotSealed
                },
            );
        }
        let kind = datagram[KIND_BYTE];
        if kind & SEALED == 0 {
            return Err(OpenError::NotSealed);
        }
        let clear = kind & CLEAR != 0;
        if clear && self.require_encryption {
            return Err(OpenError::ClearRefused);
        }
        let sender = u64_at(datagram, 8);
        let epoch = u32::from_le_bytes([datagram[16], datagram[17], datagram[18], datagram[19]]);
        let session = u64_at(datagram, 20);
        let counter = u64_at(datagram, 28);
        let key = match self.pair_keys.get(&sender) {
            Some(key) => key,
            None if self.require_pairs => return Err(OpenError::Unkeyed),
            None => self.keyring.key(epoch).ok_or(OpenError::UnknownEpoch)?,
        };
        let known = self.senders.get(&(sender, epoch));
        let same_session = known.is_some_and(|state| state.session == session);
        if let Some(state) = known {
            if same_session && !state.window.fresh(counter) {
                return Err(OpenError::Replayed);
            }
            let idle = now.saturating_duration_since(state.heard) >= SESSION_IDLE;
            if session < state.session && !idle {
                return Err(OpenError::StaleSession);
            }
        }
        // The session's key, or a new session's, derived (and kept only if its tag verifies).
        let mut derived = None;
        let cipher: &SessionKey = match known.filter(|_| same_session) {
            Some(state) => &state.cipher,
            None => derived.insert(derive(
                key,
                self.keyring.cipher(),
                self.domain,
                epoch,
                sender,
                session,
            )),
        };
        let body_end = datagram.len() - TAG_LEN;
        let (sealed, tag) = datagram.split_at_mut(body_end);
        let tag = Tag::try_from(&tag[..]).map_err(|_| OpenError::Truncated)?;
        let verified = if clear {
            cipher.open(counter, sealed, &mut [], &tag)
        } else {
            let (aad, body) = sealed.split_at_mut(SEALED_HEAD);
            cipher.open(counter, aad, body, &tag)
        };
        if !verified {
            return Err(OpenError::BadTag);
        }
        match derived {
            None => {
                if let Some(state) = self.senders.get_mut(&(sender, epoch)) {
                    state.window.accept(counter);
                    state.heard = now;
                }
            }
            Some(cipher) => {
                let mut window = ReplayWindow::new();
                window.accept(counter);
                let known = self.senders.contains_key(&(sender, epoch));
                if !known && self.senders.len() >= MAX_SENDERS {
                    self.evict_one();
                }
                let state = SenderState {
                    session,
                    cipher,
                    window,
                    heard: now,
                };
                self.senders.insert((sender, epoch), state);
            }
        }
        Ok(body_end - SEAL_HEAD_LEN)
    }

    /// Forgets the sender heard least recently.
    fn evict_one(&mut self) {
        let oldest = self
            .senders
            .iter()
            .min_by_key(|(_, state)| state.heard)
            .map(|(key, _)| *key);
        if let Some(oldest) = oldest {
            self.senders.remove(&oldest);
            self.stats.evicted += 1;
        }
    }
}

fn u64_at(bytes: &[u8], at: usize) -> u64 {
    let mut word = [0u8; 8];
    word.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(word)
}

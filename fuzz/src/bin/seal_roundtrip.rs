//! Sealing and opening together, so that the fuzzer reaches everything past the tag: the
//! replay window, sessions, senders' state and eviction, decryption in place. The harness
//! seals datagrams it builds from the input with the fixture key, then delivers them, again,
//! late, corrupted or after a pause, and checks what must hold:
//!
//! - a datagram delivered for the first time and in its session's newest counter opens, and
//!   `open(seal(x)) == x` (unless its session is older than one already heard, or it is
//!   integrity-only where encryption is required);
//! - a datagram that opened once never opens again, unless its sender's state moved to
//!   another session and back since (an older session is accepted again once the newest
//!   one was idle for `SESSION_IDLE`, with a fresh replay window: see "Replays across
//!   sessions" in docs/fuzzing.md);
//! - a datagram with any bit flipped never opens;
//! - sealed in three pieces into a recycled buffer of old bytes (`Sealer::seal_into`, the data
//!   plane's way), a datagram has the bytes `Sealer::seal` gives it.
//!
//! ```text
//! input := flags { sel u16le-length-chunk }
//! flags  bit 0: AES-GCM (bit 3: AES-128); bit 4: AEGIS-128L; bit 1: integrity only; bit 2:
//!        encryption required
//! sel    bits 0-1: action (0 seal and deliver, 1 seal and hold back, 2 deliver again an
//!        earlier datagram, 3 deliver one with a bit flipped); bit 2: sender; bits 3-4:
//!        session; bits 5-7 with the chunk's first byte: time that passes first (seconds)
//! chunk  kind byte, then the body (seal actions); index u8 and bit u16le (others)
//! ```

use std::collections::HashMap;
use std::time::{Duration, Instant};

use ndds_core::seal::{OpenError, Opener, Route, SealMode, Sealer, route};
use ndds_core::wire::{Header, MessageKind};
use ndds_fuzz::Input;
use ndds_fuzz::fixture::{DOMAIN, cipher, keyring};

/// A datagram sealed by the harness: the plain bytes, the sealed bytes, opened once yet.
struct Sealed {
    plain: Vec<u8>,
    sealed: Vec<u8>,
    opened: bool,
    /// The sender and session that sealed it.
    session: (u64, u64),
    /// Its sender's session changes (in the opener) when it opened.
    changes_at_open: u32,
}

/// What the opener keeps of one sender, as the harness models it: the session of its
/// state, and how often that session changed.
#[derive(Default)]
struct SenderModel {
    session: Option<u64>,
    changes: u32,
}

/// `plain` cut in three pieces, and a recycled buffer of old bytes to seal them into; the
/// cuts and the buffer's length follow from `sel` and the bytes themselves.
fn cut(sel: u8, plain: &[u8]) -> ([&[u8]; 3], Vec<u8>) {
    let hash = plain.iter().fold(usize::from(sel), |hash, byte| {
        hash.wrapping_mul(31).wrapping_add(usize::from(*byte))
    });
    let len = plain.len();
    let first = hash % (len + 1);
    let second = first + (hash / 7) % (len + 1 - first);
    let recycled = vec![0xa5; (hash / 13) % (2 * len + 64)];
    (
        [&plain[..first], &plain[first..second], &plain[second..]],
        recycled,
    )
}

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let mut input = Input::new(data);
        let flags = input.u8();
        let keys = keyring(cipher(flags));
        let mode = if flags & 2 != 0 {
            SealMode::IntegrityOnly
        } else {
            SealMode::Encrypt
        };
        let require_encryption = flags & 4 != 0;
        let mut opener = Opener::new(keys.clone(), DOMAIN, require_encryption);
        let mut sealers: HashMap<(u64, u64), Sealer> = HashMap::new();
        // A second sealer per sender and session, sealing the same datagrams in pieces into a
        // recycled buffer (`Sealer::seal_into`, as the data plane does).
        let mut twins: HashMap<(u64, u64), Sealer> = HashMap::new();
        let mut model: HashMap<u64, SenderModel> = HashMap::new();
        let mut sent: Vec<Sealed> = Vec::new();
        let mut now = Instant::now();
        while !input.is_empty() {
            let sel = input.u8();
            let mut chunk = Input::new(input.chunk());
            let pause = u64::from(sel >> 5) * 30;
            now += Duration::from_secs(pause);
            let sender = 0x100 + u64::from(sel >> 2 & 1);
            let session = 1 + u64::from(sel >> 3 & 3);
            match sel & 3 {
                action @ (0 | 1) => {
                    let kind = MessageKind::ALL[usize::from(chunk.u8()) % MessageKind::ALL.len()];
                    let mut plain = Vec::new();
                    Header {
                        kind,
                        domain: DOMAIN,
                        sender,
                    }
                    .emit(&mut plain);
                    plain.extend_from_slice(chunk.rest());
                    let sealer = sealers
                        .entry((sender, session))
                        .or_insert_with(|| Sealer::new(&keys, DOMAIN, sender, session, mode));
                    let mut sealed = plain.clone();
                    sealer
                        .seal(&mut sealed)
                        .expect("a datagram with a header seals");
                    let twin = twins
                        .entry((sender, session))
                        .or_insert_with(|| Sealer::new(&keys, DOMAIN, sender, session, mode));
                    let (pieces, mut recycled) = cut(sel, &plain);
                    twin.seal_into(&mut recycled, &pieces)
                        .expect("a datagram with a header seals in pieces");
                    assert_eq!(recycled, sealed, "sealed in pieces, the same bytes");
                    assert_eq!(route(&sealed, true), Route::Open);
                    assert_eq!(route(&sealed, false), Route::SealedWithoutKey);
                    sent.push(Sealed {
                        plain,
                        sealed,
                        opened: false,
                        session: (sender, session),
                        changes_at_open: 0,
                    });
                    if action == 0 {
                        let index = sent.len() - 1;
                        let current = model.get(&sender).and_then(|m| m.session);
                        let result = deliver(&mut opener, now, &mut sent[index], &mut model);
                        match result {
                            Ok(()) => {}
                            Err(OpenError::ClearRefused) => {
                                assert!(require_encryption && mode == SealMode::IntegrityOnly)
                            }
                            Err(OpenError::StaleSession) => {
                                assert!(current.is_some_and(|c| session < c))
                            }
                            Err(err) => panic!("a fresh datagram did not open: {err}"),
                        }
                    }
                }
                2 => {
                    if sent.is_empty() {
                        continue;
                    }
                    let index = usize::from(chunk.u8()) % sent.len();
                    let _ = deliver(&mut opener, now, &mut sent[index], &mut model);
                }
                _ => {
                    if sent.is_empty() {
                        continue;
                    }
                    let index = usize::from(chunk.u8()) % sent.len();
                    let mut corrupted = sent[index].sealed.clone();
                    let bit = usize::from(chunk.u16()) % (corrupted.len() * 8);
                    corrupted[bit / 8] ^= 1 << (bit % 8);
                    assert!(
                        opener.open(now, &mut corrupted).is_err(),
                        "a corrupted datagram opened"
                    );
                }
            }
        }
    });
}

/// Opens a copy of `datagram`'s sealed bytes; on success checks that it is the plain
/// datagram and marks it opened.
fn deliver(
    opener: &mut Opener,
    now: Instant,
    datagram: &mut Sealed,
    model: &mut HashMap<u64, SenderModel>,
) -> Result<(), OpenError> {
    let mut bytes = datagram.sealed.clone();
    let plain = opener.open(now, &mut bytes)?;
    assert_eq!(
        plain,
        datagram.plain.as_slice(),
        "open(seal(x)) differs from x"
    );
    let (sender, session) = datagram.session;
    let sender_model = model.entry(sender).or_default();
    if sender_model.session != Some(session) {
        sender_model.session = Some(session);
        sender_model.changes += 1;
    }
    // Opening again needs a fresh window: the state moved away from this session and back.
    assert!(
        !datagram.opened || sender_model.changes >= datagram.changes_at_open + 2,
        "a datagram opened twice in one session state"
    );
    datagram.opened = true;
    datagram.changes_at_open = sender_model.changes;
    Ok(())
}

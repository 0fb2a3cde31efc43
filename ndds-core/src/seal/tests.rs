//! Sealing and opening together: round trips, tampering, replays, sessions, rotation.

use std::time::{Duration, Instant};

use proptest::prelude::*;

use super::*;
use crate::hex::unhex;
use crate::wire::{Header, MessageKind};

const DOMAIN: u16 = 7;

fn ring(epoch: u32, byte: u8) -> Keyring {
    Keyring::new(epoch, DomainKey::from_bytes([byte; 32]))
}

fn plain(sender: u64, body: &[u8]) -> Vec<u8> {
    let mut datagram = Vec::new();
    Header {
        kind: MessageKind::Data,
        domain: DOMAIN,
        sender,
    }
    .emit(&mut datagram);
    datagram.extend_from_slice(body);
    datagram
}

fn sealed(sealer: &mut Sealer, sender: u64, body: &[u8]) -> Vec<u8> {
    let mut datagram = plain(sender, body);
    sealer.seal(&mut datagram).unwrap();
    datagram
}

#[test]
fn a_sealed_datagram_opens_to_the_plain_one_and_hides_its_body() {
    let t0 = Instant::now();
    let mut sealer = Sealer::new(&ring(1, 9), DOMAIN, 42, 1000, SealMode::Encrypt);
    let mut opener = Opener::new(ring(1, 9), DOMAIN, true);
    let body = b"the arm's pose, in clear nowhere on the wire";
    let mut datagram = sealed(&mut sealer, 42, body);
    assert_eq!(datagram.len(), HEADER_LEN + body.len() + OVERHEAD);
    assert!(is_sealed(&datagram));
    assert!(
        !datagram.windows(8).any(|w| w == b"the arm'"),
        "body in clear"
    );
    assert_eq!(opener.open(t0, &mut datagram), Ok(&plain(42, body)[..]));
    assert_eq!(opener.stats().opened, 1);
}

#[test]
fn integrity_only_leaves_the_body_readable_and_still_authenticates_it() {
    let t0 = Instant::now();
    let mut sealer = Sealer::new(&ring(1, 9), DOMAIN, 42, 1, SealMode::IntegrityOnly);
    let body = b"readable by tcpdump";
    let datagram = sealed(&mut sealer, 42, body);
    assert!(datagram.windows(body.len()).any(|w| w == body));
    let mut strict = Opener::new(ring(1, 9), DOMAIN, true);
    assert_eq!(
        strict.open(t0, &mut datagram.clone()),
        Err(OpenError::ClearRefused)
    );
    let mut lenient = Opener::new(ring(1, 9), DOMAIN, false);
    let mut changed = datagram.clone();
    let at = HEADER_LEN + SEAL_HEAD_LEN;
    changed[at] ^= 1;
    assert_eq!(lenient.open(t0, &mut changed), Err(OpenError::BadTag));
    assert_eq!(
        lenient.open(t0, &mut datagram.clone()),
        Ok(&plain(42, body)[..])
    );
}

#[test]
fn every_changed_byte_and_every_wrong_key_fails_the_tag() {
    let t0 = Instant::now();
    let mut sealer = Sealer::new(&ring(1, 9), DOMAIN, 42, 1, SealMode::Encrypt);
    let datagram = sealed(&mut sealer, 42, b"0123456789");
    for at in 0..datagram.len() {
        if at == 5 {
            continue; // the kind byte: its flags are judged before the tag
        }
        let mut opener = Opener::new(ring(1, 9), DOMAIN, true);
        let mut changed = datagram.clone();
        changed[at] ^= 0x10;
        let result = opener.open(t0, &mut changed);
        assert!(
            matches!(result, Err(OpenError::BadTag | OpenError::UnknownEpoch)),
            "byte {at}: {result:?}"
        );
    }
    let mut other_key = Opener::new(ring(1, 8), DOMAIN, true);
    assert_eq!(
        other_key.open(t0, &mut datagram.clone()),
        Err(OpenError::BadTag)
    );
    let mut other_domain = Opener::new(ring(1, 9), DOMAIN + 1, true);
    assert_eq!(
        other_domain.open(t0, &mut datagram.clone()),
        Err(OpenError::BadTag)
    );
    assert_eq!(other_key.senders(), 0, "no state for what did not verify");
}

#[test]
fn a_replayed_datagram_is_refused_and_reordering_is_not() {
    let t0 = Instant::now();
    let mut sealer = Sealer::new(&ring(1, 9), DOMAIN, 42, 1, SealMode::Encrypt);
    let mut opener = Opener::new(ring(1, 9), DOMAIN, true);
    let first = sealed(&mut sealer, 42, b"a");
    let second = sealed(&mut sealer, 42, b"b");
    assert!(opener.open(t0, &mut second.clone()).is_ok());
    assert!(opener.open(t0, &mut first.clone()).is_ok(), "reordered");
    assert_eq!(
        opener.open(t0, &mut first.clone()),
        Err(OpenError::Replayed)
    );
    assert_eq!(
        opener.open(t0, &mut second.clone()),
        Err(OpenError::Replayed)
    );
    assert_eq!(opener.stats().dropped(OpenError::Replayed), 2);
}

#[test]
fn an_older_session_is_refused_until_the_newer_one_falls_silent() {
    let t0 = Instant::now();
    let mut opener = Opener::new(ring(1, 9), DOMAIN, true);
    let mut old = Sealer::new(&ring(1, 9), DOMAIN, 42, 100, SealMode::Encrypt);
    let recorded = sealed(&mut old, 42, b"yesterday");
    // The sender restarts (a later session) and is heard.
    let mut restarted = Sealer::new(&ring(1, 9), DOMAIN, 42, 200, SealMode::Encrypt);
    assert!(
        opener
            .open(t0, &mut sealed(&mut restarted, 42, b"now"))
            .is_ok()
    );
    assert_eq!(
        opener.open(t0, &mut recorded.clone()),
        Err(OpenError::StaleSession)
    );
    // Silent for the idle time: an older session may start again (a clock stepped back).
    let later = t0 + SESSION_IDLE + Duration::from_secs(1);
    assert!(opener.open(later, &mut recorded.clone()).is_ok());
}

#[test]
fn rotation_accepts_both_epochs_during_the_overlap_and_the_new_one_after() {
    let t0 = Instant::now();
    let mut old_ring = ring(1, 1);
    let mut sender = Sealer::new(&old_ring, DOMAIN, 42, 1, SealMode::Encrypt);
    // Step 1: every host adds the new key.
    old_ring.add(2, DomainKey::from_bytes([2; 32]));
    let mut opener = Opener::new(old_ring.clone(), DOMAIN, true);
    let before = sealed(&mut sender, 42, b"epoch 1");
    // Step 2: the sender switches.
    assert!(old_ring.set_send(2));
    sender.rekey(&old_ring);
    let after = sealed(&mut sender, 42, b"epoch 2");
    assert!(opener.open(t0, &mut after.clone()).is_ok());
    assert!(opener.open(t0, &mut before.clone()).is_ok(), "overlap");
    // Step 3: the old key is retired.
    let straggler = before.clone();
    assert!(old_ring.retire(1));
    opener.set_keyring(old_ring);
    assert_eq!(
        opener.open(t0, &mut straggler.clone()),
        Err(OpenError::UnknownEpoch)
    );
    assert!(
        opener
            .open(t0, &mut sealed(&mut sender, 42, b"still"))
            .is_ok()
    );
}

#[test]
fn plain_and_short_datagrams_are_told_apart() {
    let t0 = Instant::now();
    let mut opener = Opener::new(ring(1, 9), DOMAIN, true);
    assert_eq!(
        opener.open(
            t0,
            &mut plain(42, b"no seal at all, but long enough to hold one")
        ),
        Err(OpenError::NotSealed)
    );
    assert_eq!(
        opener.open(t0, &mut plain(42, b"short")),
        Err(OpenError::NotSealed)
    );
    let mut cut = plain(42, b"x");
    cut[5] |= SEALED;
    assert_eq!(opener.open(t0, &mut cut), Err(OpenError::Truncated));
    assert_eq!(opener.open(t0, &mut [0u8; 3]), Err(OpenError::Truncated));
}

#[test]
fn forged_senders_cost_no_state_and_genuine_ones_are_bounded() {
    let t0 = Instant::now();
    let mut opener = Opener::new(ring(1, 9), DOMAIN, true);
    let mut forger = Sealer::new(&ring(1, 66), DOMAIN, 1, 1, SealMode::Encrypt);
    for sender in 0..500 {
        let _ = opener.open(t0, &mut sealed(&mut forger, sender, b"x"));
    }
    assert_eq!(opener.senders(), 0);
    assert_eq!(opener.stats().dropped(OpenError::BadTag), 500);
    for sender in 0..(MAX_SENDERS as u64 + 10) {
        let mut genuine = Sealer::new(&ring(1, 9), DOMAIN, sender, 1, SealMode::Encrypt);
        let at = t0 + Duration::from_micros(sender);
        assert!(
            opener
                .open(at, &mut sealed(&mut genuine, sender, b"x"))
                .is_ok()
        );
    }
    assert_eq!(opener.senders(), MAX_SENDERS);
    assert_eq!(opener.stats().evicted, 10);
}

proptest! {
    #[test]
    fn any_body_round_trips(body in proptest::collection::vec(any::<u8>(), 0..2000),
                            session in any::<u64>(), clear in any::<bool>()) {
        let mode = if clear { SealMode::IntegrityOnly } else { SealMode::Encrypt };
        let mut sealer = Sealer::new(&ring(3, 5), DOMAIN, 9, session, mode);
        let mut opener = Opener::new(ring(3, 5), DOMAIN, false);
        let mut datagram = sealed(&mut sealer, 9, &body);
        prop_assert_eq!(opener.open(Instant::now(), &mut datagram), Ok(&plain(9, &body)[..]));
    }

    #[test]
    fn arbitrary_bytes_never_open_and_never_panic(mut bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        let mut opener = Opener::new(ring(1, 9), DOMAIN, false);
        prop_assert!(opener.open(Instant::now(), &mut bytes).is_err());
        prop_assert_eq!(opener.senders(), 0);
    }
}

#[test]
fn only_ndds_datagrams_with_the_flag_and_a_known_kind_count_as_sealed() {
    let mut sealer = Sealer::new(&ring(1, 9), DOMAIN, 42, 1, SealMode::Encrypt);
    let genuine = sealed(&mut sealer, 42, b"x");
    assert!(is_sealed(&genuine));
    // Junk with the flag bit set where the kind would be is junk, not a sealed datagram.
    let mut junk = genuine.clone();
    junk[0] = b'X';
    assert!(!is_sealed(&junk));
    let mut unknown_kind = plain(42, b"x");
    unknown_kind[5] = 0x80 | 0x3f;
    assert!(!is_sealed(&unknown_kind));
    let mut other_version = genuine.clone();
    other_version[4] = 99;
    assert!(!is_sealed(&other_version));
    assert!(!is_sealed(&genuine[..15]));
}

#[test]
fn every_cipher_seals_and_opens_and_never_opens_another_ciphers_datagrams() {
    let t0 = Instant::now();
    for cipher in Cipher::ALL {
        let keys = ring(1, 9).with_cipher(cipher);
        let mut sealer = Sealer::new(&keys, DOMAIN, 42, 1, SealMode::Encrypt);
        let mut opener = Opener::new(keys, DOMAIN, true);
        let datagram = sealed(&mut sealer, 42, b"same key, any cipher");
        assert_eq!(
            opener.open(t0, &mut datagram.clone()),
            Ok(&plain(42, b"same key, any cipher")[..]),
            "{cipher:?}"
        );
        // A host configured for another cipher, with the same key, cannot open it.
        for other in Cipher::ALL.into_iter().filter(|c| *c != cipher) {
            let mut wrong = Opener::new(ring(1, 9).with_cipher(other), DOMAIN, true);
            assert_eq!(
                wrong.open(t0, &mut datagram.clone()),
                Err(OpenError::BadTag),
                "{cipher:?} opened as {other:?}"
            );
        }
    }
}

proptest! {
    #[test]
    fn any_body_round_trips_with_every_cipher(body in proptest::collection::vec(any::<u8>(), 0..2000),
                                              clear in any::<bool>(), which in 0..Cipher::ALL.len()) {
        let mode = if clear { SealMode::IntegrityOnly } else { SealMode::Encrypt };
        let cipher = Cipher::ALL[which];
        let keys = ring(3, 5).with_cipher(cipher);
        let mut sealer = Sealer::new(&keys, DOMAIN, 9, 77, mode);
        let mut opener = Opener::new(keys, DOMAIN, false);
        let mut datagram = sealed(&mut sealer, 9, &body);
        prop_assert_eq!(opener.open(Instant::now(), &mut datagram), Ok(&plain(9, &body)[..]));
    }
}

/// AEGIS-128L as a session key seals is the draft's (draft-irtf-cfrg-aegis-aead): its test
/// vector 5, whose nonce ends in 8 zero bytes as ndds's do, so its first 8 are the counter.
#[test]
fn aegis_128l_seals_the_drafts_test_vector() {
    let mut bytes = [0u8; 32];
    bytes[..16].copy_from_slice(&unhex::<16>("10010000000000000000000000000000").unwrap());
    let key = SessionKey::new(Cipher::Aegis128L, &bytes, Backend::PREFERRED);
    let counter = u64::from_le_bytes(unhex::<8>("1000020000000000").unwrap());
    let ad = unhex::<42>(
        "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f20212223242526272829",
    )
    .unwrap();
    let msg = unhex::<40>(
        "101112131415161718191a1b1c1d1e1f202122232425262728292a2b2c2d2e2f3031323334353637",
    )
    .unwrap();
    let ct = unhex::<40>(
        "b31052ad1cca4e291abcf2df3502e6bdb1bfd6db36798be3607b1f94d34478aa7ede7f7a990fec10",
    )
    .unwrap();
    let mut body = msg;
    let tag = key.seal(counter, &ad, &mut body).unwrap();
    assert_eq!(body, ct);
    assert_eq!(
        tag[..],
        unhex::<16>("7542a745733014f9474417b337399507").unwrap()
    );
    assert!(key.open(counter, &ad, &mut body, &tag));
    assert_eq!(body, msg);
    // A forged variant of it: one changed ciphertext bit fails.
    let mut forged = ct;
    forged[39] ^= 1;
    assert!(!key.open(counter, &ad, &mut forged, &tag));
}

/// ring's ciphers and RustCrypto's seal the same bytes: a datagram sealed by a host built
/// with one opens on a host built with the other.
#[cfg(feature = "ring")]
#[test]
fn ring_and_rustcrypto_seal_the_same_bytes_and_open_each_other() {
    for cipher in Cipher::ALL {
        for len in [0usize, 1, 15, 16, 17, 64, 1000, 8192] {
            let bytes = [0x5a; 32];
            let rust = SessionKey::new(cipher, &bytes, Backend::RustCrypto);
            let ring = SessionKey::new(cipher, &bytes, Backend::Ring);
            // (AEGIS-128L has one implementation, the same key either way.)
            assert!(
                matches!(ring, SessionKey::Ring(_))
                    || matches!(ring, SessionKey::Aegis(_)) && cipher == Cipher::Aegis128L
            );
            let aad = *b"header and seal head";
            let body: Vec<u8> = (0..len).map(|i| (i * 7 % 251) as u8).collect();
            let counter = 0x0102_0304_0506_0708 + len as u64;
            let mut by_rust = body.clone();
            let tag_rust = rust.seal(counter, &aad, &mut by_rust).unwrap();
            let mut by_ring = body.clone();
            let tag_ring = ring.seal(counter, &aad, &mut by_ring).unwrap();
            assert_eq!(
                (&by_rust, tag_rust),
                (&by_ring, tag_ring),
                "{cipher:?} {len}"
            );
            if len > 0 {
                assert_ne!(by_rust, body, "{cipher:?} {len}: encrypted");
            }
            assert!(ring.open(counter, &aad, &mut by_rust, &tag_rust));
            assert!(rust.open(counter, &aad, &mut by_ring, &tag_ring));
            assert_eq!((&by_rust, &by_ring), (&body, &body), "{cipher:?} {len}");
            // A flipped bit, another counter or other associated data never opens.
            let mut forged = tag_ring;
            forged[3] ^= 1;
            // (ring wipes what it refused; the opener drops it either way.)
            let mut sealed = body.clone();
            let tag = ring.seal(counter, &aad, &mut sealed).unwrap();
            assert!(!ring.open(counter, &aad, &mut sealed.clone(), &forged));
            assert!(!ring.open(counter + 1, &aad, &mut sealed.clone(), &tag));
            assert!(!ring.open(counter, b"other", &mut sealed.clone(), &tag));
            assert!(ring.open(counter, &aad, &mut sealed, &tag));
        }
    }
}

#[test]
fn sealing_a_datagram_in_pieces_gives_the_bytes_of_sealing_it_whole() {
    for (cipher, mode) in Cipher::ALL.into_iter().flat_map(|cipher| {
        [
            (cipher, SealMode::Encrypt),
            (cipher, SealMode::IntegrityOnly),
        ]
    }) {
        let keys = ring(1, 9).with_cipher(cipher);
        let whole_body: Vec<u8> = (0..300u32).map(|i| (i * 13) as u8).collect();
        let datagram = plain(42, &whole_body);
        let mut whole = Sealer::new(&keys, DOMAIN, 42, 1000, mode);
        let mut pieces = Sealer::new(&keys, DOMAIN, 42, 1000, mode);
        let mut opener = Opener::new(keys.clone(), DOMAIN, false);
        let t0 = Instant::now();
        // Cuts inside the header, at its end, in the body, and at both ends; into a short
        // buffer and into a recycled one longer than the datagram, both holding old bytes.
        let cuts = [(0, 0), (3, 3), (16, 16), (10, 40), (100, 250), (316, 316)];
        for ((first, second), old) in cuts.into_iter().flat_map(|cut| [(cut, 7), (cut, 2000)]) {
            let expected = sealed(&mut whole, 42, &whole_body);
            let mut out = vec![0xee; old];
            let parts = [
                &datagram[..first],
                &datagram[first..second],
                &datagram[second..],
            ];
            pieces.seal_into(&mut out, &parts).unwrap();
            assert_eq!(
                out, expected,
                "{cipher:?} {mode:?} cut at {first} and {second} into {old} bytes"
            );
            let opened = opener.open(t0, &mut out).unwrap().to_vec();
            assert_eq!(opened, datagram);
        }
        // A header and no body.
        let bare = plain(42, b"");
        let expected = sealed(&mut whole, 42, b"");
        let mut out = vec![0xee; 100];
        pieces
            .seal_into(&mut out, &[&bare[..5], &bare[5..]])
            .unwrap();
        assert_eq!(out, expected, "{cipher:?} {mode:?} a bare header");
        // Less than a header: refused before anything is written or counted.
        let counted = pieces.sealed();
        let mut out = vec![0xee; 7];
        assert_eq!(
            pieces.seal_into(&mut out, &[&datagram[..10], &datagram[10..15]]),
            Err(SealError::NotADatagram)
        );
        assert_eq!((pieces.sealed(), &out[..]), (counted, &[0xee; 7][..]));
    }
}

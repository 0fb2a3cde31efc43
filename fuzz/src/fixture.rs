//! Fixed identities and keys, so that every input replays the same way and the seed
//! generator produces datagrams the targets accept.

use std::net::{Ipv4Addr, SocketAddrV4};

use ndds_core::seal::{Cipher, DomainKey, Keyring};
use ndds_core::wire::Locator;

/// The domain of every target.
pub const DOMAIN: u16 = 7;

/// The keyring of every sealed target: epochs 1 and 2, sending with 2, in `cipher`. The keys
/// are public test values; a fuzzer that holds them can produce datagrams that open, and so
/// reach what lies past the tag.
pub fn keyring(cipher: Cipher) -> Keyring {
    let mut keyring = Keyring::new(1, DomainKey::from_bytes([0x11; 32])).with_cipher(cipher);
    keyring.add(2, DomainKey::from_bytes([0x22; 32]));
    keyring.set_send(2);
    keyring
}

/// The cipher a seal target's flag byte selects: bit 4 AEGIS-128L; else bit 0 AES-GCM, with
/// a 128-bit key if bit 3 is set too (256-bit otherwise); else ChaCha20-Poly1305.
pub fn cipher(flags: u8) -> Cipher {
    match (flags & 16 != 0, flags & 1 != 0, flags & 8 != 0) {
        (true, _, _) => Cipher::Aegis128L,
        (false, false, _) => Cipher::ChaCha20Poly1305,
        (false, true, false) => Cipher::Aes256Gcm,
        (false, true, true) => Cipher::Aes128Gcm,
    }
}

/// The unicast locator of simulated host `index` (`10.0.0.(index+1):7400`).
pub fn locator(index: u8) -> Locator {
    Locator {
        addr: [10, 0, 0, index.saturating_add(1)],
        port: 7400,
    }
}

/// The data socket of simulated host `index` (`10.0.1.(index+1):7410`).
pub fn data_addr(index: u8) -> SocketAddrV4 {
    SocketAddrV4::new(Ipv4Addr::new(10, 0, 1, index.saturating_add(1)), 7410)
}

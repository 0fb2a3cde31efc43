//! Sealed-datagram routing and opening on arbitrary bytes: `seal::route` (plain, open,
//! sealed without a key, junk) and `Opener::open` with the fixture keyring (epochs 1 and 2).
//! Input: a flag byte (bit 0: AES-GCM, bit 3 with it: AES-128-GCM, bit 4: AEGIS-128L, bit 1:
//! encryption required, bit 2: the receiver holds no key), then datagrams as u16le-length
//! chunks, opened in turn by one opener. What opens must start with a plain header; random
//! bytes rarely pass the tag, which is why `seal_roundtrip` seals inputs first.

use std::time::{Duration, Instant};

use ndds_core::seal::{Opener, Route, is_sealed, route};
use ndds_core::wire::Header;
use ndds_fuzz::Input;
use ndds_fuzz::fixture::{DOMAIN, cipher, keyring};

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let mut input = Input::new(data);
        let flags = input.u8();
        let keyed = flags & 4 == 0;
        let mut opener = Opener::new(
            keyring(cipher(flags)),
            DOMAIN,
            flags & 2 != 0,
        );
        let mut now = Instant::now();
        while !input.is_empty() {
            let mut datagram = input.chunk().to_vec();
            let routed = route(&datagram, keyed);
            match routed {
                Route::Plain => assert!(!is_sealed(&datagram) && !keyed),
                Route::SealedWithoutKey => assert!(is_sealed(&datagram) && !keyed),
                Route::Junk(reason) => assert_eq!(Header::parse(&datagram).err(), Some(reason)),
                Route::Open => {
                    assert!(keyed);
                    if let Ok(plain) = opener.open(now, &mut datagram) {
                        assert!(
                            Header::parse(plain).is_ok(),
                            "an opened datagram has a plain header"
                        );
                    }
                }
            }
            now += Duration::from_millis(1);
        }
        let stats = opener.stats();
        let _ = stats.opened + stats.dropped.iter().sum::<u64>();
    });
}

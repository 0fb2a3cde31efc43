//! Key files (`seal::Keyring::parse`), read by the daemon and `ndds key` from a path an
//! operator gives. A key file that parses is written again (`to_file_text`) and must parse
//! to the same keyring.

use ndds_core::seal::Keyring;

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let Ok(text) = std::str::from_utf8(data) else {
            return;
        };
        let Ok(keyring) = Keyring::parse(text) else {
            return;
        };
        let again = Keyring::parse(&keyring.to_file_text()).expect("a written key file parses");
        assert_eq!(again, keyring);
    });
}

//! The fixed 16-byte datagram header (`wire::Header::parse`), the first thing every
//! receiver reads: a header that parses emits the same 16 bytes, and the body is the rest.

use ndds_core::wire::{HEADER_LEN, Header};

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        if let Ok((header, body)) = Header::parse(data) {
            let mut emitted = Vec::new();
            header.emit(&mut emitted);
            assert_eq!(emitted, data[..HEADER_LEN], "emit(parse(x)) differs from x");
            assert_eq!(body, &data[HEADER_LEN..]);
        }
    });
}

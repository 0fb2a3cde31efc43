//! Dynamic decoding of samples (`dynamic::decode_json`, what `ndds echo --json` does with a
//! layout received from discovery) and its inverse (`encode_json`). Input: a postcard
//! `TypeLayout`, then the payload. Neither may panic, validated layout or not; for a
//! validated layout, a payload that decodes to JSON encodes back, and that encoding decodes
//! to the same JSON.

use ndds_core::dynamic::{decode_json, encode_json};
use ndds_core::types::TypeLayout;

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let Ok((layout, payload)) = postcard::take_from_bytes::<TypeLayout>(data) else {
            return;
        };
        let valid = layout.validate().is_ok();
        let Ok(json) = decode_json(&layout, payload) else {
            return;
        };
        let encoded = encode_json(&layout, &json);
        if !valid {
            return;
        }
        let encoded = encoded.unwrap_or_else(|err| panic!("decoded JSON does not encode: {err}"));
        let again = decode_json(&layout, &encoded)
            .unwrap_or_else(|err| panic!("encode_json's output does not decode: {err}"));
        assert_eq!(
            again, json,
            "decode(encode(decode(x))) differs from decode(x)"
        );
    });
}

//! Type descriptions as they travel in discovery (`TypeDescription`, `TypeLayout` with its
//! bounded vectors) and what a receiver computes from them: `validate`, the canonical text,
//! the fingerprint and the one-line shape. A description that decodes encodes and decodes
//! again to itself; a validated one has a fingerprint that does not depend on the encoding.

use ndds_core::types::TypeDescription;
use ndds_fuzz::roundtrip::postcard_round_trip;

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let Ok((desc, _rest)) = postcard::take_from_bytes::<TypeDescription>(data) else {
            return;
        };
        let bytes = postcard_round_trip(&desc);
        let _ = desc.short_name();
        if desc.validate().is_err() {
            return;
        }
        let text = desc.canonical_text();
        let fingerprint = desc.fingerprint();
        let _ = desc.shape();
        let again: TypeDescription = postcard::from_bytes(&bytes).expect("round trip checked");
        assert_eq!(again.canonical_text(), text);
        assert_eq!(again.fingerprint(), fingerprint);
    });
}

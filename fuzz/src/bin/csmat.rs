//! CSMat samples as they arrive on a topic (ndds-runtime): `postcard::from_bytes::<CsMat>`
//! (the validating `Deserialize`) and `CsMat::decode_into` (in place, what a binding does
//! with every sample). Both must agree: a sample one accepts the other accepts, to the
//! same matrix, and a decoded matrix encodes to bytes that decode to the same encoding.
//! Values are compared through their encoding, so that NaN equals itself.

use ndds_runtime::CsMat;

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let decoded = postcard::from_bytes::<CsMat>(data);
        // Decoding into a matrix of another shape, and then again into the result (the
        // path that allocates nothing).
        let mut target = CsMat::zeros("target", 2, 3)
            .with_row_fields([("a", "m"), ("b", "s")])
            .expect("two rows, two fields");
        let in_place = target.decode_into(data);
        match (&decoded, &in_place) {
            (Ok(mat), Ok(())) => {
                let bytes = postcard::to_allocvec(mat).expect("a decoded matrix encodes");
                let target_bytes = postcard::to_allocvec(&target).expect("encodes");
                assert_eq!(target_bytes, bytes, "decode_into and Deserialize disagree");
                let again: CsMat = postcard::from_bytes(&bytes).expect("re-encoded decodes");
                assert_eq!(postcard::to_allocvec(&again).expect("encodes"), bytes);
                target.decode_into(&bytes).expect("decodes in place again");
                assert_eq!(postcard::to_allocvec(&target).expect("encodes"), bytes);
            }
            (Err(_), Err(_)) => {}
            (Ok(_), Err(err)) => panic!("decode_into refused what Deserialize took: {err}"),
            (Err(err), Ok(())) => panic!("Deserialize refused what decode_into took: {err}"),
        }
    });
}

//! Assertions shared by the decoder targets: a value that decoded must encode, and decode
//! again to itself. (Bytes are not compared: postcard accepts varints with redundant
//! continuation bytes, so the re-encoding may be shorter than the input.)

use std::fmt::Debug;

use serde::Serialize;
use serde::de::DeserializeOwned;

/// Encodes `value` with postcard and asserts that it decodes to an equal value; returns the
/// encoding.
pub fn postcard_round_trip<T>(value: &T) -> Vec<u8>
where
    T: Serialize + DeserializeOwned + PartialEq + Debug,
{
    let bytes = postcard::to_allocvec(value).expect("a decoded value encodes");
    let again: T = postcard::from_bytes(&bytes).expect("an encoded value decodes");
    assert_eq!(&again, value, "decode(encode(value)) differs from value");
    bytes
}

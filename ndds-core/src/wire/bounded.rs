//! Sequence decoding whose memory is bounded by the input actually consumed.
//!
//! serde's `Vec<T>` implementation pre-allocates from the length prefix (capped at 1 MiB), so a
//! 20-byte datagram claiming four billion elements would allocate a megabyte before failing.
//! Every `Vec` field of a wire message therefore deserializes through [`vec()`], which grows the
//! vector only as elements are actually decoded. postcard encodes every element we use in at
//! least one byte, so the allocation stays proportional to the datagram's length.

use std::fmt;
use std::marker::PhantomData;

use serde::de::{Deserialize, Deserializer, SeqAccess, Visitor};

/// Initial capacity granted regardless of the claimed length.
const INITIAL_CAPACITY: usize = 4;

/// Deserializes a sequence without trusting its length prefix for allocation.
///
/// Use as `#[serde(deserialize_with = "crate::wire::bounded::vec")]`.
pub fn vec<'de, D, T>(deserializer: D) -> Result<Vec<T>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    deserializer.deserialize_seq(BoundedVecVisitor(PhantomData))
}

/// Like [`vec()`], for `Cow<'_, [T]>` fields (always decoded as owned).
pub fn cow_vec<'de, 'a, D, T>(deserializer: D) -> Result<std::borrow::Cow<'a, [T]>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de> + Clone,
{
    vec(deserializer).map(std::borrow::Cow::Owned)
}

struct BoundedVecVisitor<T>(PhantomData<T>);

impl<'de, T: Deserialize<'de>> Visitor<'de> for BoundedVecVisitor<T> {
    type Value = Vec<T>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<T>, A::Error> {
        let claimed = seq.size_hint().unwrap_or(0);
        let mut out = Vec::with_capacity(claimed.min(INITIAL_CAPACITY));
        while let Some(item) = seq.next_element()? {
            out.push(item);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use serde::Deserialize;

    #[derive(Deserialize, Debug)]
    struct Holder {
        #[serde(deserialize_with = "super::vec")]
        items: Vec<u32>,
    }

    #[test]
    fn huge_length_claim_fails_without_preallocating() {
        // Length prefix 0xFFFF_FFFF (varint) followed by two elements only.
        let bytes = [0xFF, 0xFF, 0xFF, 0xFF, 0x0F, 1, 2];
        let result: Result<Holder, _> = postcard::from_bytes(&bytes);
        assert!(result.is_err());
    }

    #[test]
    fn honest_sequences_decode() {
        let bytes = [3, 1, 2, 3];
        let holder: Holder = postcard::from_bytes(&bytes).unwrap();
        assert_eq!(holder.items, vec![1, 2, 3]);
    }
}

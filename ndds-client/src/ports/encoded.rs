//! [`Encoded`]: a port message already encoded, for bindings whose types are described at run
//! time (`ndds-python`), so that they use the ports' whole machinery without a Rust type.

use serde::de::{Deserializer, SeqAccess, Visitor};
use serde::ser::{SerializeTuple, Serializer};
use serde::{Deserialize, Serialize};

/// A message of a port already encoded with postcard (the ports' codec), by a caller that
/// knows its type only at run time: [`PortUser::declare_described`](super::PortUser::declare_described)
/// and [`PortOwner::declare_described`](super::PortOwner::declare_described) announce and
/// check the types' fingerprints; the bytes go out as they are and come back as they arrived.
///
/// Only the `declare_described` constructors take it: the others trace their message types,
/// which `Encoded` has none of, and refuse it ([`PortError::Undescribed`](super::PortError::Undescribed)).
/// It is not a topic sample type either (a producer or consumer of `Encoded` would be traced
/// the same way): topics of types described at run time use raw producers and consumers.
///
/// It serializes as its bytes with nothing around them (postcard writes a tuple of `u8`s as
/// the bytes themselves) and deserializes as every byte that is left, so a request's payload
/// is exactly the encoded message. It is meant for postcard only, which is what the ports use:
/// its serde implementation is not that of a byte string in self-describing formats.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Encoded(pub Vec<u8>);

impl Serialize for Encoded {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut tuple = serializer.serialize_tuple(self.0.len())?;
        for byte in &self.0 {
            tuple.serialize_element(byte)?;
        }
        tuple.end()
    }
}

impl<'de> Deserialize<'de> for Encoded {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Rest;
        impl<'de> Visitor<'de> for Rest {
            type Value = Encoded;

            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("the rest of the message's bytes")
            }

            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Encoded, A::Error> {
                let mut bytes = Vec::new();
                // postcard's tuple access reads one byte per element and fails at the end of
                // the input: the end of the message (nothing was consumed by the failed read).
                while let Ok(Some(byte)) = seq.next_element::<u8>() {
                    bytes.push(byte);
                }
                Ok(Encoded(bytes))
            }
        }
        // The length is unknown: every byte up to the end of the payload.
        deserializer.deserialize_tuple(usize::MAX, Rest)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize, Deserialize, Debug, PartialEq)]
    struct Pose {
        x: f64,
        label: String,
        ids: Vec<u32>,
    }

    #[test]
    fn an_encoded_message_is_its_bytes_both_ways() {
        let pose = Pose {
            x: 1.5,
            label: "arm".to_owned(),
            ids: vec![1, 300],
        };
        let bytes = postcard::to_stdvec(&pose).unwrap();
        // Written: exactly the bytes, as the typed side writes the value.
        let written = postcard::to_stdvec(&Encoded(bytes.clone())).unwrap();
        assert_eq!(written, bytes);
        // Read: every byte, which the typed side reads back as the value.
        let read: Encoded = postcard::from_bytes(&bytes).unwrap();
        assert_eq!(read.0, bytes);
        assert_eq!(postcard::from_bytes::<Pose>(&read.0).unwrap(), pose);
        // An empty message (a unit reply) is empty both ways.
        assert_eq!(
            postcard::from_bytes::<Encoded>(&[]).unwrap(),
            Encoded::default()
        );
        assert!(postcard::to_stdvec(&Encoded::default()).unwrap().is_empty());
    }
}

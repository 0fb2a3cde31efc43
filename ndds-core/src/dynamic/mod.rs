//! Decoding a sample to JSON, and encoding JSON to a sample, from its [`TypeLayout`] alone.
//!
//! Command-line tools receive a topic's layout over the network but do not have its Rust type
//! compiled in. [`decode_json`] turns a sample payload into a [`serde_json::Value`] (what
//! `ndds echo --json` prints) and [`encode_json`] does the inverse (what `ndds pub` sends).
//!
//! Both are **postcard-specific**: postcard is not self-describing and ignores struct, field
//! and variant names, so the layout drives postcard's typed `deserialize_*` / `serialize_*`
//! calls with blank names, and structs are read as the tuples postcard writes them as.
//!
//! ## JSON mapping
//!
//! | layout                     | JSON                                                        |
//! |----------------------------|-------------------------------------------------------------|
//! | `bool`                     | `true` / `false`                                            |
//! | `i8` … `i64`, `u8` … `u64` | number                                                      |
//! | `i128`, `u128`             | number if it fits in `i64` or `u64`, else a decimal string  |
//! | `f32`, `f64`               | number; NaN and infinities as `"NaN"`, `"inf"`, `"-inf"`    |
//! | `char`                     | one-character string                                        |
//! | `str`                      | string                                                      |
//! | `bytes`                    | array of numbers 0–255                                      |
//! | `unit`, unit struct        | `null`                                                      |
//! | `option<T>`                | `null` or the value of `T`                                  |
//! | `seq<T>`                   | array                                                       |
//! | `map<str, V>`              | object                                                      |
//! | `map<K, V>`, other `K`     | array of `[key, value]` pairs                               |
//! | tuple, tuple struct, array | array                                                       |
//! | newtype struct             | the inner value                                             |
//! | struct                     | object, one member per field                                |
//! | enum, unit variant         | `"Variant"`                                                 |
//! | enum, other variants       | `{"Variant": value}` (value as newtype, tuple or struct)    |
//!
//! An `f32` is decoded to the shortest decimal that reads back as the same `f32` (`0.1`, not
//! `0.10000000149011612`), and [`encode_json`] reads the number's decimal text directly as an
//! `f32`, so the round trip is exact.
//!
//! [`encode_json`] accepts exactly this JSON and, for convenience, also: any integer as a
//! decimal string; a map of any key type as an object whose member names are the keys written
//! as strings (`{"7": ..}` for a `u32` key); a missing struct field whose type accepts `null`
//! (an option, unit or unit struct) as `null`; `{"Variant": null}` for a unit variant.
//! Unknown struct fields are rejected.
//!
//! Where this differs from `serde_json::to_value` of the same Rust value: `f32` digits (see
//! above; `to_value` widens exactly), non-finite floats (`to_value` gives `null`), 128-bit
//! integers beyond 64 bits (`to_value` fails), and maps with non-string keys (`to_value` turns
//! integer keys into strings). `serde_json`'s `Map` keeps members sorted by name unless its
//! `preserve_order` feature is on, so struct fields print in declaration order only then.
//!
//! Two JSON values are ambiguous, as with serde_json: `Some(x)` where `x` is itself `null`
//! (`Option<Option<T>>`, `Option<()>`) encodes back as `None`, and every NaN encodes back as
//! the canonical quiet NaN.
//!
//! ## Limits
//!
//! Neither function panics on any input. Values nest at most [`MAX_DEPTH`] deep (counting
//! every level, including containers recursing into themselves), or the call fails with
//! [`DynamicError::TooDeep`]. Decoding produces at most [`value_limit`]`(payload.len())`
//! values in all, or fails with [`DynamicError::TooManyElements`]: unit values occupy no bytes,
//! so without this bound a `seq<unit>` claiming four billion elements would loop four billion
//! times. Every value counts, not only sequence elements, because a hostile layout can also
//! multiply zero-sized values through nested tuples; the allowance of [`VALUES_PER_BYTE`] per
//! byte leaves room for the several values (struct, newtype, field) that share one byte.
//! Nothing is pre-allocated from a length prefix.
//!
//! ## Errors
//!
//! Errors name where they happened as a JSON pointer into the value (`/pose/x`, `/items/3`;
//! the root is written `/`). In a map written as an object, a value is addressed by its key
//! (`/tags/left`), and so is the key when encoding; when decoding, a key not yet read is
//! addressed by its position (`/tags/2`). In a map written as pairs, the key and value of the
//! third entry are `/ids/2/0` and `/ids/2/1`.

mod decode;
mod encode;
mod path;
mod schema;
#[cfg(test)]
mod tests;

use serde_json::Value;

use crate::types::TypeLayout;

pub use schema::json_schema;

/// Deepest nesting of values accepted while decoding or encoding.
pub const MAX_DEPTH: usize = 64;
/// Values a decoded payload may produce per byte, on top of [`BASE_VALUES`].
pub const VALUES_PER_BYTE: usize = 8;
/// Values any payload may produce, whatever its length.
pub const BASE_VALUES: usize = 1024;

/// Why a payload or a JSON value could not be converted.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DynamicError {
    /// The payload does not match the layout (truncated, bad UTF-8, unknown variant, ...).
    #[error("at {path}: {reason}")]
    Decode {
        /// Where, as a JSON pointer.
        path: String,
        /// What went wrong.
        reason: String,
    },
    /// The JSON value does not match the layout.
    #[error("at {path}: expected {expected}, found {found}")]
    Encode {
        /// Where, as a JSON pointer.
        path: String,
        /// What the layout wants there.
        expected: String,
        /// What the JSON holds there.
        found: String,
    },
    /// Values nest deeper than [`MAX_DEPTH`].
    #[error("at {path}: values nest deeper than {limit} levels")]
    TooDeep {
        /// Where the limit was reached.
        path: String,
        /// The limit.
        limit: usize,
    },
    /// The payload decodes to more than [`value_limit`] values.
    #[error("at {path}: the payload decodes to more than {limit} values")]
    TooManyElements {
        /// Where the limit was reached.
        path: String,
        /// The limit for this payload's length.
        limit: usize,
    },
    /// Bytes were left over after the value.
    #[error("{0} trailing bytes after the value")]
    Trailing(usize),
    /// The layout refers to a format or container it does not have (it was not validated).
    #[error("at {path}: the layout has no {what} {index}")]
    BadLayout {
        /// Where.
        path: String,
        /// `"format"` or `"container"`.
        what: &'static str,
        /// The missing index.
        index: u32,
    },
}

/// The most values a payload of `payload_len` bytes may decode to.
pub fn value_limit(payload_len: usize) -> usize {
    payload_len
        .saturating_mul(VALUES_PER_BYTE)
        .saturating_add(BASE_VALUES)
}

/// Decodes a postcard `payload` of the type `layout` describes into JSON (see the module docs
/// for the mapping). Bytes left after the value are an error.
///
/// ```
/// use ndds_core::dynamic::decode_json;
/// use ndds_core::types::TypeDescription;
///
/// #[derive(serde::Serialize, serde::Deserialize)]
/// struct Pose { x: f64, y: f64 }
///
/// let layout = TypeDescription::try_of::<Pose>().unwrap().layout.unwrap();
/// let payload = postcard::to_allocvec(&Pose { x: 1.5, y: -2.0 }).unwrap();
/// let json = decode_json(&layout, &payload).unwrap();
/// assert_eq!(json, serde_json::json!({"x": 1.5, "y": -2.0}));
/// ```
pub fn decode_json(layout: &TypeLayout, payload: &[u8]) -> Result<Value, DynamicError> {
    decode::decode(layout, payload)
}

/// Encodes JSON as a postcard payload of the type `layout` describes; the inverse of
/// [`decode_json`].
///
/// ```
/// use ndds_core::dynamic::encode_json;
/// use ndds_core::types::TypeDescription;
///
/// #[derive(serde::Serialize, serde::Deserialize)]
/// struct Pose { x: f64, y: f64 }
///
/// let layout = TypeDescription::try_of::<Pose>().unwrap().layout.unwrap();
/// let payload = encode_json(&layout, &serde_json::json!({"x": 1.5, "y": -2.0})).unwrap();
/// assert_eq!(payload, postcard::to_allocvec(&Pose { x: 1.5, y: -2.0 }).unwrap());
///
/// let err = encode_json(&layout, &serde_json::json!({"x": "far", "y": 0.0})).unwrap_err();
/// assert_eq!(err.to_string(), r#"at /x: expected f64, found string "far""#);
/// ```
pub fn encode_json(layout: &TypeLayout, value: &Value) -> Result<Vec<u8>, DynamicError> {
    encode::encode(layout, value)
}

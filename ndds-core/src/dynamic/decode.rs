//! Payload → JSON: a [`DeserializeSeed`] driven by the layout, calling postcard's typed
//! `deserialize_*` methods.
//!
//! Every value is decoded by a [`Seed`], which first charges the depth and value budgets. An
//! error raised by this module is recorded in full in [`Cx`] (postcard's error type would keep
//! only its kind); an error raised by postcard is recorded by the innermost seed it passes
//! through, which knows the path.

use std::cell::{Cell, RefCell};
use std::fmt;

use serde::de::{self, DeserializeSeed, Deserializer, EnumAccess, MapAccess, SeqAccess};
use serde::de::{VariantAccess, Visitor};
use serde_json::{Map, Number, Value};

use super::path::{Path, Step};
use super::{DynamicError, MAX_DEPTH, value_limit};
use crate::types::{Container, ContainerShape, Field, Format, TypeLayout, Variant, VariantShape};

/// Decodes `payload`; see [`super::decode_json`].
pub(super) fn decode(layout: &TypeLayout, payload: &[u8]) -> Result<Value, DynamicError> {
    let cx = Cx {
        layout,
        spent: Cell::new(0),
        limit: value_limit(payload.len()),
        failure: RefCell::new(None),
    };
    let mut deserializer = postcard::Deserializer::from_bytes(payload);
    let at = At {
        cx: &cx,
        path: Path::ROOT,
    };
    let value = at
        .seed(layout.root, Step::Inner)
        .deserialize(&mut deserializer)
        .map_err(|err| cx.take(err))?;
    match deserializer.finalize() {
        Ok([]) => Ok(value),
        Ok(rest) => Err(DynamicError::Trailing(rest.len())),
        Err(err) => Err(cx.take(err)),
    }
}

/// State shared by every seed of one decode.
struct Cx<'a> {
    layout: &'a TypeLayout,
    /// Values decoded so far.
    spent: Cell<usize>,
    limit: usize,
    /// The first error, with its path.
    failure: RefCell<Option<DynamicError>>,
}

impl Cx<'_> {
    /// Records `error` unless one is recorded already, and returns it for postcard to carry.
    fn fail<E: de::Error>(&self, error: DynamicError) -> E {
        let message = error.to_string();
        self.failure.borrow_mut().get_or_insert(error);
        E::custom(message)
    }

    /// The recorded error, or `err` (which then happened outside any value).
    fn take(&self, err: impl fmt::Display) -> DynamicError {
        self.failure.take().unwrap_or_else(|| DynamicError::Decode {
            path: "/".to_owned(),
            reason: err.to_string(),
        })
    }
}

/// A place in the value being decoded.
#[derive(Clone, Copy)]
struct At<'a> {
    cx: &'a Cx<'a>,
    path: Path<'a>,
}

impl<'a> At<'a> {
    /// The seed for the value one `step` inside this place.
    fn seed<'b>(&'b self, format: u32, step: Step<'b>) -> Seed<'b> {
        Seed {
            at: self.enter(step),
            format,
        }
    }

    /// The place one `step` inside this one.
    fn enter<'b>(&'b self, step: Step<'b>) -> At<'b> {
        At {
            cx: self.cx,
            path: self.path.child(step),
        }
    }

    fn fail<E: de::Error>(&self, reason: String) -> E {
        let path = self.path.render();
        self.cx.fail(DynamicError::Decode { path, reason })
    }

    /// Records an error postcard raised here, unless a deeper one is recorded already.
    fn note<E: de::Error>(&self, err: E) -> E {
        let mut failure = self.cx.failure.borrow_mut();
        failure.get_or_insert_with(|| DynamicError::Decode {
            path: self.path.render(),
            reason: err.to_string(),
        });
        drop(failure);
        err
    }

    fn missing<E: de::Error>(&self, what: &'static str, index: u32) -> E {
        let path = self.path.render();
        self.cx.fail(DynamicError::BadLayout { path, what, index })
    }

    /// Charges one value against the depth and value budgets.
    fn charge<E: de::Error>(&self) -> Result<(), E> {
        let spent = self.cx.spent.get() + 1;
        self.cx.spent.set(spent);
        if self.path.depth() > MAX_DEPTH {
            let (path, limit) = (self.path.render(), MAX_DEPTH);
            return Err(self.cx.fail(DynamicError::TooDeep { path, limit }));
        }
        if spent > self.cx.limit {
            let (path, limit) = (self.path.render(), self.cx.limit);
            return Err(self.cx.fail(DynamicError::TooManyElements { path, limit }));
        }
        Ok(())
    }

    /// An element a sequence access must yield: postcard yields exactly as many as asked.
    fn element<E: de::Error>(&self, element: Option<Value>) -> Result<Value, E> {
        element.ok_or_else(|| self.fail("the value ended early".to_owned()))
    }
}

/// Decodes one value of `format` at `at`.
struct Seed<'a> {
    at: At<'a>,
    format: u32,
}

impl<'de> DeserializeSeed<'de> for Seed<'_> {
    type Value = Value;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Value, D::Error> {
        self.at.charge()?;
        let at = self.at;
        self.dispatch(deserializer).map_err(|err| at.note(err))
    }
}

impl<'a> Seed<'a> {
    fn dispatch<'de, D: Deserializer<'de>>(self, de: D) -> Result<Value, D::Error> {
        let Some(format) = self.at.cx.layout.format(self.format) else {
            return Err(self.at.missing("format", self.format));
        };
        let at = self.at;
        match format {
            Format::Unit => de.deserialize_unit(Scalar("unit")),
            Format::Bool => de.deserialize_bool(Scalar("bool")),
            Format::I8 => de.deserialize_i8(Scalar("i8")),
            Format::I16 => de.deserialize_i16(Scalar("i16")),
            Format::I32 => de.deserialize_i32(Scalar("i32")),
            Format::I64 => de.deserialize_i64(Scalar("i64")),
            Format::I128 => de.deserialize_i128(Scalar("i128")),
            Format::U8 => de.deserialize_u8(Scalar("u8")),
            Format::U16 => de.deserialize_u16(Scalar("u16")),
            Format::U32 => de.deserialize_u32(Scalar("u32")),
            Format::U64 => de.deserialize_u64(Scalar("u64")),
            Format::U128 => de.deserialize_u128(Scalar("u128")),
            Format::F32 => de.deserialize_f32(Scalar("f32")),
            Format::F64 => de.deserialize_f64(Scalar("f64")),
            Format::Char => de.deserialize_char(Scalar("char")),
            Format::Str => de.deserialize_str(Scalar("string")),
            Format::Bytes => de.deserialize_bytes(Scalar("bytes")),
            Format::Option(inner) => de.deserialize_option(OptionVisitor { at, inner: *inner }),
            Format::Seq(item) => de.deserialize_seq(SeqVisitor { at, item: *item }),
            Format::Map { key, value } => de.deserialize_map(MapVisitor {
                at,
                key: *key,
                value: *value,
            }),
            Format::Tuple(items) => de.deserialize_tuple(items.len(), List::listed(at, items)),
            Format::Array { item, len } => {
                de.deserialize_tuple(*len as usize, List::repeated(at, *item, *len))
            }
            Format::Named(index) => self.container(*index, de),
        }
    }

    fn container<'de, D: Deserializer<'de>>(self, index: u32, de: D) -> Result<Value, D::Error> {
        let Some(container) = self.at.cx.layout.container(index) else {
            return Err(self.at.missing("container", index));
        };
        let at = self.at;
        match &container.shape {
            ContainerShape::UnitStruct => de.deserialize_unit_struct("", Scalar("unit struct")),
            ContainerShape::NewType(inner) => {
                de.deserialize_newtype_struct("", NewtypeVisitor { at, inner: *inner })
            }
            ContainerShape::TupleStruct(items) => {
                de.deserialize_tuple_struct("", items.len(), List::listed(at, items))
            }
            // postcard writes a struct as the tuple of its fields (`deserialize_struct` would
            // need the field names only to count them).
            ContainerShape::Struct(fields) => {
                de.deserialize_tuple(fields.len(), StructVisitor { at, fields })
            }
            ContainerShape::Enum(_) => de.deserialize_enum("", &[], EnumVisitor { at, container }),
        }
    }
}

/// Every value without inner values.
struct Scalar(&'static str);

impl<'de> Visitor<'de> for Scalar {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.0)
    }

    fn visit_unit<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }

    fn visit_bool<E>(self, v: bool) -> Result<Value, E> {
        Ok(Value::Bool(v))
    }

    fn visit_i64<E>(self, v: i64) -> Result<Value, E> {
        Ok(Value::from(v))
    }

    fn visit_u64<E>(self, v: u64) -> Result<Value, E> {
        Ok(Value::from(v))
    }

    fn visit_i128<E>(self, v: i128) -> Result<Value, E> {
        Ok(wide_integer(
            v,
            i64::try_from(v).ok(),
            u64::try_from(v).ok(),
        ))
    }

    fn visit_u128<E>(self, v: u128) -> Result<Value, E> {
        Ok(wide_integer(v, None, u64::try_from(v).ok()))
    }

    fn visit_f32<E>(self, v: f32) -> Result<Value, E> {
        Ok(float32(v))
    }

    fn visit_f64<E>(self, v: f64) -> Result<Value, E> {
        Ok(float64(v))
    }

    fn visit_char<E>(self, v: char) -> Result<Value, E> {
        Ok(Value::String(v.to_string()))
    }

    fn visit_str<E>(self, v: &str) -> Result<Value, E> {
        Ok(Value::String(v.to_owned()))
    }

    fn visit_bytes<E>(self, v: &[u8]) -> Result<Value, E> {
        Ok(Value::Array(
            v.iter().map(|byte| Value::from(*byte)).collect(),
        ))
    }
}

/// A 128-bit integer: a number if it fits in 64 bits, else a decimal string.
fn wide_integer(v: impl fmt::Display, signed: Option<i64>, unsigned: Option<u64>) -> Value {
    match (signed, unsigned) {
        (_, Some(n)) => Value::from(n),
        (Some(n), None) => Value::from(n),
        (None, None) => Value::String(v.to_string()),
    }
}

/// An `f32` as the shortest decimal that reads back as it (see the module docs).
fn float32(v: f32) -> Value {
    let shortest = format!("{v:e}").parse::<f64>().unwrap_or(f64::from(v));
    finite_or_named(shortest)
}

fn float64(v: f64) -> Value {
    finite_or_named(v)
}

fn finite_or_named(v: f64) -> Value {
    match Number::from_f64(v) {
        Some(number) => Value::Number(number),
        None if v.is_nan() => Value::String("NaN".to_owned()),
        None if v > 0.0 => Value::String("inf".to_owned()),
        None => Value::String("-inf".to_owned()),
    }
}

struct OptionVisitor<'a> {
    at: At<'a>,
    inner: u32,
}

impl<'de> Visitor<'de> for OptionVisitor<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an option")
    }

    fn visit_none<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }

    fn visit_some<D: Deserializer<'de>>(self, de: D) -> Result<Value, D::Error> {
        self.at.seed(self.inner, Step::Inner).deserialize(de)
    }
}

struct NewtypeVisitor<'a> {
    at: At<'a>,
    inner: u32,
}

impl<'de> Visitor<'de> for NewtypeVisitor<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a newtype struct")
    }

    fn visit_newtype_struct<D: Deserializer<'de>>(self, de: D) -> Result<Value, D::Error> {
        self.at.seed(self.inner, Step::Inner).deserialize(de)
    }
}

struct SeqVisitor<'a> {
    at: At<'a>,
    item: u32,
}

impl<'de> Visitor<'de> for SeqVisitor<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        // Grows only as elements arrive: the length prefix is never trusted for allocation.
        let mut out = Vec::new();
        while let Some(item) =
            seq.next_element_seed(self.at.seed(self.item, Step::Index(out.len())))?
        {
            out.push(item);
        }
        Ok(Value::Array(out))
    }
}

/// The elements of a tuple, array or tuple struct: their formats listed, or one repeated.
struct List<'a> {
    at: At<'a>,
    listed: &'a [u32],
    repeated: Option<(u32, u32)>,
}

impl<'a> List<'a> {
    fn listed(at: At<'a>, items: &'a [u32]) -> Self {
        List {
            at,
            listed: items,
            repeated: None,
        }
    }

    fn repeated(at: At<'a>, item: u32, len: u32) -> Self {
        List {
            at,
            listed: &[],
            repeated: Some((item, len)),
        }
    }

    fn format(&self, index: usize) -> Option<u32> {
        match self.repeated {
            Some((item, len)) => (index < len as usize).then_some(item),
            None => self.listed.get(index).copied(),
        }
    }
}

impl<'de> Visitor<'de> for List<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a tuple")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut out = Vec::new();
        while let Some(format) = self.format(out.len()) {
            let element = seq.next_element_seed(self.at.seed(format, Step::Index(out.len())))?;
            out.push(self.at.element(element)?);
        }
        Ok(Value::Array(out))
    }
}

struct StructVisitor<'a> {
    at: At<'a>,
    fields: &'a [Field],
}

impl<'de> Visitor<'de> for StructVisitor<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a struct")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut out = Map::new();
        for field in self.fields {
            let value =
                seq.next_element_seed(self.at.seed(field.format, Step::Name(&field.name)))?;
            out.insert(field.name.clone(), self.at.element(value)?);
        }
        Ok(Value::Object(out))
    }
}

struct MapVisitor<'a> {
    at: At<'a>,
    key: u32,
    value: u32,
}

impl<'de> Visitor<'de> for MapVisitor<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a map")
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Value, A::Error> {
        match self.at.cx.layout.format(self.key) {
            Some(Format::Str) => self.object(map),
            _ => self.pairs(map),
        }
    }
}

impl MapVisitor<'_> {
    fn object<'de, A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut out = Map::new();
        let mut index = 0;
        while let Some(key) = map.next_key_seed(self.at.seed(self.key, Step::Index(index)))? {
            let key = match key {
                Value::String(key) => key,
                other => other.to_string(),
            };
            let value = map.next_value_seed(self.at.seed(self.value, Step::Name(&key)))?;
            out.insert(key, value);
            index += 1;
        }
        Ok(Value::Object(out))
    }

    fn pairs<'de, A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut out = Vec::new();
        loop {
            let entry = self.at.enter(Step::Index(out.len()));
            let Some(key) = map.next_key_seed(entry.seed(self.key, Step::Index(0)))? else {
                return Ok(Value::Array(out));
            };
            let value = map.next_value_seed(entry.seed(self.value, Step::Index(1)))?;
            out.push(Value::Array(vec![key, value]));
        }
    }
}

struct EnumVisitor<'a> {
    at: At<'a>,
    container: &'a Container,
}

impl<'de> Visitor<'de> for EnumVisitor<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an enum")
    }

    fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<Value, A::Error> {
        let (index, access) = data.variant::<u32>()?;
        let variant = self.variant(index)?;
        let at = self.at.enter(Step::Name(&variant.name));
        let value = match &variant.shape {
            VariantShape::Unit => {
                access.unit_variant()?;
                return Ok(Value::String(variant.name.clone()));
            }
            VariantShape::NewType(inner) => {
                access.newtype_variant_seed(at.seed(*inner, Step::Inner))?
            }
            VariantShape::Tuple(items) => {
                access.tuple_variant(items.len(), List::listed(at, items))?
            }
            VariantShape::Struct(fields) => {
                access.tuple_variant(fields.len(), StructVisitor { at, fields })?
            }
        };
        let mut out = Map::new();
        out.insert(variant.name.clone(), value);
        Ok(Value::Object(out))
    }
}

impl<'a> EnumVisitor<'a> {
    fn variant<E: de::Error>(&self, index: u32) -> Result<&'a Variant, E> {
        let ContainerShape::Enum(variants) = &self.container.shape else {
            return Err(self
                .at
                .fail(format!("{} is not an enum", self.container.name)));
        };
        let found = variants.binary_search_by_key(&index, |variant| variant.index);
        found
            .ok()
            .and_then(|position| variants.get(position))
            .ok_or_else(|| {
                let name = &self.container.name;
                self.at
                    .fail(format!("enum {name} has no variant with index {index}"))
            })
    }
}

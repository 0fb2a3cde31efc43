//! JSON → payload: a [`Serialize`] implementation walking the layout and the JSON value
//! together, written out by `postcard::to_allocvec`.
//!
//! A mismatch is recorded in full in [`Cx`] (postcard's error type would keep only its kind)
//! by the innermost value that finds it; the outer values only pass the error up.

use std::cell::RefCell;

use serde::ser::{
    self, Serialize, SerializeMap, SerializeSeq, SerializeStruct, SerializeStructVariant,
    SerializeTuple, SerializeTupleStruct, SerializeTupleVariant, Serializer,
};
use serde_json::{Map, Value};

use super::path::{Path, Step};
use super::{DynamicError, MAX_DEPTH};
use crate::types::{Container, ContainerShape, Field, Format, TypeLayout, Variant, VariantShape};

/// What a missing struct field stands for when its type accepts it.
static NULL: Value = Value::Null;

/// Encodes `value`; see [`super::encode_json`].
pub(super) fn encode(layout: &TypeLayout, value: &Value) -> Result<Vec<u8>, DynamicError> {
    let cx = Cx {
        layout,
        failure: RefCell::new(None),
    };
    let at = At {
        cx: &cx,
        path: Path::ROOT,
        value,
    };
    let root = at.enc(layout.root, Step::Inner, value);
    postcard::to_allocvec(&root).map_err(|err| {
        cx.failure.take().unwrap_or_else(|| DynamicError::Encode {
            path: "/".to_owned(),
            expected: "a value postcard can write".to_owned(),
            found: err.to_string(),
        })
    })
}

/// State shared by every value of one encode.
struct Cx<'a> {
    layout: &'a TypeLayout,
    /// The first error, with its path.
    failure: RefCell<Option<DynamicError>>,
}

impl Cx<'_> {
    /// Records `error` unless one is recorded already, and returns it for postcard to carry.
    fn fail<E: ser::Error>(&self, error: DynamicError) -> E {
        let message = error.to_string();
        self.failure.borrow_mut().get_or_insert(error);
        E::custom(message)
    }
}

/// A place in the JSON value, and the JSON found there.
#[derive(Clone, Copy)]
struct At<'a> {
    cx: &'a Cx<'a>,
    path: Path<'a>,
    value: &'a Value,
}

impl<'a> At<'a> {
    /// The place one `step` inside this one, holding `value`.
    fn enter<'b>(&'b self, step: Step<'b>, value: &'b Value) -> At<'b> {
        At {
            cx: self.cx,
            path: self.path.child(step),
            value,
        }
    }

    /// The encoder of `value`, of `format`, one `step` inside this place.
    fn enc<'b>(&'b self, format: u32, step: Step<'b>, value: &'b Value) -> Enc<'b> {
        Enc {
            at: self.enter(step, value),
            format,
        }
    }

    fn mismatch<E: ser::Error>(&self, expected: impl Into<String>) -> E {
        self.cx.fail(DynamicError::Encode {
            path: self.path.render(),
            expected: expected.into(),
            found: describe(self.value),
        })
    }

    /// The elements of an array of exactly `len` elements.
    fn elements<E: ser::Error>(&self, len: usize) -> Result<&'a [Value], E> {
        match self.value {
            Value::Array(items) if items.len() == len => Ok(items),
            _ => Err(self.mismatch(array_of(len))),
        }
    }

    /// Calls `emit` with the encoder of each element of an array of `len` elements, whose
    /// formats `formats` yields.
    fn each_element<E: ser::Error>(
        &self,
        len: usize,
        formats: impl Iterator<Item = u32>,
        mut emit: impl FnMut(&Enc<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        let values = self.elements(len)?;
        for (index, (format, value)) in formats.zip(values).enumerate() {
            emit(&self.enc(format, Step::Index(index), value))?;
        }
        Ok(())
    }

    /// Calls `emit` with the encoder of each field of the struct (or struct variant) `owner`.
    fn each_field<E: ser::Error>(
        &self,
        owner: &str,
        fields: &[Field],
        mut emit: impl FnMut(&Enc<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        let Value::Object(object) = self.value else {
            return Err(self.mismatch(format!("object (struct {owner})")));
        };
        self.reject_unknown(owner, fields, object)?;
        for field in fields {
            let value = self.field(field, object.get(&field.name))?;
            emit(&self.enc(field.format, Step::Name(&field.name), value))?;
        }
        Ok(())
    }

    /// A field's value; a missing field is `null` if its type accepts `null`.
    fn field<'b, E: ser::Error>(
        &self,
        field: &Field,
        value: Option<&'b Value>,
    ) -> Result<&'b Value, E> {
        match value {
            Some(value) => Ok(value),
            None if accepts_null(self.cx.layout, field.format) => Ok(&NULL),
            None => {
                let path = self.path.child(Step::Name(&field.name)).render();
                let expected = expected(self.cx.layout, field.format);
                let found = "nothing (the field is missing)".to_owned();
                Err(self.cx.fail(DynamicError::Encode {
                    path,
                    expected,
                    found,
                }))
            }
        }
    }

    fn reject_unknown<E: ser::Error>(
        &self,
        owner: &str,
        fields: &[Field],
        object: &Map<String, Value>,
    ) -> Result<(), E> {
        let Some(unknown) = object
            .keys()
            .find(|key| !fields.iter().any(|f| &f.name == *key))
        else {
            return Ok(());
        };
        let names: Vec<&str> = fields.iter().map(|field| field.name.as_str()).collect();
        Err(self.cx.fail(DynamicError::Encode {
            path: self.path.render(),
            expected: format!("a field of {owner} ({})", names.join(", ")),
            found: format!("field {unknown:?}"),
        }))
    }

    /// The key and value of a `[key, value]` pair.
    fn pair<E: ser::Error>(&self) -> Result<(&'a Value, &'a Value), E> {
        match self.value.as_array().map(Vec::as_slice) {
            Some([key, value]) => Ok((key, value)),
            _ => Err(self.mismatch("a [key, value] pair")),
        }
    }
}

/// Encodes the JSON at `at` as a value of `format`.
struct Enc<'a> {
    at: At<'a>,
    format: u32,
}

impl Serialize for Enc<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let at = &self.at;
        if at.path.depth() > MAX_DEPTH {
            let (path, limit) = (at.path.render(), MAX_DEPTH);
            return Err(at.cx.fail(DynamicError::TooDeep { path, limit }));
        }
        let Some(format) = at.cx.layout.format(self.format) else {
            return Err(self.missing("format", self.format));
        };
        match format {
            Format::Option(inner) => self.option(*inner, s),
            Format::Seq(item) => self.seq(*item, s),
            Format::Map { key, value } => self.map(*key, *value, s),
            Format::Tuple(items) => {
                let formats = items.iter().copied();
                let mut tuple = s.serialize_tuple(items.len())?;
                at.each_element(items.len(), formats, |e| tuple.serialize_element(e))?;
                tuple.end()
            }
            Format::Array { item, len } => {
                let (len, formats) = (*len as usize, std::iter::repeat(*item));
                let mut tuple = s.serialize_tuple(len)?;
                at.each_element(len, formats, |e| tuple.serialize_element(e))?;
                tuple.end()
            }
            Format::Named(index) => self.container(*index, s),
            scalar => self.scalar(scalar, s),
        }
    }
}

impl Enc<'_> {
    fn mismatch<E: ser::Error>(&self) -> E {
        self.at.mismatch(expected(self.at.cx.layout, self.format))
    }

    fn want<T, E: ser::Error>(&self, found: Option<T>) -> Result<T, E> {
        found.ok_or_else(|| self.mismatch())
    }

    fn missing<E: ser::Error>(&self, what: &'static str, index: u32) -> E {
        let path = self.at.path.render();
        self.at
            .cx
            .fail(DynamicError::BadLayout { path, what, index })
    }

    fn scalar<S: Serializer>(&self, format: &Format, s: S) -> Result<S::Ok, S::Error> {
        let v = self.at.value;
        match format {
            Format::Unit => self.want(v.as_null()).and_then(|()| s.serialize_unit()),
            Format::Bool => s.serialize_bool(self.want(v.as_bool())?),
            Format::I8 => s.serialize_i8(self.want(signed(v))?),
            Format::I16 => s.serialize_i16(self.want(signed(v))?),
            Format::I32 => s.serialize_i32(self.want(signed(v))?),
            Format::I64 => s.serialize_i64(self.want(signed(v))?),
            Format::I128 => s.serialize_i128(self.want(signed(v))?),
            Format::U8 => s.serialize_u8(self.want(unsigned(v))?),
            Format::U16 => s.serialize_u16(self.want(unsigned(v))?),
            Format::U32 => s.serialize_u32(self.want(unsigned(v))?),
            Format::U64 => s.serialize_u64(self.want(unsigned(v))?),
            Format::U128 => s.serialize_u128(self.want(unsigned(v))?),
            Format::F32 => s.serialize_f32(self.want(float32(v))?),
            Format::F64 => s.serialize_f64(self.want(float64(v))?),
            Format::Char => s.serialize_char(self.want(single_char(v))?),
            Format::Str => s.serialize_str(self.want(v.as_str())?),
            Format::Bytes => s.serialize_bytes(&self.want(bytes(v))?),
            _ => Err(self.mismatch()),
        }
    }

    fn option<S: Serializer>(&self, inner: u32, s: S) -> Result<S::Ok, S::Error> {
        match self.at.value {
            Value::Null => s.serialize_none(),
            value => s.serialize_some(&self.at.enc(inner, Step::Inner, value)),
        }
    }

    fn seq<S: Serializer>(&self, item: u32, s: S) -> Result<S::Ok, S::Error> {
        let items = self.want(self.at.value.as_array())?;
        let mut seq = s.serialize_seq(Some(items.len()))?;
        for (index, value) in items.iter().enumerate() {
            seq.serialize_element(&self.at.enc(item, Step::Index(index), value))?;
        }
        seq.end()
    }

    fn map<S: Serializer>(&self, key: u32, value: u32, s: S) -> Result<S::Ok, S::Error> {
        match self.at.value {
            Value::Object(object) => {
                let mut map = s.serialize_map(Some(object.len()))?;
                for (name, item) in object {
                    let at = self.at.enter(Step::Name(name), item);
                    let name = Value::String(name.clone());
                    let key = at.enc(key, Step::Inner, &name);
                    map.serialize_entry(&key, &at.enc(value, Step::Inner, item))?;
                }
                map.end()
            }
            Value::Array(pairs) => {
                let mut map = s.serialize_map(Some(pairs.len()))?;
                for (index, pair) in pairs.iter().enumerate() {
                    let at = self.at.enter(Step::Index(index), pair);
                    let (k, v) = at.pair()?;
                    let key = at.enc(key, Step::Index(0), k);
                    map.serialize_entry(&key, &at.enc(value, Step::Index(1), v))?;
                }
                map.end()
            }
            _ => Err(self.mismatch()),
        }
    }

    fn container<S: Serializer>(&self, index: u32, s: S) -> Result<S::Ok, S::Error> {
        let Some(container) = self.at.cx.layout.container(index) else {
            return Err(self.missing("container", index));
        };
        let at = &self.at;
        match &container.shape {
            ContainerShape::UnitStruct => self
                .want(at.value.as_null())
                .and_then(|()| s.serialize_unit_struct("")),
            ContainerShape::NewType(inner) => {
                s.serialize_newtype_struct("", &at.enc(*inner, Step::Inner, at.value))
            }
            ContainerShape::TupleStruct(items) => {
                let formats = items.iter().copied();
                let mut tuple = s.serialize_tuple_struct("", items.len())?;
                at.each_element(items.len(), formats, |e| tuple.serialize_field(e))?;
                tuple.end()
            }
            ContainerShape::Struct(fields) => {
                let mut fields_out = s.serialize_struct("", fields.len())?;
                at.each_field(&container.name, fields, |e| {
                    fields_out.serialize_field("", e)
                })?;
                fields_out.end()
            }
            ContainerShape::Enum(variants) => self.variant(container, variants, s),
        }
    }

    fn variant<S: Serializer>(
        &self,
        container: &Container,
        variants: &[Variant],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        let (tag, payload) = self.tagged()?;
        let Some(variant) = variants.iter().find(|variant| variant.name == tag) else {
            let names: Vec<&str> = variants.iter().map(|v| v.name.as_str()).collect();
            let expected = format!("a variant of {} ({})", container.name, names.join(", "));
            return Err(self.at.mismatch(expected));
        };
        let at = self
            .at
            .enter(Step::Name(&variant.name), payload.unwrap_or(&NULL));
        let index = variant.index;
        match (&variant.shape, payload) {
            (VariantShape::Unit, None | Some(Value::Null)) => {
                s.serialize_unit_variant("", index, "")
            }
            (VariantShape::Unit, Some(_)) => Err(at.mismatch("null (unit variant)")),
            (_, None) => Err(self.at.mismatch(format!("{{{tag:?}: value}}"))),
            (VariantShape::NewType(inner), Some(value)) => {
                s.serialize_newtype_variant("", index, "", &at.enc(*inner, Step::Inner, value))
            }
            (VariantShape::Tuple(items), Some(_)) => {
                let formats = items.iter().copied();
                let mut tuple = s.serialize_tuple_variant("", index, "", items.len())?;
                at.each_element(items.len(), formats, |e| tuple.serialize_field(e))?;
                tuple.end()
            }
            (VariantShape::Struct(fields), Some(_)) => {
                let mut fields_out = s.serialize_struct_variant("", index, "", fields.len())?;
                at.each_field(&variant.name, fields, |e| fields_out.serialize_field("", e))?;
                fields_out.end()
            }
        }
    }

    /// The variant name and payload of an enum value: `"Name"` or `{"Name": payload}`.
    fn tagged<E: ser::Error>(&self) -> Result<(&str, Option<&Value>), E> {
        match self.at.value {
            Value::String(tag) => Ok((tag, None)),
            Value::Object(object) if object.len() == 1 => {
                let first = object.iter().next();
                first
                    .map(|(tag, payload)| (tag.as_str(), Some(payload)))
                    .ok_or_else(|| self.mismatch())
            }
            _ => Err(self.mismatch()),
        }
    }
}

/// An integer from a number or a decimal string, if it fits in `T`.
fn signed<T: TryFrom<i128>>(value: &Value) -> Option<T> {
    let wide = match value {
        Value::Number(n) => n.as_i64().map(i128::from).or(n.as_u64().map(i128::from))?,
        Value::String(text) => text.parse().ok()?,
        _ => return None,
    };
    T::try_from(wide).ok()
}

/// A non-negative integer from a number or a decimal string, if it fits in `T`.
fn unsigned<T: TryFrom<u128>>(value: &Value) -> Option<T> {
    let wide = match value {
        Value::Number(n) => n.as_u64().map(u128::from)?,
        Value::String(text) => text.parse().ok()?,
        _ => return None,
    };
    T::try_from(wide).ok()
}

/// A float named by a string: `"NaN"`, `"inf"`, `"-inf"`.
fn named_float(text: &str) -> Option<f64> {
    match text {
        "NaN" => Some(f64::NAN),
        "inf" => Some(f64::INFINITY),
        "-inf" => Some(f64::NEG_INFINITY),
        _ => None,
    }
}

fn float64(value: &Value) -> Option<f64> {
    match value {
        Value::Number(n) => n.as_f64(),
        Value::String(text) => named_float(text),
        _ => None,
    }
}

/// An `f32`, read from the number's shortest decimal text so that the decimal `decode` wrote
/// comes back as the very same `f32` (going through `f64` would round twice). A finite number
/// too large for `f32` is rejected.
fn float32(value: &Value) -> Option<f32> {
    match value {
        Value::Number(n) => n.to_string().parse::<f32>().ok().filter(|f| f.is_finite()),
        Value::String(text) => named_float(text).map(|f| f as f32),
        _ => None,
    }
}

fn single_char(value: &Value) -> Option<char> {
    let mut chars = value.as_str()?.chars();
    let first = chars.next()?;
    chars.next().is_none().then_some(first)
}

fn bytes(value: &Value) -> Option<Vec<u8>> {
    let items = value.as_array()?;
    items
        .iter()
        .map(|item| item.as_u64().and_then(|n| u8::try_from(n).ok()))
        .collect()
}

/// Whether a missing struct field of `format` may stand for `null`.
fn accepts_null(layout: &TypeLayout, format: u32) -> bool {
    match layout.format(format) {
        Some(Format::Unit | Format::Option(_)) => true,
        Some(Format::Named(index)) => layout
            .container(*index)
            .is_some_and(|c| matches!(c.shape, ContainerShape::UnitStruct)),
        _ => false,
    }
}

/// What JSON the layout wants for `format`, for error messages. Never recurses.
fn expected(layout: &TypeLayout, format: u32) -> String {
    let text = match layout.format(format) {
        None => "nothing (the layout is broken)",
        Some(Format::Unit) => "null",
        Some(Format::Bool) => "bool",
        Some(Format::I8) => "i8",
        Some(Format::I16) => "i16",
        Some(Format::I32) => "i32",
        Some(Format::I64) => "i64",
        Some(Format::I128) => "i128",
        Some(Format::U8) => "u8",
        Some(Format::U16) => "u16",
        Some(Format::U32) => "u32",
        Some(Format::U64) => "u64",
        Some(Format::U128) => "u128",
        Some(Format::F32) => "f32",
        Some(Format::F64) => "f64",
        Some(Format::Char) => "char (a one-character string)",
        Some(Format::Str) => "string",
        Some(Format::Bytes) => "bytes (an array of numbers 0-255)",
        Some(Format::Option(_)) => "option",
        Some(Format::Seq(_)) => "array",
        Some(Format::Map { .. }) => "object or array of [key, value] pairs",
        Some(Format::Tuple(items)) => return array_of(items.len()),
        Some(Format::Array { len, .. }) => return array_of(*len as usize),
        Some(Format::Named(index)) => return expected_container(layout.container(*index)),
    };
    text.to_owned()
}

fn expected_container(container: Option<&Container>) -> String {
    let Some(container) = container else {
        return "nothing (the layout is broken)".to_owned();
    };
    let name = &container.name;
    match &container.shape {
        ContainerShape::UnitStruct => format!("null (unit struct {name})"),
        ContainerShape::NewType(_) => format!("newtype {name}"),
        ContainerShape::TupleStruct(items) => format!("{} ({name})", array_of(items.len())),
        ContainerShape::Struct(_) => format!("object (struct {name})"),
        ContainerShape::Enum(_) => format!("\"Variant\" or {{\"Variant\": value}} (enum {name})"),
    }
}

/// What a JSON value is, for error messages.
fn describe(value: &Value) -> String {
    match value {
        Value::Null => "null".to_owned(),
        Value::Bool(b) => format!("bool {b}"),
        Value::Number(n) => format!("number {n}"),
        Value::String(text) if text.chars().count() <= 40 => format!("string {text:?}"),
        Value::String(text) => {
            let start: String = text.chars().take(40).collect();
            format!("string {start:?}…")
        }
        Value::Array(items) => array_of(items.len()),
        Value::Object(_) => "object".to_owned(),
    }
}

fn array_of(len: usize) -> String {
    match len {
        1 => "array of 1 element".to_owned(),
        _ => format!("array of {len} elements"),
    }
}

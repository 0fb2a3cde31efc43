//! Samples between Python objects and postcard bytes, driven by a [`TypeLayout`].
//!
//! Encoding implements `serde::Serialize` for a Python object seen through a format of the
//! layout, and decoding `serde::de::DeserializeSeed`, so postcard itself writes and reads the
//! bytes: a Python sample is byte for byte what the Rust type of the same shape writes.
//!
//! How Python sees each layout node:
//!
//! | layout                 | encoded from                                  | decoded to            |
//! |------------------------|-----------------------------------------------|-----------------------|
//! | bool, integers, floats | `bool`, `int` (in the width's range), `float` | the same              |
//! | `str`, `char`          | `str` (one character for `char`)              | `str`                 |
//! | `bytes`                | `bytes`, `bytearray`                          | `bytes`               |
//! | `unit`                 | `None`                                        | `None`                |
//! | option                 | `None` or the value                           | the same              |
//! | seq, array             | any sized iterable (`list`, `tuple`, ...)     | `list`                |
//! | tuple, tuple struct    | any sized iterable of the right length        | `tuple`               |
//! | map                    | `dict`                                        | `dict`                |
//! | struct                 | its dataclass, or any object or `dict` with the fields | the dataclass, or a `dict` |
//! | newtype struct         | the inner value                               | the inner value       |
//! | enum, unit variant     | its `enum.Enum` member, or the variant's name | the member, or the name |
//! | enum, other variants   | `{"Variant": value}`                          | the same              |
//!
//! Errors name where they happened (`pose.x`, `points[3]`): a value of the wrong type or out
//! of its width's range raises `TypeError`; bytes that do not decode raise `ValueError`. Nothing
//! is allocated from a length the payload claims, values nest at most
//! [`MAX_DEPTH`](ndds_core::dynamic::MAX_DEPTH) deep, and a payload decodes to at most
//! [`value_limit`](ndds_core::dynamic::value_limit) values, as `ndds echo`'s decoder.

use std::cell::{Cell, RefCell};
use std::fmt;

use ndds_core::dynamic::{MAX_DEPTH, value_limit};
use ndds_core::types::{ContainerShape, Format, TypeLayout, VariantShape};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyDict, PyList, PyString, PyTuple};
use serde::Serialize;
use serde::de::{
    self, DeserializeSeed, Deserializer, EnumAccess, MapAccess, SeqAccess, VariantAccess, Visitor,
};
use serde::ser::{self, SerializeMap, SerializeSeq, SerializeTuple, Serializer};

/// How Python sees one container of the layout.
pub(crate) enum PyShape {
    /// A struct as a `dict`, an enum's variants as names (untyped consumers).
    Plain,
    /// A struct as instances of this class, built with its fields as positional arguments.
    Class(Py<PyAny>),
    /// The same, built with its fields as keyword arguments (a dataclass with keyword-only
    /// fields).
    KeywordClass(Py<PyAny>),
    /// An enum of unit variants as this `enum.Enum`'s members, in variant order.
    Members(Vec<Py<PyAny>>),
}

/// A layout and how Python sees its containers: encodes and decodes samples.
pub(crate) struct Codec {
    layout: TypeLayout,
    /// Per container (layout order).
    shapes: Vec<PyShape>,
    /// Per container: its field names (structs) or variant names (enums), as Python strings.
    names: Vec<Vec<Py<PyString>>>,
}

impl Codec {
    /// A codec over `layout`; `shapes` per container (missing ones are [`PyShape::Plain`]).
    pub(crate) fn new(py: Python<'_>, layout: TypeLayout, mut shapes: Vec<PyShape>) -> Self {
        shapes.resize_with(layout.containers.len(), || PyShape::Plain);
        let names = layout
            .containers
            .iter()
            .map(|container| match &container.shape {
                ContainerShape::Struct(fields) => fields
                    .iter()
                    .map(|f| PyString::intern(py, &f.name).unbind())
                    .collect(),
                ContainerShape::Enum(variants) => variants
                    .iter()
                    .map(|v| PyString::intern(py, &v.name).unbind())
                    .collect(),
                _ => Vec::new(),
            })
            .collect();
        Codec {
            layout,
            shapes,
            names,
        }
    }

    /// Encodes `value` as a sample of the layout's root type.
    pub(crate) fn encode(&self, value: &Bound<'_, PyAny>) -> PyResult<Vec<u8>> {
        let ctx = Ctx {
            codec: self,
            path: RefCell::new(Vec::new()),
            error: RefCell::new(None),
            values: Cell::new(0),
            limit: usize::MAX,
        };
        let root = Enc {
            ctx: &ctx,
            format: self.layout.root,
            value: value.clone(),
            depth: 0,
        };
        match postcard::to_stdvec(&root) {
            Ok(bytes) => Ok(bytes),
            Err(err) => Err(ctx.error.take().unwrap_or_else(|| {
                PyValueError::new_err(format!("cannot encode the sample: {err}"))
            })),
        }
    }

    /// Decodes a sample of the layout's root type.
    pub(crate) fn decode<'py>(
        &self,
        py: Python<'py>,
        payload: &[u8],
    ) -> PyResult<Bound<'py, PyAny>> {
        let ctx = Ctx {
            codec: self,
            path: RefCell::new(Vec::new()),
            error: RefCell::new(None),
            values: Cell::new(0),
            limit: value_limit(payload.len()),
        };
        let seed = Dec {
            ctx: &ctx,
            py,
            format: self.layout.root,
            depth: 0,
        };
        let mut deserializer = postcard::Deserializer::from_bytes(payload);
        let result = seed.deserialize(&mut deserializer);
        match result {
            Ok(value) => {
                let rest = deserializer.finalize().map(|rest| rest.len()).unwrap_or(0);
                if rest > 0 {
                    return Err(PyValueError::new_err(format!(
                        "the sample has {rest} bytes after its value: it was not written as this type"
                    )));
                }
                Ok(value)
            }
            Err(err) => Err(ctx.error.take().unwrap_or_else(|| {
                PyValueError::new_err(format!(
                    "the sample does not decode as its type{}: {err}",
                    ctx.at()
                ))
            })),
        }
    }
}

/// One encoding or decoding: where it is, and the Python error that stopped it.
struct Ctx<'a> {
    codec: &'a Codec,
    path: RefCell<Vec<Seg>>,
    error: RefCell<Option<PyErr>>,
    values: Cell<usize>,
    limit: usize,
}

impl Ctx<'_> {
    /// ` at pose.x`, or nothing at the root.
    fn at(&self) -> String {
        let path = self.path.borrow();
        if path.is_empty() {
            String::new()
        } else {
            format!(" at `{}`", join(&path))
        }
    }

    /// Records a `TypeError` naming the field, and returns the serde error that unwinds.
    fn type_error<E: ser::Error>(&self, what: String) -> E {
        let message = {
            let path = self.path.borrow();
            if path.is_empty() {
                format!("sample: {what}")
            } else {
                format!("sample field `{}`: {what}", join(&path))
            }
        };
        self.error
            .replace(Some(PyTypeError::new_err(message.clone())));
        E::custom(message)
    }

    /// Records a Python error raised while decoding.
    fn py_error<E: de::Error>(&self, err: PyErr) -> E {
        let message = err.to_string();
        self.error.replace(Some(err));
        E::custom(message)
    }

    /// Records why a payload does not decode (postcard's custom errors keep no text), and
    /// returns the serde error that unwinds.
    fn fail<E: de::Error>(&self, reason: impl Into<String>) -> E {
        let reason = reason.into();
        let message = format!(
            "the sample does not decode as its type{}: {reason}",
            self.at()
        );
        self.error.replace(Some(PyValueError::new_err(message)));
        E::custom(reason)
    }

    fn count<E: de::Error>(&self) -> Result<(), E> {
        let n = self.values.get() + 1;
        self.values.set(n);
        if n > self.limit {
            return Err(self.fail(format!(
                "the payload decodes to more than {} values",
                self.limit
            )));
        }
        Ok(())
    }
}

/// One step of the path to a value: a field or variant name, an index, a map key's repr.
/// Indexes are kept as numbers, so a path costs no allocation per element.
enum Seg {
    Name(String),
    Index(usize),
    /// A map's key, shown by its repr only when an error is reported.
    Key(Py<PyAny>),
}

fn join(path: &[Seg]) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    for segment in path {
        match segment {
            Seg::Name(name) => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(name);
            }
            Seg::Index(i) => {
                let _ = write!(out, "[{i}]");
            }
            Seg::Key(key) => {
                let shown = Python::attach(|py| {
                    key.bind(py)
                        .repr()
                        .map(|r| r.to_string())
                        .unwrap_or_default()
                });
                let _ = write!(out, "[{shown}]");
            }
        }
    }
    out
}

/// A short description of a Python value for messages: its type and, if short, its repr.
fn describe(value: &Bound<'_, PyAny>) -> String {
    let kind = value
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".to_owned());
    match value.repr() {
        Ok(repr) => {
            let repr = repr.to_string();
            if repr.chars().count() <= 40 {
                format!("{kind} {repr}")
            } else {
                kind
            }
        }
        Err(_) => kind,
    }
}

/// The layout's name for a format, for messages.
fn format_name(layout: &TypeLayout, format: u32) -> String {
    match &layout.formats[format as usize] {
        Format::Named(c) => layout.containers[*c as usize].name.clone(),
        other => format!("{other:?}").to_lowercase(),
    }
}

// ---------------------------------------------------------------------------------------------
// Encoding

/// A Python value to be written as `format`.
struct Enc<'a, 'py> {
    ctx: &'a Ctx<'a>,
    format: u32,
    value: Bound<'py, PyAny>,
    depth: usize,
}

impl<'a, 'py> Enc<'a, 'py> {
    fn child(&self, format: u32, value: Bound<'py, PyAny>) -> Enc<'a, 'py> {
        Enc {
            ctx: self.ctx,
            format,
            value,
            depth: self.depth + 1,
        }
    }

    /// Writes `value` as `format` under the path segment `segment`.
    fn element<S: SerializeTuple>(
        &self,
        out: &mut S,
        segment: Seg,
        format: u32,
        value: Bound<'py, PyAny>,
    ) -> Result<(), S::Error> {
        self.ctx.path.borrow_mut().push(segment);
        out.serialize_element(&self.child(format, value))?;
        self.ctx.path.borrow_mut().pop();
        Ok(())
    }

    fn expected<E: ser::Error>(&self, what: &str) -> E {
        self.ctx
            .type_error(format!("expected {what}, got {}", describe(&self.value)))
    }

    fn int<E: ser::Error, T: TryFrom<i128>>(&self, kind: &str) -> Result<T, E> {
        if self.value.is_instance_of::<pyo3::types::PyFloat>() {
            return Err(self.expected(&format!("an int ({kind})")));
        }
        let wide: i128 = self
            .value
            .extract()
            .map_err(|_| self.expected(&format!("an int ({kind})")))?;
        T::try_from(wide).map_err(|_| self.ctx.type_error(format!("{wide} does not fit {kind}")))
    }

    /// The value's text (`str` and `char`).
    fn text<E: ser::Error>(&self) -> Result<std::borrow::Cow<'_, str>, E> {
        let text = self
            .value
            .cast::<PyString>()
            .map_err(|_| self.expected("a str"))?;
        text.to_cow()
            .map_err(|e| self.ctx.type_error(e.to_string()))
    }

    /// A tuple, tuple struct or array: exactly one item per format, written in order.
    fn tuple<S: Serializer>(
        &self,
        serializer: S,
        formats: impl ExactSizeIterator<Item = u32>,
    ) -> Result<S::Ok, S::Error> {
        let len = formats.len();
        let values = self.items(Some(len))?;
        let mut out = serializer.serialize_tuple(len)?;
        for (i, (format, value)) in formats.zip(values).enumerate() {
            self.element(&mut out, Seg::Index(i), format, value)?;
        }
        out.end()
    }

    fn float<E: ser::Error>(&self, kind: &str) -> Result<f64, E> {
        self.value
            .extract::<f64>()
            .map_err(|_| self.expected(&format!("a float ({kind})")))
    }

    /// The items of a sequence value, with `len` checked if given.
    fn items<E: ser::Error>(&self, len: Option<usize>) -> Result<Vec<Bound<'py, PyAny>>, E> {
        if self.value.is_instance_of::<PyString>() || self.value.is_instance_of::<PyDict>() {
            return Err(self.expected("a list"));
        }
        let items: Vec<Bound<'py, PyAny>> = if let Ok(list) = self.value.cast::<PyList>() {
            list.iter().collect()
        } else if let Ok(tuple) = self.value.cast::<PyTuple>() {
            tuple.iter().collect()
        } else {
            let iter = self.value.try_iter().map_err(|_| self.expected("a list"))?;
            iter.collect::<PyResult<_>>()
                .map_err(|err| self.ctx.type_error(format!("cannot iterate: {err}")))?
        };
        if let Some(len) = len
            && items.len() != len
        {
            return Err(self
                .ctx
                .type_error(format!("expected {len} items, got {}", items.len())));
        }
        Ok(items)
    }

    fn fields<S: Serializer>(&self, container: usize, serializer: S) -> Result<S::Ok, S::Error> {
        let names = &self.ctx.codec.names[container];
        let py = self.value.py();
        let dict = self.value.cast::<PyDict>().ok();
        let ContainerShape::Struct(fields) = &self.ctx.codec.layout.containers[container].shape
        else {
            unreachable!("fields of a struct")
        };
        if let PyShape::Class(class) | PyShape::KeywordClass(class) =
            &self.ctx.codec.shapes[container]
            && dict.is_none()
            && !self.value.is_instance(class.bind(py)).unwrap_or(false)
        {
            let wanted = class
                .bind(py)
                .getattr("__name__")
                .map(|n| n.to_string())
                .unwrap_or_default();
            return Err(self.expected(&format!("a {wanted} (or a dict of its fields)")));
        }
        // A dict's keys are checked first: a misspelled optional field would otherwise pass
        // as a missing one.
        if let Some(dict) = dict {
            for key in dict.keys() {
                if !names
                    .iter()
                    .any(|n| PyAnyMethods::eq(n.bind(py).as_any(), &key).unwrap_or(false))
                {
                    return Err(self.ctx.type_error(format!(
                        "unknown field {} (fields: {})",
                        describe(&key),
                        fields
                            .iter()
                            .map(|f| f.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )));
                }
            }
        }
        let mut out = serializer.serialize_tuple(fields.len())?;
        for (field, name) in fields.iter().zip(names) {
            let name = name.bind(py);
            let value = match dict {
                Some(dict) => dict.get_item(name).ok().flatten(),
                None => self.value.getattr(name).ok(),
            };
            let value = match value {
                Some(value) => value,
                // A missing optional or unit field is `None`, as in `ndds pub`'s JSON.
                None if matches!(
                    self.ctx.codec.layout.formats[field.format as usize],
                    Format::Option(_) | Format::Unit
                ) =>
                {
                    py.None().into_bound(py)
                }
                None => {
                    self.ctx
                        .path
                        .borrow_mut()
                        .push(Seg::Name(field.name.clone()));
                    return Err(self.ctx.type_error(format!(
                        "missing (the {} has no field `{}`)",
                        describe(&self.value),
                        field.name
                    )));
                }
            };
            self.element(&mut out, Seg::Name(field.name.clone()), field.format, value)?;
        }
        out.end()
    }

    fn variant<S: Serializer>(&self, container: usize, serializer: S) -> Result<S::Ok, S::Error> {
        let ContainerShape::Enum(variants) = &self.ctx.codec.layout.containers[container].shape
        else {
            unreachable!("variants of an enum")
        };
        let py = self.value.py();
        // A member of an `enum.Enum`, a name, or `{"Variant": value}`.
        // A member first: a `StrEnum` member is also a `str`, whose value is not the name.
        let (name, inner): (String, Option<Bound<'py, PyAny>>) = if let Ok(name) =
            self.value.getattr(pyo3::intern!(py, "name"))
            && let Ok(members) = self
                .value
                .get_type()
                .getattr(pyo3::intern!(py, "__members__"))
            && members.contains(&name).unwrap_or(false)
        {
            (name.to_string(), None)
        } else if let Ok(name) = self.value.cast::<PyString>() {
            (name.to_string(), None)
        } else if let Ok(dict) = self.value.cast::<PyDict>()
            && dict.len() == 1
        {
            let (key, value) = dict.iter().next().expect("one item");
            (key.to_string(), Some(value))
        } else {
            let names: Vec<&str> = variants.iter().map(|v| v.name.as_str()).collect();
            return Err(self.expected(&format!(
                "a member of {} ({})",
                self.ctx.codec.layout.containers[container].name,
                names.join(", ")
            )));
        };
        let Some(variant) = variants.iter().find(|v| v.name == name) else {
            let names: Vec<&str> = variants.iter().map(|v| v.name.as_str()).collect();
            return Err(self.ctx.type_error(format!(
                "{} has no variant `{name}` ({})",
                self.ctx.codec.layout.containers[container].name,
                names.join(", ")
            )));
        };
        let index = variant.index;
        match (&variant.shape, inner) {
            (VariantShape::Unit, None) => serializer.serialize_unit_variant("", index, ""),
            (VariantShape::Unit, Some(inner)) if inner.is_none() => {
                serializer.serialize_unit_variant("", index, "")
            }
            (VariantShape::NewType(format), Some(inner)) => {
                self.ctx.path.borrow_mut().push(Seg::Name(name.clone()));
                let result = serializer.serialize_newtype_variant(
                    "",
                    index,
                    "",
                    &self.child(*format, inner),
                );
                self.ctx.path.borrow_mut().pop();
                result
            }
            (VariantShape::Tuple(items), Some(inner)) => {
                let enc = self.child(0, inner);
                let values = enc.items(Some(items.len()))?;
                // postcard writes a tuple variant as its index, then the items.
                let mut out = serializer.serialize_tuple(1 + items.len())?;
                out.serialize_element(&Varint(index))?;
                for (i, (format, value)) in items.iter().zip(values).enumerate() {
                    self.element(&mut out, Seg::Name(format!("{name}[{i}]")), *format, value)?;
                }
                out.end()
            }
            (VariantShape::Struct(fields), Some(inner)) => {
                let mut out = serializer.serialize_tuple(1 + fields.len())?;
                out.serialize_element(&Varint(index))?;
                let dict = inner.cast::<PyDict>().map_err(|_| {
                    self.ctx.type_error::<S::Error>(format!(
                        "variant `{name}`: expected a dict of its fields"
                    ))
                })?;
                if let Some(unknown) = dict.keys().iter().find(|key| {
                    !fields
                        .iter()
                        .any(|f| key.extract::<String>().is_ok_and(|k| k == f.name))
                }) {
                    return Err(self.ctx.type_error(format!(
                        "variant `{name}`: unknown field {}",
                        describe(&unknown)
                    )));
                }
                for field in fields {
                    let optional = matches!(
                        self.ctx.codec.layout.formats[field.format as usize],
                        Format::Option(_) | Format::Unit
                    );
                    let value = match dict.get_item(&field.name).ok().flatten() {
                        Some(value) => value,
                        None if optional => py.None().into_bound(py),
                        None => {
                            return Err(self.ctx.type_error(format!(
                                "variant `{name}`: field `{}` missing",
                                field.name
                            )));
                        }
                    };
                    self.element(
                        &mut out,
                        Seg::Name(format!("{name}.{}", field.name)),
                        field.format,
                        value,
                    )?;
                }
                out.end()
            }
            _ => Err(self.ctx.type_error(format!(
                "variant `{name}` of {} carries {}",
                self.ctx.codec.layout.containers[container].name,
                if matches!(variant.shape, VariantShape::Unit) {
                    "no value"
                } else {
                    "a value: write {\"Variant\": value}"
                }
            ))),
        }
    }
}

/// A variant index, written as postcard writes one (a varint).
struct Varint(u32);

impl Serialize for Varint {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        // postcard writes a `u32` as a varint, like a variant index.
        serializer.serialize_u32(self.0)
    }
}

impl Serialize for Enc<'_, '_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        if self.depth > MAX_DEPTH {
            return Err(self
                .ctx
                .type_error(format!("values nest deeper than {MAX_DEPTH} levels")));
        }
        let layout = &self.ctx.codec.layout;
        match &layout.formats[self.format as usize] {
            Format::Unit => {
                if !self.value.is_none() {
                    return Err(self.expected("None"));
                }
                serializer.serialize_unit()
            }
            Format::Bool => match self.value.extract::<bool>() {
                Ok(b) => serializer.serialize_bool(b),
                Err(_) => Err(self.expected("a bool")),
            },
            Format::I8 => serializer.serialize_i8(self.int("i8")?),
            Format::I16 => serializer.serialize_i16(self.int("i16")?),
            Format::I32 => serializer.serialize_i32(self.int("i32")?),
            Format::I64 => serializer.serialize_i64(self.int("i64")?),
            Format::I128 => serializer.serialize_i128(self.int("i128")?),
            Format::U8 => serializer.serialize_u8(self.int("u8")?),
            Format::U16 => serializer.serialize_u16(self.int("u16")?),
            Format::U32 => serializer.serialize_u32(self.int("u32")?),
            Format::U64 => serializer.serialize_u64(self.int("u64")?),
            Format::U128 => {
                let value: u128 = self
                    .value
                    .extract()
                    .map_err(|_| self.expected("an int (u128)"))?;
                serializer.serialize_u128(value)
            }
            Format::F32 => serializer.serialize_f32(self.float("f32")? as f32),
            Format::F64 => serializer.serialize_f64(self.float("f64")?),
            Format::Char => {
                let text = self.text()?;
                let mut chars = text.chars();
                match (chars.next(), chars.next()) {
                    (Some(c), None) => serializer.serialize_char(c),
                    _ => Err(self.expected("one character")),
                }
            }
            Format::Str => serializer.serialize_str(&self.text()?),
            Format::Bytes => {
                if let Ok(bytes) = self.value.cast::<PyBytes>() {
                    serializer.serialize_bytes(bytes.as_bytes())
                } else if let Ok(array) = self.value.cast::<PyByteArray>() {
                    serializer.serialize_bytes(&array.to_vec())
                } else {
                    Err(self.expected("bytes"))
                }
            }
            Format::Option(inner) => {
                if self.value.is_none() {
                    serializer.serialize_none()
                } else {
                    serializer.serialize_some(&self.child(*inner, self.value.clone()))
                }
            }
            Format::Seq(item) => {
                // `bytes` for a sequence of `u8` (a Rust `Vec<u8>`).
                if matches!(layout.formats[*item as usize], Format::U8)
                    && let Ok(bytes) = self.value.cast::<PyBytes>()
                {
                    let bytes = bytes.as_bytes();
                    let mut out = serializer.serialize_seq(Some(bytes.len()))?;
                    for byte in bytes {
                        out.serialize_element(byte)?;
                    }
                    return out.end();
                }
                let items = self.items(None)?;
                let mut out = serializer.serialize_seq(Some(items.len()))?;
                for (i, value) in items.into_iter().enumerate() {
                    self.ctx.path.borrow_mut().push(Seg::Index(i));
                    out.serialize_element(&self.child(*item, value))?;
                    self.ctx.path.borrow_mut().pop();
                }
                out.end()
            }
            Format::Map { key, value } => {
                let dict = self
                    .value
                    .cast::<PyDict>()
                    .map_err(|_| self.expected("a dict"))?;
                // A snapshot of the entries: encoding a value may run Python code (`__float__`,
                // `__iter__`, another thread) that changes the dict.
                let entries: Vec<(Bound<'_, PyAny>, Bound<'_, PyAny>)> = dict.iter().collect();
                let mut out = serializer.serialize_map(Some(entries.len()))?;
                for (k, v) in entries {
                    self.ctx
                        .path
                        .borrow_mut()
                        .push(Seg::Key(k.clone().unbind()));
                    out.serialize_entry(&self.child(*key, k), &self.child(*value, v))?;
                    self.ctx.path.borrow_mut().pop();
                }
                out.end()
            }
            Format::Tuple(items) => self.tuple(serializer, items.iter().copied()),
            Format::Array { item, len } => {
                self.tuple(serializer, std::iter::repeat_n(*item, *len as usize))
            }
            Format::Named(container) => {
                let container = *container as usize;
                match &layout.containers[container].shape {
                    ContainerShape::UnitStruct => serializer.serialize_unit_struct(""),
                    ContainerShape::NewType(inner) => serializer
                        .serialize_newtype_struct("", &self.child(*inner, self.value.clone())),
                    ContainerShape::TupleStruct(items) => {
                        self.tuple(serializer, items.iter().copied())
                    }
                    ContainerShape::Struct(_) => self.fields(container, serializer),
                    ContainerShape::Enum(_) => self.variant(container, serializer),
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Decoding

/// Reads a value of `format` into a Python object.
struct Dec<'a, 'py> {
    ctx: &'a Ctx<'a>,
    py: Python<'py>,
    format: u32,
    depth: usize,
}

impl<'a, 'py> Dec<'a, 'py> {
    fn child(&self, format: u32) -> Dec<'a, 'py> {
        Dec {
            ctx: self.ctx,
            py: self.py,
            format,
            depth: self.depth + 1,
        }
    }

    /// A visitor for this value (the same level: only children add one).
    fn visitor(&self, want: Want) -> Value<'a, 'py> {
        Value {
            dec: Dec {
                ctx: self.ctx,
                py: self.py,
                format: self.format,
                depth: self.depth,
            },
            want,
        }
    }
}

/// What a visitor builds from what postcard hands it.
#[derive(Clone, Copy)]
enum Want {
    /// A scalar, string, bytes, option or unit: as it comes.
    Plain,
    /// A list of `len` items (`None`: a sequence, its length from the payload) of formats
    /// given by [`Value::item_format`].
    List,
    /// A struct's fields (container index).
    Fields(usize),
    /// An enum's variant (container index).
    Variant(usize),
    /// A map.
    Map,
}

struct Value<'a, 'py> {
    dec: Dec<'a, 'py>,
    want: Want,
}

impl<'a, 'py> Value<'a, 'py> {
    fn ok<E: de::Error>(&self, value: Bound<'py, PyAny>) -> Result<Bound<'py, PyAny>, E> {
        self.dec.ctx.count()?;
        Ok(value)
    }

    fn py_ok<E: de::Error, T>(&self, value: PyResult<T>) -> Result<T, E> {
        value.map_err(|err| self.dec.ctx.py_error(err))
    }

    /// A Python int or float.
    fn number<E: de::Error, T: IntoPyObject<'py>>(&self, v: T) -> Result<Bound<'py, PyAny>, E> {
        let value = self.py_ok(pyo3::IntoPyObjectExt::into_bound_py_any(v, self.dec.py))?;
        self.ok(value)
    }

    /// The format of item `i` of the list being read.
    fn item_format(&self, i: usize) -> Option<u32> {
        let layout = &self.dec.ctx.codec.layout;
        match &layout.formats[self.dec.format as usize] {
            Format::Seq(item) => Some(*item),
            Format::Array { item, .. } => Some(*item),
            Format::Tuple(items) => items.get(i).copied(),
            Format::Named(c) => match &layout.containers[*c as usize].shape {
                ContainerShape::TupleStruct(items) => items.get(i).copied(),
                _ => None,
            },
            _ => None,
        }
    }

    fn read_list<'de, A: SeqAccess<'de>>(
        &self,
        mut seq: A,
    ) -> Result<Vec<Bound<'py, PyAny>>, A::Error> {
        let mut items = Vec::new();
        let mut i = 0usize;
        while let Some(format) = self.item_format(i) {
            self.dec.ctx.path.borrow_mut().push(Seg::Index(i));
            let item = seq.next_element_seed(self.dec.child(format))?;
            self.dec.ctx.path.borrow_mut().pop();
            match item {
                Some(item) => items.push(item),
                None => break,
            }
            i += 1;
        }
        Ok(items)
    }
}

impl<'de, 'py> DeserializeSeed<'de> for Dec<'_, 'py> {
    type Value = Bound<'py, PyAny>;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        if self.depth > MAX_DEPTH {
            return Err(self
                .ctx
                .fail(format!("values nest deeper than {MAX_DEPTH} levels")));
        }
        let layout = &self.ctx.codec.layout;
        let plain = self.visitor(Want::Plain);
        match &layout.formats[self.format as usize] {
            Format::Unit => d.deserialize_unit(plain),
            Format::Bool => d.deserialize_bool(plain),
            Format::I8 => d.deserialize_i8(plain),
            Format::I16 => d.deserialize_i16(plain),
            Format::I32 => d.deserialize_i32(plain),
            Format::I64 => d.deserialize_i64(plain),
            Format::I128 => d.deserialize_i128(plain),
            Format::U8 => d.deserialize_u8(plain),
            Format::U16 => d.deserialize_u16(plain),
            Format::U32 => d.deserialize_u32(plain),
            Format::U64 => d.deserialize_u64(plain),
            Format::U128 => d.deserialize_u128(plain),
            Format::F32 => d.deserialize_f32(plain),
            Format::F64 => d.deserialize_f64(plain),
            Format::Char => d.deserialize_char(plain),
            Format::Str => d.deserialize_str(plain),
            Format::Bytes => d.deserialize_bytes(plain),
            Format::Option(_) => d.deserialize_option(plain),
            Format::Seq(_) => d.deserialize_seq(self.visitor(Want::List)),
            Format::Map { .. } => d.deserialize_map(self.visitor(Want::Map)),
            Format::Tuple(items) => d.deserialize_tuple(items.len(), self.visitor(Want::List)),
            Format::Array { len, .. } => {
                d.deserialize_tuple(*len as usize, self.visitor(Want::List))
            }
            Format::Named(container) => {
                let c = *container as usize;
                match &layout.containers[c].shape {
                    ContainerShape::UnitStruct => d.deserialize_unit_struct("", plain),
                    ContainerShape::NewType(_) => d.deserialize_newtype_struct("", plain),
                    ContainerShape::TupleStruct(items) => {
                        d.deserialize_tuple(items.len(), self.visitor(Want::List))
                    }
                    ContainerShape::Struct(fields) => {
                        d.deserialize_tuple(fields.len(), self.visitor(Want::Fields(c)))
                    }
                    ContainerShape::Enum(_) => {
                        d.deserialize_enum("", &[], self.visitor(Want::Variant(c)))
                    }
                }
            }
        }
    }
}

impl<'de, 'py> Visitor<'de> for Value<'_, 'py> {
    type Value = Bound<'py, PyAny>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "a value of {}",
            format_name(&self.dec.ctx.codec.layout, self.dec.format)
        )
    }

    fn visit_bool<E: de::Error>(self, v: bool) -> Result<Self::Value, E> {
        let value = pyo3::types::PyBool::new(self.dec.py, v)
            .to_owned()
            .into_any();
        self.ok(value)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
        self.number(v)
    }

    fn visit_i128<E: de::Error>(self, v: i128) -> Result<Self::Value, E> {
        self.number(v)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
        self.number(v)
    }

    fn visit_u128<E: de::Error>(self, v: u128) -> Result<Self::Value, E> {
        self.number(v)
    }

    fn visit_f32<E: de::Error>(self, v: f32) -> Result<Self::Value, E> {
        // The shortest decimal that reads back as the same f32 (0.1, not 0.10000000149...).
        let shortest: f64 = v.to_string().parse().unwrap_or(f64::from(v));
        self.visit_f64(shortest)
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
        self.number(v)
    }

    fn visit_char<E: de::Error>(self, v: char) -> Result<Self::Value, E> {
        let mut buf = [0u8; 4];
        self.visit_str(v.encode_utf8(&mut buf))
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<Self::Value, E> {
        self.ok(PyString::new(self.dec.py, v).into_any())
    }

    fn visit_bytes<E: de::Error>(self, v: &[u8]) -> Result<Self::Value, E> {
        self.ok(PyBytes::new(self.dec.py, v).into_any())
    }

    fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
        self.ok(self.dec.py.None().into_bound(self.dec.py))
    }

    fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
        self.visit_none()
    }

    fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        let Format::Option(inner) = self.dec.ctx.codec.layout.formats[self.dec.format as usize]
        else {
            return Err(self.dec.ctx.fail("unexpected option"));
        };
        self.dec.child(inner).deserialize(d)
    }

    fn visit_newtype_struct<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        let layout = &self.dec.ctx.codec.layout;
        let Format::Named(c) = layout.formats[self.dec.format as usize] else {
            return Err(self.dec.ctx.fail("unexpected newtype"));
        };
        let ContainerShape::NewType(inner) = layout.containers[c as usize].shape else {
            return Err(self.dec.ctx.fail("unexpected newtype"));
        };
        self.dec.child(inner).deserialize(d)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
        let py = self.dec.py;
        match self.want {
            Want::Fields(c) => {
                let codec = self.dec.ctx.codec;
                let ContainerShape::Struct(fields) = &codec.layout.containers[c].shape else {
                    return Err(self.dec.ctx.fail("unexpected struct"));
                };
                let mut seq = seq;
                let mut values = Vec::with_capacity(fields.len());
                for field in fields {
                    self.dec
                        .ctx
                        .path
                        .borrow_mut()
                        .push(Seg::Name(field.name.clone()));
                    let value = seq
                        .next_element_seed(self.dec.child(field.format))?
                        .ok_or_else(|| self.dec.ctx.fail("the struct ends early"))?;
                    self.dec.ctx.path.borrow_mut().pop();
                    values.push(value);
                }
                let value = match &codec.shapes[c] {
                    PyShape::Class(class) => {
                        let args = self.py_ok(PyTuple::new(py, values))?;
                        self.py_ok(class.bind(py).call1(args))?
                    }
                    PyShape::KeywordClass(class) => {
                        let kwargs = PyDict::new(py);
                        for (name, value) in codec.names[c].iter().zip(values) {
                            self.py_ok(kwargs.set_item(name.bind(py), value))?;
                        }
                        self.py_ok(class.bind(py).call((), Some(&kwargs)))?
                    }
                    _ => {
                        let dict = PyDict::new(py);
                        for (name, value) in codec.names[c].iter().zip(values) {
                            self.py_ok(dict.set_item(name.bind(py), value))?;
                        }
                        dict.into_any()
                    }
                };
                self.ok(value)
            }
            _ => {
                let items = self.read_list(seq)?;
                let layout = &self.dec.ctx.codec.layout;
                // Tuples as tuples; sequences and arrays as lists.
                let tuple = match &layout.formats[self.dec.format as usize] {
                    Format::Tuple(_) => true,
                    Format::Named(c) => matches!(
                        layout.containers[*c as usize].shape,
                        ContainerShape::TupleStruct(_)
                    ),
                    _ => false,
                };
                let value = if tuple {
                    self.py_ok(PyTuple::new(py, items))?.into_any()
                } else {
                    self.py_ok(PyList::new(py, items))?.into_any()
                };
                self.ok(value)
            }
        }
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let py = self.dec.py;
        let Format::Map { key, value } =
            self.dec.ctx.codec.layout.formats[self.dec.format as usize]
        else {
            return Err(self.dec.ctx.fail("unexpected map"));
        };
        let dict = PyDict::new(py);
        let mut i = 0usize;
        loop {
            self.dec.ctx.path.borrow_mut().push(Seg::Index(i));
            let Some(k) = map.next_key_seed(self.dec.child(key))? else {
                self.dec.ctx.path.borrow_mut().pop();
                break;
            };
            let v = map.next_value_seed(self.dec.child(value))?;
            self.dec.ctx.path.borrow_mut().pop();
            // A sequence or array key (Rust `[i32; 2]`, `Vec<u8>`) as a tuple: a list cannot
            // be a dict key.
            let k = match k.cast::<PyList>() {
                Ok(list) => list.to_tuple().into_any(),
                Err(_) => k,
            };
            self.py_ok(dict.set_item(k, v))?;
            i += 1;
        }
        self.ok(dict.into_any())
    }

    fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<Self::Value, A::Error> {
        let Want::Variant(c) = self.want else {
            return Err(self.dec.ctx.fail("unexpected enum"));
        };
        let py = self.dec.py;
        let codec = self.dec.ctx.codec;
        let container = &codec.layout.containers[c];
        let ContainerShape::Enum(variants) = &container.shape else {
            return Err(self.dec.ctx.fail("unexpected enum"));
        };
        let (index, access): (u32, A::Variant) = data.variant()?;
        let Some(position) = variants.iter().position(|v| v.index == index) else {
            return Err(self
                .dec
                .ctx
                .fail(format!("{} has no variant {index}", container.name)));
        };
        let variant = &variants[position];
        let name = codec.names[c][position].bind(py).clone();
        let payload = match &variant.shape {
            VariantShape::Unit => {
                access.unit_variant()?;
                let value = match &codec.shapes[c] {
                    PyShape::Members(members) => members[position].bind(py).clone(),
                    _ => name.into_any(),
                };
                return self.ok(value);
            }
            VariantShape::NewType(format) => {
                access.newtype_variant_seed(self.dec.child(*format))?
            }
            VariantShape::Tuple(items) => access.tuple_variant(
                items.len(),
                TupleItems {
                    dec: self.dec.visitor(Want::List).dec,
                    items,
                },
            )?,
            VariantShape::Struct(fields) => access.tuple_variant(
                fields.len(),
                VariantFields {
                    dec: self.dec.visitor(Want::List).dec,
                    fields,
                },
            )?,
        };
        let dict = PyDict::new(py);
        self.py_ok(dict.set_item(name, payload))?;
        self.ok(dict.into_any())
    }
}

/// Reads a tuple variant's items into a list.
struct TupleItems<'a, 'py> {
    dec: Dec<'a, 'py>,
    items: &'a [u32],
}

impl<'de, 'py> Visitor<'de> for TupleItems<'_, 'py> {
    type Value = Bound<'py, PyAny>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a tuple of {} items", self.items.len())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut values = Vec::with_capacity(self.items.len());
        for format in self.items {
            let value = seq
                .next_element_seed(self.dec.child(*format))?
                .ok_or_else(|| self.dec.ctx.fail("the tuple ends early"))?;
            values.push(value);
        }
        PyList::new(self.dec.py, values)
            .map(Bound::into_any)
            .map_err(|err| self.dec.ctx.py_error(err))
    }
}

/// Reads a struct variant's fields into a dict.
struct VariantFields<'a, 'py> {
    dec: Dec<'a, 'py>,
    fields: &'a [ndds_core::types::Field],
}

impl<'de, 'py> Visitor<'de> for VariantFields<'_, 'py> {
    type Value = Bound<'py, PyAny>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a variant of {} fields", self.fields.len())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let dict = PyDict::new(self.dec.py);
        for field in self.fields {
            let value = seq
                .next_element_seed(self.dec.child(field.format))?
                .ok_or_else(|| self.dec.ctx.fail("the variant ends early"))?;
            dict.set_item(&field.name, value)
                .map_err(|err| self.dec.ctx.py_error::<A::Error>(err))?;
        }
        Ok(dict.into_any())
    }
}

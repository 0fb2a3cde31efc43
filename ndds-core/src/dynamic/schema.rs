//! A JSON Schema (draft-07) of the JSON [`decode_json`](super::decode_json) makes of a
//! layout's samples: what recordings carry beside each JSON channel, so Foxglove, Lichtblick
//! and Python's `jsonschema` know the fields without ndds.
//!
//! Everything is written inline (a validated layout expands to at most
//! [`MAX_EXPANDED_FORMATS`](crate::types::MAX_EXPANDED_FORMATS) nodes, and some viewers do not
//! follow references), except a container inside itself (a tree): that one is a
//! `{"$ref": "#/definitions/NAME"}` to its definition.

use serde_json::{Value, json};

use super::DynamicError;
use crate::types::{ContainerShape, Field, Format, TypeLayout, VariantShape};

/// Deepest nesting followed (a validated layout nests less; this guards a broken one).
const MAX_SCHEMA_DEPTH: usize = 256;

/// The JSON Schema of the JSON [`decode_json`](super::decode_json) produces for `layout`'s
/// samples, with the type's name as its title.
pub fn json_schema(layout: &TypeLayout, title: &str) -> Result<Value, DynamicError> {
    let mut schemas = Schemas {
        layout,
        stack: Vec::new(),
        recursive: std::collections::BTreeSet::new(),
    };
    let mut schema = schemas.node(layout.root, 0)?;
    // Each container met inside itself, defined once (its definition may find others).
    let mut definitions = serde_json::Map::new();
    while let Some(index) = schemas
        .recursive
        .iter()
        .copied()
        .find(|i| !definitions.contains_key(&definition_name(layout, *i)))
    {
        schemas.stack = vec![index];
        let body = schemas.container(index, 0)?;
        definitions.insert(definition_name(layout, index), body);
    }
    if let Value::Object(map) = &mut schema {
        map.insert(
            "$schema".into(),
            json!("http://json-schema.org/draft-07/schema#"),
        );
        map.entry("title").or_insert_with(|| json!(title));
        if !definitions.is_empty() {
            map.insert("definitions".into(), Value::Object(definitions));
        }
    }
    Ok(schema)
}

/// The name of a recursive container's definition (names are unique in a layout; the index
/// keeps it so if one is not).
fn definition_name(layout: &TypeLayout, index: u32) -> String {
    let name = layout.container(index).map_or("", |c| c.name.as_str());
    let name: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    format!("{name}_{index}")
}

struct Schemas<'a> {
    layout: &'a TypeLayout,
    /// Containers being expanded, outermost first.
    stack: Vec<u32>,
    /// Containers met inside themselves.
    recursive: std::collections::BTreeSet<u32>,
}

fn missing(what: &'static str, index: u32) -> DynamicError {
    DynamicError::BadLayout {
        path: "/".into(),
        what,
        index,
    }
}

fn integer(min: i128, max: u128) -> Value {
    json!({"type": "integer", "minimum": min as f64, "maximum": max as f64})
}

fn float() -> Value {
    // Non-finite values are written as these strings (see the module docs of `dynamic`).
    json!({"anyOf": [{"type": "number"}, {"enum": ["NaN", "inf", "-inf"]}]})
}

impl Schemas<'_> {
    fn node(&mut self, index: u32, depth: usize) -> Result<Value, DynamicError> {
        if depth > MAX_SCHEMA_DEPTH {
            return Err(DynamicError::TooDeep {
                path: "/".into(),
                limit: MAX_SCHEMA_DEPTH,
            });
        }
        let layout = self.layout;
        let format = layout
            .format(index)
            .ok_or_else(|| missing("format", index))?;
        let next = depth + 1;
        Ok(match format {
            Format::Unit => json!({"type": "null"}),
            Format::Bool => json!({"type": "boolean"}),
            Format::I8 => integer(i8::MIN.into(), i8::MAX as u128),
            Format::I16 => integer(i16::MIN.into(), i16::MAX as u128),
            Format::I32 => integer(i32::MIN.into(), i32::MAX as u128),
            Format::I64 => integer(i64::MIN.into(), i64::MAX as u128),
            Format::U8 => integer(0, u8::MAX.into()),
            Format::U16 => integer(0, u16::MAX.into()),
            Format::U32 => integer(0, u32::MAX.into()),
            Format::U64 => integer(0, u64::MAX.into()),
            // A number when it fits in 64 bits, else its decimal string.
            Format::I128 | Format::U128 => json!({"anyOf": [
                {"type": "integer"},
                {"type": "string", "pattern": "^-?[0-9]+$"}
            ]}),
            Format::F32 | Format::F64 => float(),
            Format::Char => json!({"type": "string", "minLength": 1, "maxLength": 1}),
            Format::Str => json!({"type": "string"}),
            Format::Bytes => json!({
                "type": "array",
                "items": {"type": "integer", "minimum": 0, "maximum": 255}
            }),
            Format::Option(inner) => json!({"anyOf": [{"type": "null"}, self.node(*inner, next)?]}),
            Format::Seq(item) => json!({"type": "array", "items": self.node(*item, next)?}),
            Format::Map { key, value } => match layout.format(*key) {
                Some(Format::Str) => {
                    json!({"type": "object", "additionalProperties": self.node(*value, next)?})
                }
                _ => {
                    let pair = [self.node(*key, next)?, self.node(*value, next)?];
                    json!({
                        "type": "array",
                        "items": {"type": "array", "items": pair, "minItems": 2, "maxItems": 2}
                    })
                }
            },
            Format::Tuple(items) => self.tuple(items, next)?,
            Format::Array { item, len } => json!({
                "type": "array",
                "items": self.node(*item, next)?,
                "minItems": len,
                "maxItems": len
            }),
            Format::Named(index) => {
                if self.stack.contains(index) {
                    self.recursive.insert(*index);
                    json!({"$ref": format!("#/definitions/{}", definition_name(layout, *index))})
                } else {
                    self.stack.push(*index);
                    let schema = self.container(*index, next);
                    self.stack.pop();
                    schema?
                }
            }
        })
    }

    /// A named container's schema.
    fn container(&mut self, index: u32, depth: usize) -> Result<Value, DynamicError> {
        let container = self
            .layout
            .container(index)
            .ok_or_else(|| missing("container", index))?;
        let mut schema = match &container.shape {
            ContainerShape::UnitStruct => json!({"type": "null"}),
            ContainerShape::NewType(inner) => self.node(*inner, depth)?,
            ContainerShape::TupleStruct(items) => self.tuple(items, depth)?,
            ContainerShape::Struct(fields) => self.object(fields, depth)?,
            ContainerShape::Enum(variants) => {
                let mut any = Vec::new();
                for variant in variants {
                    let value = match &variant.shape {
                        VariantShape::Unit => {
                            any.push(json!({"const": variant.name}));
                            continue;
                        }
                        VariantShape::NewType(inner) => self.node(*inner, depth)?,
                        VariantShape::Tuple(items) => self.tuple(items, depth)?,
                        VariantShape::Struct(fields) => self.object(fields, depth)?,
                    };
                    any.push(json!({
                        "type": "object",
                        "properties": {variant.name.clone(): value},
                        "required": [variant.name],
                        "additionalProperties": false,
                    }));
                }
                json!({"anyOf": any})
            }
        };
        if let Value::Object(map) = &mut schema {
            map.entry("title").or_insert_with(|| json!(container.name));
        }
        Ok(schema)
    }

    fn tuple(&mut self, items: &[u32], depth: usize) -> Result<Value, DynamicError> {
        let items = items
            .iter()
            .map(|i| self.node(*i, depth))
            .collect::<Result<Vec<_>, _>>()?;
        let len = items.len();
        Ok(json!({"type": "array", "items": items, "minItems": len, "maxItems": len}))
    }

    fn object(&mut self, fields: &[Field], depth: usize) -> Result<Value, DynamicError> {
        let mut properties = serde_json::Map::new();
        for field in fields {
            properties.insert(field.name.clone(), self.node(field.format, depth)?);
        }
        let required: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
        Ok(json!({
            "type": "object",
            "properties": properties,
            "required": required,
            "additionalProperties": false,
        }))
    }
}

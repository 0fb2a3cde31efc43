//! The canonical text of a type layout and the fingerprint derived from it.
//!
//! The canonical text is independent of how the layout's arena happens to be numbered, so two
//! implementations that build the arena differently still agree on the fingerprint. Grammar
//! (names are JSON string literals; no whitespace anywhere):
//!
//! ```text
//! description := "root=" format ";" { container ";" }      containers in byte order of name
//! format      := "unit" | "bool" | "i8" | "i16" | "i32" | "i64" | "i128"
//!              | "u8" | "u16" | "u32" | "u64" | "u128" | "f32" | "f64" | "char" | "str" | "bytes"
//!              | "option<" format ">" | "seq<" format ">" | "map<" format "," format ">"
//!              | "tuple<" [ format { "," format } ] ">" | "array<" format ";" len ">"
//!              | name
//! container   := name "=" ( "unit_struct" | "newtype(" format ")"
//!              | "tuple_struct(" formats ")" | "struct{" fields "}" | "enum{" variants "}" )
//! fields      := [ name ":" format { "," name ":" format } ]
//! variants    := [ variant { "," variant } ]
//! variant     := index ":" name ":" ( "unit" | "newtype(" format ")" | "tuple(" formats ")"
//!              | "struct{" fields "}" )
//! ```
//!
//! The fingerprint is the first eight bytes of the SHA-256 digest of the canonical text, read as
//! a big-endian `u64`. A type without a layout (see [`super::TypeDescription`]) has the canonical
//! text `opaque=` followed by its name as a JSON string.

use std::fmt::Write as _;

use sha2::{Digest, Sha256};

use super::layout::{ContainerShape, Field, Format, TypeLayout, VariantShape};

/// The canonical text of a validated layout.
pub fn canonical_text(layout: &TypeLayout) -> String {
    let mut out = String::new();
    out.push_str("root=");
    write_format(layout, layout.root, &mut out);
    out.push(';');
    for container in &layout.containers {
        write_name(&container.name, &mut out);
        out.push('=');
        match &container.shape {
            ContainerShape::UnitStruct => out.push_str("unit_struct"),
            ContainerShape::NewType(f) => {
                out.push_str("newtype(");
                write_format(layout, *f, &mut out);
                out.push(')');
            }
            ContainerShape::TupleStruct(items) => {
                out.push_str("tuple_struct(");
                write_list(layout, items, &mut out);
                out.push(')');
            }
            ContainerShape::Struct(fields) => write_fields(layout, fields, &mut out),
            ContainerShape::Enum(variants) => {
                out.push_str("enum{");
                for (i, variant) in variants.iter().enumerate() {
                    if i > 0 {
                        out.push(',');
                    }
                    let _ = write!(out, "{}:", variant.index);
                    write_name(&variant.name, &mut out);
                    out.push(':');
                    match &variant.shape {
                        VariantShape::Unit => out.push_str("unit"),
                        VariantShape::NewType(f) => {
                            out.push_str("newtype(");
                            write_format(layout, *f, &mut out);
                            out.push(')');
                        }
                        VariantShape::Tuple(items) => {
                            out.push_str("tuple(");
                            write_list(layout, items, &mut out);
                            out.push(')');
                        }
                        VariantShape::Struct(fields) => write_fields(layout, fields, &mut out),
                    }
                }
                out.push('}');
            }
        }
        out.push(';');
    }
    out
}

/// The canonical text of a type known only by name.
pub fn opaque_text(name: &str) -> String {
    let mut out = String::from("opaque=");
    write_name(name, &mut out);
    out
}

/// First eight bytes of SHA-256 of `text`, big-endian.
pub fn fingerprint_of_text(text: &str) -> u64 {
    let digest = Sha256::digest(text.as_bytes());
    let mut first = [0u8; 8];
    first.copy_from_slice(&digest[..8]);
    u64::from_be_bytes(first)
}

fn write_name(name: &str, out: &mut String) {
    // serde_json's string escaping is the documented escaping of names.
    match serde_json::to_string(name) {
        Ok(quoted) => out.push_str(&quoted),
        Err(_) => out.push_str("\"\""),
    }
}

fn write_fields(layout: &TypeLayout, fields: &[Field], out: &mut String) {
    out.push_str("struct{");
    for (i, field) in fields.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        write_name(&field.name, out);
        out.push(':');
        write_format(layout, field.format, out);
    }
    out.push('}');
}

fn write_list(layout: &TypeLayout, items: &[u32], out: &mut String) {
    for (i, item) in items.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        write_format(layout, *item, out);
    }
}

/// Recursion here follows format children only, and only children that precede their parent
/// (as `validate` requires), so even an unvalidated layout cannot recurse forever; containers
/// are written by name, so recursive types terminate.
fn write_format(layout: &TypeLayout, index: u32, out: &mut String) {
    let Some(format) = layout.format(index) else {
        out.push('?');
        return;
    };
    if format.children().any(|child| child >= index) {
        out.push('?');
        return;
    }
    let simple = match format {
        Format::Unit => "unit",
        Format::Bool => "bool",
        Format::I8 => "i8",
        Format::I16 => "i16",
        Format::I32 => "i32",
        Format::I64 => "i64",
        Format::I128 => "i128",
        Format::U8 => "u8",
        Format::U16 => "u16",
        Format::U32 => "u32",
        Format::U64 => "u64",
        Format::U128 => "u128",
        Format::F32 => "f32",
        Format::F64 => "f64",
        Format::Char => "char",
        Format::Str => "str",
        Format::Bytes => "bytes",
        _ => "",
    };
    if !simple.is_empty() {
        out.push_str(simple);
        return;
    }
    match format {
        Format::Option(inner) => wrap("option", &[*inner], layout, out),
        Format::Seq(inner) => wrap("seq", &[*inner], layout, out),
        Format::Map { key, value } => wrap("map", &[*key, *value], layout, out),
        Format::Tuple(items) => wrap("tuple", items, layout, out),
        Format::Array { item, len } => {
            out.push_str("array<");
            write_format(layout, *item, out);
            let _ = write!(out, ";{len}>");
        }
        Format::Named(c) => match layout.container(*c) {
            Some(container) => write_name(&container.name, out),
            None => out.push('?'),
        },
        _ => {}
    }
}

fn wrap(keyword: &str, items: &[u32], layout: &TypeLayout, out: &mut String) {
    out.push_str(keyword);
    out.push('<');
    write_list(layout, items, out);
    out.push('>');
}

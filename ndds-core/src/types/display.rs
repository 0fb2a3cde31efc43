//! How types are shown to people when two of them differ: a one-line shape
//! (`Pose{x: f64, y: f64}`) that says why.
//!
//! Names are not shortened here: [`TypeDescription::name`] is already free of module paths
//! where the description is made ([`super::name`]), so every tool and message shows the same
//! name. Display only: what matches is the fingerprint ([`super::canonical`]), which these
//! functions never touch.

use std::fmt::Write as _;

use super::TypeDescription;
use super::layout::{ContainerShape, Field, Format, TypeLayout, VariantShape};

/// Longest shape text, in bytes, before it is cut with `…`.
const MAX_SHAPE: usize = 240;
/// Most fields, items or variants listed in one container before `…`.
const MAX_LISTED: usize = 12;

impl TypeDescription {
    /// The name messages show: [`name`](TypeDescription::name) itself, which has no module
    /// path to shorten (see [`super::name`]); an explicit name such as `ndds::CsMat` is shown
    /// whole. Prefer `name`: this remains for callers written when names were shortened here.
    pub fn short_name(&self) -> String {
        self.name.clone()
    }

    /// The type's shape on one line, as messages show it when two types differ: the root
    /// container under the description's [`name`](TypeDescription::name), with its fields
    /// (`Pose{x: f64, y: f64}`, `ndds::CsMat{name: String, ..}`), a primitive or standard
    /// type (`f64`, `Vec<String>`), or the name of an opaque type. Nested containers are
    /// shown by their serde names; long shapes are cut with `…`.
    pub fn shape(&self) -> String {
        let Some(layout) = &self.layout else {
            return self.name.clone();
        };
        let mut out = String::new();
        match layout.format(layout.root) {
            Some(Format::Named(index)) => write_container(layout, *index, &self.name, &mut out),
            _ => write_format(layout, layout.root, &mut out),
        }
        if out.len() > MAX_SHAPE {
            let mut cut = MAX_SHAPE;
            while !out.is_char_boundary(cut) {
                cut -= 1;
            }
            out.truncate(cut);
            out.push('…');
        }
        out
    }
}

/// Writes the root container, labelled `name`, with its content.
fn write_container(layout: &TypeLayout, index: u32, name: &str, out: &mut String) {
    let Some(container) = layout.container(index) else {
        out.push('?');
        return;
    };
    out.push_str(name);
    match &container.shape {
        ContainerShape::UnitStruct => {}
        ContainerShape::NewType(item) => write_items(layout, std::slice::from_ref(item), out),
        ContainerShape::TupleStruct(items) => write_items(layout, items, out),
        ContainerShape::Struct(fields) => write_fields(layout, fields, out),
        ContainerShape::Enum(variants) => {
            out.push('{');
            for (i, variant) in variants.iter().enumerate() {
                if !separate(i, " | ", out) {
                    break;
                }
                out.push_str(&variant.name);
                match &variant.shape {
                    VariantShape::Unit => {}
                    VariantShape::NewType(item) => {
                        write_items(layout, std::slice::from_ref(item), out);
                    }
                    VariantShape::Tuple(items) => write_items(layout, items, out),
                    VariantShape::Struct(fields) => write_fields(layout, fields, out),
                }
            }
            out.push('}');
        }
    }
}

/// Writes the separator before item `i`; false (after writing `…`) once enough were listed
/// or the text is already too long to be shown whole.
fn separate(i: usize, separator: &str, out: &mut String) -> bool {
    if i > 0 {
        out.push_str(separator);
    }
    if i >= MAX_LISTED || out.len() > MAX_SHAPE {
        out.push('…');
        return false;
    }
    true
}

fn write_fields(layout: &TypeLayout, fields: &[Field], out: &mut String) {
    out.push('{');
    for (i, field) in fields.iter().enumerate() {
        if !separate(i, ", ", out) {
            break;
        }
        let _ = write!(out, "{}: ", field.name);
        write_format(layout, field.format, out);
    }
    out.push('}');
}

fn write_items(layout: &TypeLayout, items: &[u32], out: &mut String) {
    out.push('(');
    write_list(layout, items, out);
    out.push(')');
}

fn write_list(layout: &TypeLayout, items: &[u32], out: &mut String) {
    for (i, item) in items.iter().enumerate() {
        if !separate(i, ", ", out) {
            break;
        }
        write_format(layout, *item, out);
    }
}

/// Writes a format the way Rust spells it. Recursion follows format children only, which a
/// validated layout bounds by its maximum depth.
fn write_format(layout: &TypeLayout, index: u32, out: &mut String) {
    let Some(format) = layout.format(index) else {
        out.push('?');
        return;
    };
    let name = match format {
        Format::Unit => "()",
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
        Format::Str => "String",
        Format::Bytes => "bytes",
        Format::Option(inner) => return wrap(layout, "Option<", &[*inner], ">", out),
        Format::Seq(inner) => return wrap(layout, "Vec<", &[*inner], ">", out),
        Format::Map { key, value } => return wrap(layout, "Map<", &[*key, *value], ">", out),
        Format::Tuple(items) => return wrap(layout, "(", items, ")", out),
        Format::Array { item, len } => {
            out.push('[');
            write_format(layout, *item, out);
            let _ = write!(out, "; {len}]");
            return;
        }
        Format::Named(container) => match layout.container(*container) {
            Some(container) => &container.name,
            None => "?",
        },
    };
    out.push_str(name);
}

fn wrap(layout: &TypeLayout, open: &str, items: &[u32], close: &str, out: &mut String) {
    out.push_str(open);
    write_list(layout, items, out);
    out.push_str(close);
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use serde::{Deserialize, Serialize};

    use super::*;

    #[derive(Serialize, Deserialize)]
    struct Pose {
        x: f64,
        y: f64,
        label: Option<String>,
    }

    #[derive(Serialize, Deserialize)]
    enum Mode {
        Idle,
        Move { speed: f32 },
        Hold(u8, u8),
    }

    #[derive(Serialize, Deserialize)]
    struct Scene {
        poses: Vec<Pose>,
        table: BTreeMap<String, [u16; 3]>,
        pair: (i32, bool),
    }

    #[test]
    fn names_are_shown_as_made() {
        let desc = TypeDescription::try_of::<Vec<String>>().unwrap();
        assert_eq!(desc.short_name(), "Vec<String>");
        assert_eq!(desc.shape(), "Vec<String>");
        let named = desc.with_name("ndds::Strings");
        assert_eq!(
            named.short_name(),
            "ndds::Strings",
            "an explicit name is not cut"
        );
        let pose = TypeDescription::named::<Pose>("demo::Pose");
        assert_eq!(
            pose.shape(),
            "demo::Pose{x: f64, y: f64, label: Option<String>}",
            "the root under the description's name"
        );
    }

    #[test]
    fn shapes_show_the_root_container_and_standard_types() {
        let pose = TypeDescription::try_of::<Pose>().unwrap();
        assert_eq!(pose.shape(), "Pose{x: f64, y: f64, label: Option<String>}");
        let mode = TypeDescription::try_of::<Mode>().unwrap();
        assert_eq!(mode.shape(), "Mode{Idle | Move{speed: f32} | Hold(u8, u8)}");
        let scene = TypeDescription::try_of::<Scene>().unwrap();
        assert_eq!(
            scene.shape(),
            "Scene{poses: Vec<Pose>, table: Map<String, [u16; 3]>, pair: (i32, bool)}"
        );
        assert_eq!(TypeDescription::try_of::<f32>().unwrap().shape(), "f32");
        assert_eq!(
            TypeDescription::opaque("ndds::Blob").shape(),
            "ndds::Blob",
            "an opaque type by its name"
        );
    }

    #[test]
    fn long_shapes_are_cut() {
        #[derive(Serialize, Deserialize)]
        struct Wide {
            a_rather_long_field_name_0: f64,
            a_rather_long_field_name_1: f64,
            a_rather_long_field_name_2: f64,
            a_rather_long_field_name_3: f64,
            a_rather_long_field_name_4: f64,
            a_rather_long_field_name_5: f64,
            a_rather_long_field_name_6: f64,
            a_rather_long_field_name_7: f64,
            a_rather_long_field_name_8: f64,
        }
        let shape = TypeDescription::try_of::<Wide>().unwrap().shape();
        assert!(shape.chars().count() <= MAX_SHAPE + 1, "{shape}");
        assert!(shape.ends_with('…'), "{shape}");
    }
}

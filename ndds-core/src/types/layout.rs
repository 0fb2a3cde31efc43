//! The structural layout of a sample type, as it travels in discovery.
//!
//! A layout is a flat arena: `formats` holds format nodes whose children are referred to by
//! index, and every child index is smaller than its parent's index, so decoding a layout never
//! recurses and a layout cannot contain a cycle. Named containers (structs and enums) live in
//! `containers`, sorted by name; a format refers to one with [`Format::Named`]. A recursive type
//! (a tree) is expressed by a container whose fields name the container itself.

use serde::{Deserialize, Serialize};

use crate::wire::bounded;

/// Deepest nesting of formats accepted (`option<seq<tuple<..>>>` counts three).
pub const MAX_FORMAT_DEPTH: usize = 32;
/// Most format nodes accepted in one layout.
pub const MAX_FORMATS: usize = 4096;
/// Largest fixed-size array length accepted.
pub const MAX_ARRAY_LEN: u32 = 1 << 16;
/// Most format nodes the layout may stand for once shared children are written out (the
/// size of its canonical text is proportional to this). Sharing children lets a short
/// layout describe an exponentially large type; this bound keeps every walk linear.
pub const MAX_EXPANDED_FORMATS: u64 = 1 << 16;

/// A validated-on-receipt type layout. See the module docs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TypeLayout {
    /// Format nodes; children precede parents.
    #[serde(deserialize_with = "bounded::vec")]
    pub formats: Vec<Format>,
    /// Index in `formats` of the sample type itself.
    pub root: u32,
    /// Named containers, sorted by name, names unique.
    #[serde(deserialize_with = "bounded::vec")]
    pub containers: Vec<Container>,
}

/// One format node. `u32` fields are indices into [`TypeLayout::formats`], except in
/// [`Format::Named`], which indexes [`TypeLayout::containers`].
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Format {
    /// `()`
    Unit,
    /// `bool`
    Bool,
    /// `i8`
    I8,
    /// `i16`
    I16,
    /// `i32`
    I32,
    /// `i64`
    I64,
    /// `i128`
    I128,
    /// `u8`
    U8,
    /// `u16`
    U16,
    /// `u32`
    U32,
    /// `u64`
    U64,
    /// `u128`
    U128,
    /// `f32`
    F32,
    /// `f64`
    F64,
    /// `char`
    Char,
    /// A string.
    Str,
    /// A byte string (`serde_bytes`).
    Bytes,
    /// `Option<T>`
    Option(u32),
    /// A variable-length sequence.
    Seq(u32),
    /// A map.
    Map {
        /// Key format.
        key: u32,
        /// Value format.
        value: u32,
    },
    /// A tuple.
    Tuple(#[serde(deserialize_with = "bounded::vec")] Vec<u32>),
    /// A fixed-size array `[T; len]`.
    Array {
        /// Element format.
        item: u32,
        /// Number of elements.
        len: u32,
    },
    /// A named container (struct or enum).
    Named(u32),
}

/// A named struct or enum.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Container {
    /// The serde name of the container (usually the Rust type's name without its path).
    pub name: String,
    /// Its shape.
    pub shape: ContainerShape,
}

/// The shape of a named container.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ContainerShape {
    /// `struct S;`
    UnitStruct,
    /// `struct S(T);`
    NewType(u32),
    /// `struct S(T, U);`
    TupleStruct(#[serde(deserialize_with = "bounded::vec")] Vec<u32>),
    /// `struct S { a: T }`
    Struct(#[serde(deserialize_with = "bounded::vec")] Vec<Field>),
    /// `enum E { .. }`, variants sorted by index.
    Enum(#[serde(deserialize_with = "bounded::vec")] Vec<Variant>),
}

/// A named field.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Field {
    /// Field name.
    pub name: String,
    /// Index of its format.
    pub format: u32,
}

/// An enum variant.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Variant {
    /// The variant index serde uses on the wire.
    pub index: u32,
    /// Variant name.
    pub name: String,
    /// Its shape.
    pub shape: VariantShape,
}

/// The shape of an enum variant.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum VariantShape {
    /// `V`
    Unit,
    /// `V(T)`
    NewType(u32),
    /// `V(T, U)`
    Tuple(#[serde(deserialize_with = "bounded::vec")] Vec<u32>),
    /// `V { a: T }`
    Struct(#[serde(deserialize_with = "bounded::vec")] Vec<Field>),
}

/// Why a layout was rejected.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LayoutError {
    /// More than [`MAX_FORMATS`] nodes.
    #[error("layout has {0} format nodes (limit {MAX_FORMATS})")]
    TooManyFormats(usize),
    /// A node refers to itself, a later node, or past the end.
    #[error("format node {node} refers to node {child}, which does not precede it")]
    BadChild {
        /// The referring node.
        node: usize,
        /// The index it refers to.
        child: u32,
    },
    /// A `Named` node or container refers past the container list.
    #[error("container index {0} out of range")]
    BadContainer(u32),
    /// The root index is out of range.
    #[error("root index {0} out of range")]
    BadRoot(u32),
    /// Nesting deeper than [`MAX_FORMAT_DEPTH`].
    #[error("formats nest deeper than {MAX_FORMAT_DEPTH}")]
    TooDeep,
    /// An array longer than [`MAX_ARRAY_LEN`].
    #[error("array of {0} elements (limit {MAX_ARRAY_LEN})")]
    ArrayTooLong(u32),
    /// Container names are not strictly increasing.
    #[error("containers are not sorted by unique name near {0:?}")]
    UnsortedContainers(String),
    /// Enum variant indices are not strictly increasing.
    #[error("enum {0:?} has variants out of order or repeated")]
    UnsortedVariants(String),
    /// Two fields of one struct, or two variants of one enum, share a name.
    #[error("{container:?} has two fields or variants named {name:?}")]
    DuplicateName {
        /// The struct or enum.
        container: String,
        /// The repeated name.
        name: String,
    },
    /// The layout expands to more than [`MAX_EXPANDED_FORMATS`] formats.
    #[error("layout expands to {0} formats (limit {MAX_EXPANDED_FORMATS})")]
    TooLarge(u64),
}

/// The first name that repeats an earlier one.
fn duplicate<'a>(mut names: impl Iterator<Item = &'a str>) -> Option<&'a str> {
    let mut seen = std::collections::HashSet::new();
    names.find(|name| !seen.insert(*name))
}

impl Format {
    /// Indices of the format nodes this node refers to directly.
    pub fn children(&self) -> impl Iterator<Item = u32> + '_ {
        let (first, second, rest): (Option<u32>, Option<u32>, &[u32]) = match self {
            Format::Option(c) | Format::Seq(c) => (Some(*c), None, &[]),
            Format::Map { key, value } => (Some(*key), Some(*value), &[]),
            Format::Tuple(items) => (None, None, items),
            Format::Array { item, .. } => (Some(*item), None, &[]),
            _ => (None, None, &[]),
        };
        first.into_iter().chain(second).chain(rest.iter().copied())
    }
}

impl TypeLayout {
    /// Checks every rule in the module docs. A layout that passes can be walked without
    /// bounds errors and without unbounded recursion through formats.
    pub fn validate(&self) -> Result<(), LayoutError> {
        if self.formats.len() > MAX_FORMATS {
            return Err(LayoutError::TooManyFormats(self.formats.len()));
        }
        let mut depth = vec![0usize; self.formats.len()];
        let mut expanded = vec![0u64; self.formats.len()];
        for (node, format) in self.formats.iter().enumerate() {
            let mut deepest = 0;
            let mut size = 1u64;
            let mut check = |child: u32| -> Result<(), LayoutError> {
                let child_index = child as usize;
                if child_index >= node {
                    return Err(LayoutError::BadChild { node, child });
                }
                deepest = deepest.max(depth[child_index]);
                size = size.saturating_add(expanded[child_index]);
                Ok(())
            };
            match format {
                Format::Named(c) if *c as usize >= self.containers.len() => {
                    return Err(LayoutError::BadContainer(*c));
                }
                Format::Array { len, .. } if *len > MAX_ARRAY_LEN => {
                    return Err(LayoutError::ArrayTooLong(*len));
                }
                other => other.children().try_for_each(&mut check)?,
            }
            depth[node] = deepest + 1;
            if depth[node] > MAX_FORMAT_DEPTH {
                return Err(LayoutError::TooDeep);
            }
            if size > MAX_EXPANDED_FORMATS {
                return Err(LayoutError::TooLarge(size));
            }
            expanded[node] = size;
        }
        if self.root as usize >= self.formats.len() {
            return Err(LayoutError::BadRoot(self.root));
        }
        self.validate_containers()?;
        let total = self
            .container_refs()
            .fold(expanded[self.root as usize], |total, index| {
                total.saturating_add(expanded[index as usize])
            });
        if total > MAX_EXPANDED_FORMATS {
            return Err(LayoutError::TooLarge(total));
        }
        Ok(())
    }

    /// Every format index the containers refer to (after `validate_containers`).
    fn container_refs(&self) -> impl Iterator<Item = u32> + '_ {
        self.containers.iter().flat_map(|container| {
            let refs: Vec<u32> = match &container.shape {
                ContainerShape::UnitStruct => Vec::new(),
                ContainerShape::NewType(f) => vec![*f],
                ContainerShape::TupleStruct(items) => items.clone(),
                ContainerShape::Struct(fields) => fields.iter().map(|f| f.format).collect(),
                ContainerShape::Enum(variants) => variants
                    .iter()
                    .flat_map(|v| match &v.shape {
                        VariantShape::Unit => Vec::new(),
                        VariantShape::NewType(f) => vec![*f],
                        VariantShape::Tuple(items) => items.clone(),
                        VariantShape::Struct(fields) => fields.iter().map(|f| f.format).collect(),
                    })
                    .collect(),
            };
            refs
        })
    }

    fn validate_containers(&self) -> Result<(), LayoutError> {
        let in_range = |index: &u32| -> Result<(), LayoutError> {
            if (*index as usize) < self.formats.len() {
                Ok(())
            } else {
                Err(LayoutError::BadChild {
                    node: self.formats.len(),
                    child: *index,
                })
            }
        };
        for (i, container) in self.containers.iter().enumerate() {
            // Field and variant names are keys of the JSON tools show: two alike would lose one.
            let unique = |duplicate: Option<&str>| match duplicate {
                Some(name) => Err(LayoutError::DuplicateName {
                    container: container.name.clone(),
                    name: name.to_owned(),
                }),
                None => Ok(()),
            };
            let fields_ok = |fields: &[Field]| {
                unique(duplicate(fields.iter().map(|f| f.name.as_str())))?;
                fields.iter().try_for_each(|f| in_range(&f.format))
            };
            if i > 0 && self.containers[i - 1].name >= container.name {
                return Err(LayoutError::UnsortedContainers(container.name.clone()));
            }
            match &container.shape {
                ContainerShape::UnitStruct => {}
                ContainerShape::NewType(f) => in_range(f)?,
                ContainerShape::TupleStruct(items) => items.iter().try_for_each(in_range)?,
                ContainerShape::Struct(fields) => fields_ok(fields)?,
                ContainerShape::Enum(variants) => {
                    unique(duplicate(variants.iter().map(|v| v.name.as_str())))?;
                    for (j, variant) in variants.iter().enumerate() {
                        if j > 0 && variants[j - 1].index >= variant.index {
                            return Err(LayoutError::UnsortedVariants(container.name.clone()));
                        }
                        match &variant.shape {
                            VariantShape::Unit => {}
                            VariantShape::NewType(f) => in_range(f)?,
                            VariantShape::Tuple(items) => items.iter().try_for_each(in_range)?,
                            VariantShape::Struct(fields) => fields_ok(fields)?,
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// The container a `Named` index refers to. Valid after [`TypeLayout::validate`].
    pub fn container(&self, index: u32) -> Option<&Container> {
        self.containers.get(index as usize)
    }

    /// The format node at `index`. Valid after [`TypeLayout::validate`].
    pub fn format(&self, index: u32) -> Option<&Format> {
        self.formats.get(index as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(formats: Vec<Format>, root: u32) -> TypeLayout {
        TypeLayout {
            formats,
            root,
            containers: vec![],
        }
    }

    /// Found by the `dynamic_json` fuzz target: two fields named alike decode to JSON with one
    /// key, which cannot encode back (`fuzz/corpus/dynamic_json/duplicate_field_names`).
    #[test]
    fn repeated_field_or_variant_names_are_rejected() {
        let field = |name: &str| Field {
            name: name.into(),
            format: 0,
        };
        let with = |shape| TypeLayout {
            formats: vec![Format::F64, Format::Named(0)],
            root: 1,
            containers: vec![Container {
                name: "Pose".into(),
                shape,
            }],
        };
        let twice = with(ContainerShape::Struct(vec![
            field("x"),
            field("y"),
            field("x"),
        ]));
        assert!(matches!(
            twice.validate(),
            Err(LayoutError::DuplicateName { ref name, .. }) if name == "x"
        ));
        with(ContainerShape::Struct(vec![field("x"), field("y")]))
            .validate()
            .unwrap();
        let variant = |index, name: &str| Variant {
            index,
            name: name.into(),
            shape: VariantShape::Unit,
        };
        let variants = with(ContainerShape::Enum(vec![variant(0, "A"), variant(1, "A")]));
        assert!(matches!(
            variants.validate(),
            Err(LayoutError::DuplicateName { .. })
        ));
    }

    #[test]
    fn forward_and_self_references_are_rejected() {
        assert!(matches!(
            layout(vec![Format::Option(0)], 0).validate(),
            Err(LayoutError::BadChild { .. })
        ));
        assert!(matches!(
            layout(vec![Format::Seq(1), Format::U8], 0).validate(),
            Err(LayoutError::BadChild { .. })
        ));
        assert!(
            layout(vec![Format::U8, Format::Seq(0)], 1)
                .validate()
                .is_ok()
        );
    }

    #[test]
    fn deep_nesting_is_rejected() {
        let mut formats = vec![Format::U8];
        for i in 0..MAX_FORMAT_DEPTH as u32 {
            formats.push(Format::Option(i));
        }
        let root = formats.len() as u32 - 1;
        assert_eq!(layout(formats, root).validate(), Err(LayoutError::TooDeep));
    }

    #[test]
    fn bad_root_and_container_are_rejected() {
        assert_eq!(
            layout(vec![Format::U8], 3).validate(),
            Err(LayoutError::BadRoot(3))
        );
        assert_eq!(
            layout(vec![Format::Named(0)], 0).validate(),
            Err(LayoutError::BadContainer(0))
        );
    }
}

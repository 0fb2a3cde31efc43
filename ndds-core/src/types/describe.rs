//! Building a [`TypeDescription`] for a Rust type by tracing its serde implementation with
//! serde-reflection.

use std::collections::{BTreeSet, HashMap};
use std::sync::OnceLock;

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_reflection::{
    ContainerFormat, Format as SrFormat, Named, Registry, Samples, Tracer, TracerConfig,
    VariantFormat,
};

use super::TypeDescription;
use super::layout::{
    Container, ContainerShape, Field, Format, LayoutError, TypeLayout, Variant, VariantShape,
};
use super::name::stable_name;

/// Why a type could not be described structurally.
#[derive(Debug, thiserror::Error)]
pub enum DescribeError {
    /// serde-reflection could not trace the type (untagged enums, `flatten`, custom
    /// deserializers that reject default values, ...).
    #[error("serde-reflection cannot trace {}: {reason}", stable_name(type_name))]
    Trace {
        /// The Rust type.
        type_name: &'static str,
        /// serde-reflection's message.
        reason: String,
    },
    /// Enums reachable only through a sequence, option or map: serde-reflection explores such
    /// a position once, so it cannot see all their variants.
    #[error(
        "enum(s) {enums} inside {short} sit behind a Vec, Option or map, where serde-reflection \
         cannot see all their variants; describe the type with \
         `TypeDescription::describer().with::<TheEnum>().describe::<{short}>()` and declare it \
         with `producer_with_type` / `consumer_with_type`",
        short = stable_name(type_name)
    )]
    IncompleteEnum {
        /// The Rust type.
        type_name: &'static str,
        /// The incomplete enums, comma-separated.
        enums: String,
    },
    /// The traced layout breaks a limit of the protocol (too deep, too many nodes, ...).
    #[error(
        "the layout of {} is not representable: {source}",
        stable_name(type_name)
    )]
    Layout {
        /// The Rust type.
        type_name: &'static str,
        /// The broken limit.
        source: LayoutError,
    },
    /// A type declared at run time (by a binding, from another language's type declarations)
    /// whose registry is incomplete or not representable.
    #[error("the type {name} cannot be described: {reason}")]
    Declared {
        /// The declared type's name.
        name: String,
        /// What is wrong.
        reason: String,
    },
}

/// Traces `T` and builds its description.
pub fn describe<T: Serialize + DeserializeOwned>() -> Result<TypeDescription, DescribeError> {
    Describer::new().describe::<T>()
}

/// Describes a type declared at run time rather than traced from Rust: its root format and
/// the registry of its named containers, in serde-reflection's terms, as a binding builds them
/// from another language's type declarations (`ndds-python`'s dataclasses). The result is the
/// description, and so the fingerprint, that the Rust type of the same shape gets.
pub fn from_registry(
    name: &str,
    root: &SrFormat,
    registry: &Registry,
) -> Result<TypeDescription, DescribeError> {
    let declared = |reason: String| DescribeError::Declared {
        name: name.to_owned(),
        reason,
    };
    let layout = layout_of(root, registry)
        .map_err(|what| declared(format!("incomplete declaration ({what})")))?;
    layout.validate().map_err(|err| declared(err.to_string()))?;
    Ok(TypeDescription {
        name: name.to_owned(),
        layout: Some(layout),
    })
}

/// A tracing step run before the described type, on the same tracer.
type PreTrace = fn(&mut Tracer, &'static Samples) -> serde_reflection::Result<()>;

fn pre_trace<U: DeserializeOwned>(
    tracer: &mut Tracer,
    samples: &'static Samples,
) -> serde_reflection::Result<()> {
    tracer.trace_type::<U>(samples).map(|_| ())
}

/// Describes a type whose nested enums serde-reflection cannot reach on its own.
///
/// An enum that appears only inside a `Vec`, `Option` or map is explored once, so only one of
/// its variants would be known. Tracing the enum by itself first completes it:
///
/// ```
/// use ndds_core::types::TypeDescription;
/// use serde::{Deserialize, Serialize};
///
/// #[derive(Serialize, Deserialize)]
/// enum Shape { Empty, Circle(f64), Box { w: f64, h: f64 } }
/// #[derive(Serialize, Deserialize)]
/// struct Scene { shapes: Vec<Shape> }
///
/// assert!(TypeDescription::try_of::<Scene>().is_err());
/// let desc = TypeDescription::describer().with::<Shape>().describe::<Scene>()?;
/// assert!(desc.canonical_text().contains("\"Box\":struct"));
/// # Ok::<(), ndds_core::types::DescribeError>(())
/// ```
#[derive(Clone, Debug, Default)]
pub struct Describer {
    pre: Vec<PreTrace>,
}

impl Describer {
    /// A describer with nothing pre-traced.
    pub fn new() -> Self {
        Describer::default()
    }

    /// Traces `U` (typically a nested enum) before the described type.
    pub fn with<U: DeserializeOwned>(mut self) -> Self {
        self.pre.push(pre_trace::<U>);
        self
    }

    /// Traces `T` and builds its description.
    pub fn describe<T: Serialize + DeserializeOwned>(
        &self,
    ) -> Result<TypeDescription, DescribeError> {
        let type_name = std::any::type_name::<T>();
        let trace_err = |err: serde_reflection::Error| DescribeError::Trace {
            type_name,
            reason: err.to_string(),
        };
        let (root, registry) = trace::<T>(&self.pre).map_err(trace_err)?;
        let incomplete = incomplete_enums(&registry);
        if !incomplete.is_empty() {
            return Err(DescribeError::IncompleteEnum {
                type_name,
                enums: incomplete.join(", "),
            });
        }
        build(type_name, &root, &registry)
    }
}

/// serde-reflection gives variants it saw by name only provisional indices just below
/// `u32::MAX`; a registry that still has one is incomplete.
fn incomplete_enums(registry: &Registry) -> Vec<String> {
    const PROVISIONAL: u32 = u32::MAX - (1 << 20);
    registry
        .iter()
        .filter(|(_, container)| {
            matches!(container, ContainerFormat::Enum(variants)
                if variants.keys().any(|index| *index >= PROVISIONAL))
        })
        .map(|(name, _)| name.clone())
        .collect()
}

fn build(
    type_name: &'static str,
    root: &SrFormat,
    registry: &Registry,
) -> Result<TypeDescription, DescribeError> {
    let layout = layout_of(root, registry).map_err(|what| DescribeError::Trace {
        type_name,
        reason: format!("incomplete trace ({what})"),
    })?;
    layout
        .validate()
        .map_err(|source| DescribeError::Layout { type_name, source })?;
    Ok(TypeDescription {
        name: stable_name(type_name),
        layout: Some(layout),
    })
}

/// Converts a root format and its registry into a layout (not yet validated); the error
/// names the part that is incomplete (`root`, or a container's name).
fn layout_of(root: &SrFormat, registry: &Registry) -> Result<TypeLayout, String> {
    let names: HashMap<&str, u32> = registry
        .keys()
        .enumerate()
        .map(|(i, name)| (name.as_str(), i as u32))
        .collect();
    let mut builder = Builder {
        names: &names,
        formats: Vec::new(),
        dedup: HashMap::new(),
    };
    let root = builder.add(root).ok_or_else(|| "root".to_owned())?;
    let mut containers = Vec::with_capacity(registry.len());
    for (name, container) in registry {
        let shape = builder.container(container).ok_or_else(|| name.clone())?;
        containers.push(Container {
            name: name.clone(),
            shape,
        });
    }
    Ok(TypeLayout {
        formats: builder.formats,
        root,
        containers,
    })
}

/// Traces `T` until every variant of every enum inside it is known.
///
/// serde-reflection explores one level of enum variants per pass and only repeats passes for a
/// top-level enum by itself. Nested enums are named by the `MissingVariants` error of a first
/// attempt; later attempts repeat passes until none of the named enums is incomplete.
fn trace<T: DeserializeOwned>(
    pre: &[PreTrace],
) -> Result<(SrFormat, Registry), serde_reflection::Error> {
    static SAMPLES: OnceLock<Samples> = OnceLock::new();
    let samples = SAMPLES.get_or_init(Samples::new);
    let mut enums: BTreeSet<String> = BTreeSet::new();
    for _attempt in 0..MAX_TRACE_ATTEMPTS {
        let mut tracer = Tracer::new(TracerConfig::default());
        for step in pre {
            step(&mut tracer, samples)?;
        }
        let mut root = SrFormat::Unit;
        for _pass in 0..MAX_TRACE_PASSES {
            let (format, _value) = tracer.trace_type_once::<T>(samples)?;
            if let SrFormat::TypeName(name) = &format {
                enums.insert(name.clone());
            }
            root = format;
            let mut incomplete = false;
            for name in &enums {
                incomplete |= tracer.check_incomplete_enum(name).is_some();
            }
            if !incomplete {
                break;
            }
        }
        match tracer.registry() {
            Ok(registry) => return Ok((root, registry)),
            Err(serde_reflection::Error::MissingVariants(missing))
                if missing.iter().any(|name| !enums.contains(name)) =>
            {
                enums.extend(missing);
            }
            Err(err) => return Err(err),
        }
    }
    Err(serde_reflection::Error::Custom(
        "enum variants still unknown after repeated tracing".to_owned(),
    ))
}

/// Fresh tracers started before giving up on nested enums.
const MAX_TRACE_ATTEMPTS: usize = 16;
/// Passes over the type within one attempt.
const MAX_TRACE_PASSES: usize = 1024;

struct Builder<'a> {
    names: &'a HashMap<&'a str, u32>,
    formats: Vec<Format>,
    dedup: HashMap<Format, u32>,
}

impl Builder<'_> {
    fn push(&mut self, format: Format) -> u32 {
        if let Some(index) = self.dedup.get(&format) {
            return *index;
        }
        let index = self.formats.len() as u32;
        self.formats.push(format.clone());
        self.dedup.insert(format, index);
        index
    }

    /// Adds a format and its children (children first). `None` for an incomplete trace.
    fn add(&mut self, format: &SrFormat) -> Option<u32> {
        let node = match format {
            SrFormat::Variable(_) => return None,
            SrFormat::TypeName(name) => Format::Named(*self.names.get(name.as_str())?),
            SrFormat::Unit => Format::Unit,
            SrFormat::Bool => Format::Bool,
            SrFormat::I8 => Format::I8,
            SrFormat::I16 => Format::I16,
            SrFormat::I32 => Format::I32,
            SrFormat::I64 => Format::I64,
            SrFormat::I128 => Format::I128,
            SrFormat::U8 => Format::U8,
            SrFormat::U16 => Format::U16,
            SrFormat::U32 => Format::U32,
            SrFormat::U64 => Format::U64,
            SrFormat::U128 => Format::U128,
            SrFormat::F32 => Format::F32,
            SrFormat::F64 => Format::F64,
            SrFormat::Char => Format::Char,
            SrFormat::Str => Format::Str,
            SrFormat::Bytes => Format::Bytes,
            SrFormat::Option(inner) => Format::Option(self.add(inner)?),
            SrFormat::Seq(inner) => Format::Seq(self.add(inner)?),
            SrFormat::Map { key, value } => Format::Map {
                key: self.add(key)?,
                value: self.add(value)?,
            },
            SrFormat::Tuple(items) => Format::Tuple(self.list(items)?),
            SrFormat::TupleArray { content, size } => Format::Array {
                item: self.add(content)?,
                len: u32::try_from(*size).ok()?,
            },
        };
        Some(self.push(node))
    }

    fn list(&mut self, items: &[SrFormat]) -> Option<Vec<u32>> {
        items.iter().map(|item| self.add(item)).collect()
    }

    fn fields(&mut self, fields: &[Named<SrFormat>]) -> Option<Vec<Field>> {
        fields
            .iter()
            .map(|field| {
                Some(Field {
                    name: field.name.clone(),
                    format: self.add(&field.value)?,
                })
            })
            .collect()
    }

    fn container(&mut self, container: &ContainerFormat) -> Option<ContainerShape> {
        Some(match container {
            ContainerFormat::UnitStruct => ContainerShape::UnitStruct,
            ContainerFormat::NewTypeStruct(inner) => ContainerShape::NewType(self.add(inner)?),
            ContainerFormat::TupleStruct(items) => ContainerShape::TupleStruct(self.list(items)?),
            ContainerFormat::Struct(fields) => ContainerShape::Struct(self.fields(fields)?),
            ContainerFormat::Enum(variants) => {
                let mut out = Vec::with_capacity(variants.len());
                for (index, variant) in variants {
                    let shape = match &variant.value {
                        VariantFormat::Variable(_) => return None,
                        VariantFormat::Unit => VariantShape::Unit,
                        VariantFormat::NewType(inner) => VariantShape::NewType(self.add(inner)?),
                        VariantFormat::Tuple(items) => VariantShape::Tuple(self.list(items)?),
                        VariantFormat::Struct(fields) => VariantShape::Struct(self.fields(fields)?),
                    };
                    out.push(Variant {
                        index: *index,
                        name: variant.name.clone(),
                        shape,
                    });
                }
                ContainerShape::Enum(out)
            }
        })
    }
}

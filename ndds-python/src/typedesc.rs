//! Sample types: a Python type declaration (from `ndds/_types.py`) turned into the
//! [`TypeDescription`] the Rust type of the same shape gets, and the codec for its samples.
//!
//! `_types.py` walks a dataclass's type hints and hands over a *spec*: a format is a string
//! naming a scalar (`"f64"`, `"str"`, `"bytes"`, ...) or a tuple (`("option", f)`,
//! `("seq", f)`, `("map", k, v)`, `("tuple", [f, ...])`, `("array", f, n)`,
//! `("named", "Pose")`), and every named type is a container: `(name, "struct", [(field, f),
//! ...], class)` (`"struct_kw"` for a dataclass with keyword-only fields, built with keyword
//! arguments) or `(name, "enum", [variant, ...], class)`. These are serde-reflection's
//! terms, so [`ndds_core::types::from_registry`] describes them exactly as tracing the Rust
//! type does.

use std::collections::BTreeMap;
use std::sync::Arc;

use ndds_core::types::serde_reflection::{
    ContainerFormat, Format as Sr, Named, Registry, VariantFormat,
};
use ndds_core::types::{TypeDescription, builtin, fingerprint_hex, from_registry};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList, PyString, PyTuple};

use crate::codec::{Codec, PyShape};

/// How samples of a type are written and read.
pub(crate) enum Kind {
    /// Through the codec: dataclasses, or dicts for an untyped consumer.
    Dynamic(Codec),
    /// `ndds.CsMat`: the runtime's CSMat, built by this Python factory on receipt.
    CsMat(Py<PyAny>),
}

/// A sample type: what a topic announces, and how its samples are encoded.
#[pyclass(module = "ndds._ndds", name = "DataType", frozen)]
pub(crate) struct DataType {
    pub(crate) desc: TypeDescription,
    pub(crate) kind: Arc<Kind>,
}

#[pymethods]
impl DataType {
    /// The type's name, as tools show it (`Pose`, `ndds::CsMat`).
    #[getter]
    fn name(&self) -> &str {
        &self.desc.name
    }

    /// The type fingerprint, 16 hex digits: equal to the Rust type's of the same shape.
    #[getter]
    fn fingerprint(&self) -> String {
        fingerprint_hex(self.desc.fingerprint())
    }

    /// The canonical text the fingerprint is computed from.
    #[getter]
    fn canonical(&self) -> String {
        self.desc.canonical_text()
    }

    /// The type's shape, e.g. `Pose{x: f64, y: f64}`.
    #[getter]
    fn shape(&self) -> String {
        self.desc.shape()
    }

    /// Encodes `value` as a sample of this type: the bytes a producer writes (and the Rust
    /// type of the same shape writes, with postcard). TypeError naming the field if it does
    /// not fit.
    fn encode<'py>(
        &self,
        py: Python<'py>,
        value: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let bytes = crate::endpoints::encode(&self.kind, value)?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// Decodes a sample of this type from its bytes; ValueError saying where if they do not
    /// decode.
    fn decode<'py>(&self, py: Python<'py>, payload: &[u8]) -> PyResult<Bound<'py, PyAny>> {
        crate::endpoints::decode(py, &self.kind, payload)
    }

    fn __repr__(&self) -> String {
        format!(
            "<ndds type {} {}>",
            self.desc.shape(),
            fingerprint_hex(self.desc.fingerprint())
        )
    }
}

impl DataType {
    /// The untyped view of a topic's announced type: structs as dicts, variants by name.
    pub(crate) fn plain(py: Python<'_>, desc: TypeDescription) -> PyResult<Self> {
        if desc.name == builtin::CSMAT {
            return Err(PyTypeError::new_err(
                "internal: CSMat types come from csmat_type",
            ));
        }
        // The description came from another endpoint: the codec trusts only a valid layout.
        desc.validate().map_err(|err| {
            PyTypeError::new_err(format!(
                "the type {} announced on this topic has an invalid layout ({err}): it cannot \
                 be decoded",
                desc.name
            ))
        })?;
        let Some(layout) = desc.layout.clone() else {
            return Err(PyTypeError::new_err(format!(
                "the type {} of this topic is opaque (its producer's type could not be traced): \
                 it cannot be decoded without that type",
                desc.name
            )));
        };
        Ok(DataType {
            desc,
            kind: Arc::new(Kind::Dynamic(Codec::new(py, layout, Vec::new()))),
        })
    }
}

/// Declares a sample type from `_types.py`'s spec (see the module docs).
#[pyfunction]
pub(crate) fn declare_type(
    py: Python<'_>,
    name: &str,
    root: &Bound<'_, PyAny>,
    containers: &Bound<'_, PyList>,
) -> PyResult<DataType> {
    let mut registry: Registry = BTreeMap::new();
    let mut classes: BTreeMap<String, (Py<PyAny>, String)> = BTreeMap::new();
    for item in containers.iter() {
        let item = item
            .cast::<PyTuple>()
            .map_err(|_| bad_spec("container", &item))?;
        let (cname, kind, items, class): (String, String, Bound<'_, PyList>, Bound<'_, PyAny>) =
            item.extract()?;
        let container = match kind.as_str() {
            "struct" | "struct_kw" => {
                let mut fields = Vec::new();
                for field in items.iter() {
                    let (fname, spec): (String, Bound<'_, PyAny>) = field.extract()?;
                    fields.push(Named {
                        name: fname,
                        value: format(&spec)?,
                    });
                }
                ContainerFormat::Struct(fields)
            }
            "enum" => {
                let mut variants = BTreeMap::new();
                for (index, variant) in items.iter().enumerate() {
                    let vname: String = variant.extract()?;
                    variants.insert(
                        index as u32,
                        Named {
                            name: vname,
                            value: VariantFormat::Unit,
                        },
                    );
                }
                ContainerFormat::Enum(variants)
            }
            other => {
                return Err(PyValueError::new_err(format!(
                    "unknown container kind {other}"
                )));
            }
        };
        if registry.insert(cname.clone(), container).is_some() {
            return Err(PyTypeError::new_err(format!(
                "two types named {cname} in one sample type: the type description names each \
                 type once (rename one of them)"
            )));
        }
        classes.insert(cname, (class.unbind(), kind));
    }
    let root = format(root)?;
    let desc = from_registry(name, &root, &registry)
        .map_err(|err| PyTypeError::new_err(err.to_string()))?;
    let layout = desc.layout.clone().expect("declared types have layouts");
    // The codec's shapes follow the layout's container order (sorted by name).
    let mut shapes = Vec::with_capacity(layout.containers.len());
    for container in &layout.containers {
        let shape = match classes.get(&container.name) {
            Some((class, kind)) if kind == "enum" => {
                PyShape::Members(enum_members(py, class.bind(py), &container.shape)?)
            }
            Some((class, kind)) if kind == "struct_kw" => {
                PyShape::KeywordClass(class.clone_ref(py))
            }
            Some((class, _)) => PyShape::Class(class.clone_ref(py)),
            None => PyShape::Plain,
        };
        shapes.push(shape);
    }
    Ok(DataType {
        desc,
        kind: Arc::new(Kind::Dynamic(Codec::new(py, layout, shapes))),
    })
}

/// The type of CSMat topics (`ndds::CsMat`, what a runtime publishes); samples arrive as what
/// `factory(name, rows, cols, data, row_fields, col_fields)` returns.
#[pyfunction]
pub(crate) fn csmat_type(factory: Py<PyAny>) -> DataType {
    DataType {
        desc: TypeDescription::named::<ndds_runtime::CsMat>(builtin::CSMAT),
        kind: Arc::new(Kind::CsMat(factory)),
    }
}

/// The members of an `enum.Enum` class in the layout's variant order.
fn enum_members(
    py: Python<'_>,
    class: &Bound<'_, PyAny>,
    shape: &ndds_core::types::ContainerShape,
) -> PyResult<Vec<Py<PyAny>>> {
    let ndds_core::types::ContainerShape::Enum(variants) = shape else {
        return Err(PyTypeError::new_err(
            "internal: an enum's container is not an enum",
        ));
    };
    variants
        .iter()
        .map(|v| Ok(class.getattr(PyString::new(py, &v.name))?.unbind()))
        .collect()
}

fn bad_spec(what: &str, value: &Bound<'_, PyAny>) -> PyErr {
    PyTypeError::new_err(format!("internal: bad {what} spec {value}"))
}

/// A format spec (see the module docs) as serde-reflection's format.
fn format(spec: &Bound<'_, PyAny>) -> PyResult<Sr> {
    if let Ok(name) = spec.cast::<PyString>() {
        return Ok(match name.to_cow()?.as_ref() {
            "unit" => Sr::Unit,
            "bool" => Sr::Bool,
            "i8" => Sr::I8,
            "i16" => Sr::I16,
            "i32" => Sr::I32,
            "i64" => Sr::I64,
            "i128" => Sr::I128,
            "u8" => Sr::U8,
            "u16" => Sr::U16,
            "u32" => Sr::U32,
            "u64" => Sr::U64,
            "u128" => Sr::U128,
            "f32" => Sr::F32,
            "f64" => Sr::F64,
            "char" => Sr::Char,
            "str" => Sr::Str,
            "bytes" => Sr::Bytes,
            _ => return Err(bad_spec("scalar", spec)),
        });
    }
    let tuple = spec
        .cast::<PyTuple>()
        .map_err(|_| bad_spec("format", spec))?;
    let head: String = tuple.get_item(0)?.extract()?;
    let arg = |i: usize| tuple.get_item(i);
    Ok(match head.as_str() {
        "option" => Sr::Option(Box::new(format(&arg(1)?)?)),
        "seq" => Sr::Seq(Box::new(format(&arg(1)?)?)),
        "map" => Sr::Map {
            key: Box::new(format(&arg(1)?)?),
            value: Box::new(format(&arg(2)?)?),
        },
        "tuple" => {
            let items = arg(1)?;
            let items = items
                .cast::<PyList>()
                .map_err(|_| bad_spec("tuple", spec))?;
            Sr::Tuple(items.iter().map(|i| format(&i)).collect::<PyResult<_>>()?)
        }
        "array" => Sr::TupleArray {
            content: Box::new(format(&arg(1)?)?),
            size: arg(2)?.extract()?,
        },
        "named" => Sr::TypeName(arg(1)?.extract()?),
        _ => return Err(bad_spec("format", spec)),
    })
}

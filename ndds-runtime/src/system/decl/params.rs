//! Component parameter values: converted as the type's documentation says ([`typed`]), or as
//! written for a type registered without one ([`generic`]).

use super::values::{matrix, number, numbers, texts};
use crate::system::source::{Diagnostics, Raw, RawValue};
use crate::{ParamKind, ParamValue, Params};

/// Converts a parameter value without a spec: numbers, lists, matrices, strings, tables.
pub(super) fn generic(raw: &Raw, key: &str, p: &mut Diagnostics) -> Option<ParamValue> {
    Some(match &raw.value {
        RawValue::Integer(_) | RawValue::Float(_) => ParamValue::Number(number(raw, key, p)?),
        RawValue::Text(s) => ParamValue::Text(s.clone()),
        RawValue::Bool(b) => ParamValue::Bool(*b),
        RawValue::Array(items) => return generic_list(raw, items, key, p),
        RawValue::Table(table) => {
            let mut params = Params::new();
            for (k, _, v) in &table.entries {
                params.0.insert(k.clone(), generic(v, k, p)?);
            }
            ParamValue::Table(params)
        }
        RawValue::Datetime => {
            let date = format!("`{key}` is a date-time");
            p.expected(&raw.at, date, "a number, string or list");
            return None;
        }
    })
}

/// A list without a spec: its first element tells strings, rows of a matrix or numbers.
fn generic_list(raw: &Raw, items: &[Raw], key: &str, p: &mut Diagnostics) -> Option<ParamValue> {
    match items.first().map(|i| &i.value) {
        Some(RawValue::Text(_)) => {
            let names = texts(raw, key, p).into_iter().map(|n| n.name);
            Some(ParamValue::Texts(names.collect()))
        }
        Some(RawValue::Array(_)) => matrix(raw, key, p).map(ParamValue::Matrix),
        _ => numbers(raw, key, p).map(ParamValue::Numbers),
    }
}

/// Converts a parameter value as its spec says.
pub(super) fn typed(
    raw: &Raw,
    key: &str,
    kind: ParamKind,
    p: &mut Diagnostics,
) -> Option<ParamValue> {
    use ParamKind as K;
    use RawValue as V;
    match (kind, &raw.value) {
        (K::Number, V::Integer(_) | V::Float(_)) => number(raw, key, p).map(ParamValue::Number),
        (K::Numbers, V::Integer(_) | V::Float(_) | V::Array(_)) => {
            numbers(raw, key, p).map(ParamValue::Numbers)
        }
        (K::Matrix, V::Integer(_) | V::Float(_) | V::Array(_)) => {
            matrix(raw, key, p).map(ParamValue::Matrix)
        }
        (K::File, V::Text(s)) if !s.trim().is_empty() => Some(ParamValue::Text(beside(raw, s))),
        (K::Text | K::Input | K::Output, V::Text(s)) if !s.trim().is_empty() => {
            Some(ParamValue::Text(s.clone()))
        }
        (K::Inputs, V::Text(_) | V::Array(_)) => inputs(raw, key, p),
        (K::Bool, V::Bool(b)) => Some(ParamValue::Bool(*b)),
        (K::Table, V::Table(_)) => generic(raw, key, p),
        _ => {
            let what = format!("parameter `{key}` is {}", raw.value.kind());
            p.expected(&raw.at, what, kind.describe());
            None
        }
    }
}

/// A file name, relative to the file it is written in (like includes).
fn beside(raw: &Raw, name: &str) -> String {
    let dir = raw.at.file.parent().unwrap_or(std::path::Path::new(""));
    dir.join(name).to_string_lossy().into_owned()
}

/// CSMats a component reads: at least one.
fn inputs(raw: &Raw, key: &str, p: &mut Diagnostics) -> Option<ParamValue> {
    let names = texts(raw, key, p);
    if names.is_empty() {
        p.expected(&raw.at, format!("`{key}` is empty"), "at least one CSMat");
        return None;
    }
    Some(ParamValue::Texts(
        names.into_iter().map(|n| n.name).collect(),
    ))
}

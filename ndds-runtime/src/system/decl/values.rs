//! Values of any table: numbers, lists of strings or numbers, matrices; each wrong one is
//! reported where it was written, with what was expected.

use nalgebra::DMatrix;

use super::Named;
use crate::system::source::{Diagnostics, Raw, RawValue};

/// Reports that `key` holds the wrong kind of value.
pub(super) fn wrong_kind<T>(
    raw: &Raw,
    key: &str,
    expected: &str,
    p: &mut Diagnostics,
) -> Option<T> {
    p.expected(
        &raw.at,
        format!("`{key}` is {}", raw.value.kind()),
        expected,
    );
    None
}

/// A finite number (an integer is one too).
pub(super) fn number(raw: &Raw, key: &str, p: &mut Diagnostics) -> Option<f64> {
    match raw.value {
        RawValue::Integer(n) => Some(n as f64),
        RawValue::Float(x) if x.is_finite() => Some(x),
        RawValue::Float(x) => {
            p.expected(&raw.at, format!("`{key}` is {x}"), "a finite number");
            None
        }
        _ => wrong_kind(raw, key, "a number", p),
    }
}

/// Non-empty strings, each with where it was written (a string is a list of one).
pub(super) fn texts(raw: &Raw, key: &str, p: &mut Diagnostics) -> Vec<Named> {
    let items: Vec<&Raw> = match &raw.value {
        RawValue::Array(items) => items.iter().collect(),
        RawValue::Text(_) => vec![raw],
        _ => return wrong_kind(raw, key, "a list of strings", p).unwrap_or_default(),
    };
    let mut out = Vec::new();
    for item in items {
        match &item.value {
            RawValue::Text(s) if !s.trim().is_empty() => out.push(Named {
                name: s.clone(),
                at: item.at.clone(),
            }),
            other => p.expected(
                &item.at,
                format!("an element of `{key}` is {}", other.kind()),
                "a non-empty string",
            ),
        }
    }
    out
}

/// The numbers of an array (a number is a list of one).
pub(super) fn numbers(raw: &Raw, key: &str, p: &mut Diagnostics) -> Option<Vec<f64>> {
    match &raw.value {
        RawValue::Integer(_) | RawValue::Float(_) => number(raw, key, p).map(|x| vec![x]),
        RawValue::Array(items) => {
            let mut out = Vec::with_capacity(items.len());
            let mut ok = true;
            for item in items {
                match number(item, key, p) {
                    Some(x) => out.push(x),
                    None => ok = false,
                }
            }
            ok.then_some(out)
        }
        _ => wrong_kind(raw, key, "a number or a list of numbers", p),
    }
}

/// A matrix: an array of equally long rows; a list of numbers is a column, a number 1 × 1.
pub(super) fn matrix(raw: &Raw, key: &str, p: &mut Diagnostics) -> Option<DMatrix<f64>> {
    match &raw.value {
        RawValue::Array(rows) if rows.first().is_some_and(is_array) => from_rows(raw, rows, key, p),
        _ => numbers(raw, key, p).map(|xs| DMatrix::from_column_slice(xs.len(), 1, &xs)),
    }
}

fn is_array(raw: &Raw) -> bool {
    matches!(raw.value, RawValue::Array(_))
}

/// The matrix of `rows` (the elements of `raw`), each an array as long as the first.
fn from_rows(raw: &Raw, rows: &[Raw], key: &str, p: &mut Diagnostics) -> Option<DMatrix<f64>> {
    let mut data = Vec::new();
    let mut cols = None;
    for row in rows {
        let values = row_numbers(row, key, cols, p)?;
        cols = Some(values.len());
        data.extend(values);
    }
    let cols = cols.unwrap_or(0);
    if cols == 0 {
        let empty = format!("`{key}` has empty rows");
        p.expected(&raw.at, empty, "at least one column");
        return None;
    }
    Some(DMatrix::from_row_slice(rows.len(), cols, &data))
}

/// The numbers of one row, which must be an array of `cols` numbers (any number for the
/// first row).
fn row_numbers(row: &Raw, key: &str, cols: Option<usize>, p: &mut Diagnostics) -> Option<Vec<f64>> {
    if !is_array(row) {
        p.expected(
            &row.at,
            format!("a row of `{key}` is {}", row.value.kind()),
            "a list of numbers (every row an array)",
        );
        return None;
    }
    let values = numbers(row, key, p)?;
    match cols {
        Some(n) if n != values.len() => {
            p.expected(
                &row.at,
                format!("a row of `{key}` has {} numbers", values.len()),
                format!("{n}, like the first row"),
            );
            None
        }
        _ => Some(values),
    }
}

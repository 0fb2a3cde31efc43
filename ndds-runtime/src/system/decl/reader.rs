//! [`Reader`]: the values of one table of a description, read through its key table, each
//! problem reported where it was written.

use std::time::Duration;

use super::keys::Key;
use super::values::{number, texts, wrong_kind};
use super::{Named, list, suggest};
use crate::system::source::{Diagnostics, Location, Raw, RawTable, RawValue};

/// Reads values out of one table, reporting what is wrong with each.
pub(super) struct Reader<'a> {
    pub table: &'a RawTable,
    pub at: Location,
    what: String,
    keys: &'static [Key],
}

impl<'a> Reader<'a> {
    /// A reader of `raw` (named `what` in messages), which must be a table with `keys`.
    pub fn new(
        raw: &'a Raw,
        what: &str,
        keys: &'static [Key],
        p: &mut Diagnostics,
    ) -> Option<Self> {
        match &raw.value {
            RawValue::Table(table) => Some(Self {
                table,
                at: raw.at.clone(),
                what: what.to_owned(),
                keys,
            }),
            other => {
                p.expected(&raw.at, format!("{what} is {}", other.kind()), "a table");
                None
            }
        }
    }

    /// Reports the keys its table does not list.
    pub fn known_keys(&self, p: &mut Diagnostics) {
        let known = self.keys;
        for (key, at, _) in &self.table.entries {
            if !known.iter().any(|k| k.name == key) {
                p.expected(
                    at,
                    format!("unknown key `{key}` in {}", self.what),
                    format!("one of {}{}", list(known), suggest(key, known)),
                );
            }
        }
    }

    /// The value of `key`, which the key table must list.
    pub fn raw(&self, key: &str) -> Option<&'a Raw> {
        debug_assert!(
            self.keys.iter().any(|k| k.name == key),
            "{} reads `{key}`, which its key table lacks",
            self.what
        );
        self.table.get(key)
    }

    /// Reports that `key` is missing, with what it takes (from the key table).
    pub fn missing(&self, key: &str, p: &mut Diagnostics) {
        let takes = self
            .keys
            .iter()
            .find(|k| k.name == key)
            .map_or("", |k| k.takes);
        p.expected(
            &self.at,
            format!("{} has no `{key}`", self.what),
            format!("`{key} = ` {takes}"),
        );
    }

    pub fn text(&self, key: &str, p: &mut Diagnostics) -> Option<Named> {
        let raw = self.raw(key)?;
        match &raw.value {
            RawValue::Text(s) if !s.trim().is_empty() => Some(Named {
                name: s.clone(),
                at: raw.at.clone(),
            }),
            RawValue::Text(_) => {
                p.expected(&raw.at, format!("`{key}` is empty"), "a non-empty string");
                None
            }
            _ => wrong_kind(raw, key, "a string", p),
        }
    }

    pub fn required_text(&self, key: &str, p: &mut Diagnostics) -> Option<Named> {
        if self.raw(key).is_none() {
            self.missing(key, p);
            return None;
        }
        self.text(key, p)
    }

    pub fn number(&self, key: &str, p: &mut Diagnostics) -> Option<f64> {
        number(self.raw(key)?, key, p)
    }

    pub fn integer(&self, key: &str, range: (i64, i64), p: &mut Diagnostics) -> Option<i64> {
        let raw = self.raw(key)?;
        match raw.value {
            RawValue::Integer(n) if (range.0..=range.1).contains(&n) => Some(n),
            RawValue::Integer(n) => {
                p.expected(
                    &raw.at,
                    format!("`{key}` is {n}"),
                    format!("an integer from {} to {}", range.0, range.1),
                );
                None
            }
            _ => wrong_kind(raw, key, "an integer", p),
        }
    }

    pub fn boolean(&self, key: &str, p: &mut Diagnostics) -> Option<bool> {
        let raw = self.raw(key)?;
        match raw.value {
            RawValue::Bool(b) => Some(b),
            _ => wrong_kind(raw, key, "true or false", p),
        }
    }

    /// Seconds, as a positive finite number.
    pub fn seconds(&self, key: &str, p: &mut Diagnostics) -> Option<Duration> {
        let raw = self.raw(key)?;
        let x = number(raw, key, p)?;
        if x.is_finite() && x > 0.0 && x <= 1e9 {
            Some(Duration::from_secs_f64(x))
        } else {
            let seconds = "a positive number of seconds";
            p.expected(&raw.at, format!("`{key}` is {x}"), seconds);
            None
        }
    }

    pub fn texts(&self, key: &str, p: &mut Diagnostics) -> Vec<Named> {
        self.raw(key)
            .map_or_else(Vec::new, |raw| texts(raw, key, p))
    }
}

//! `[[configuration]]`: one group per category, from the components' `group` keys
//! (`CATEGORY/GROUP`).

use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use super::values::number;
use super::{Description, Named};
use crate::system::source::{Diagnostics, Location, RawValue};
use crate::{MAX_RATE_HZ, MIN_RATE_HZ};

pub(super) const SECTION: Section = Section::list(
    "configuration",
    &[
        Key::new("name", TEXT),
        Key::new("groups", "a list of \"CATEGORY/GROUP\""),
        Key::new(
            "rates",
            "a table of habitat rates in Hz the switch sets: { servo = 500 }",
        ),
    ],
    |d, r, _, p| read(d, r, p),
);

pub(crate) struct ConfigurationDecl {
    pub name: Named,
    pub groups: Vec<(String, String, Location)>,
    /// `(habitat, Hz, where)`: rates the switch to this configuration sets.
    pub rates: Vec<(String, f64, Location)>,
}

fn read(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    if r.raw("groups").is_none() {
        r.missing("groups", p);
    }
    let groups: Vec<_> = r
        .texts("groups", p)
        .iter()
        .filter_map(|g| category_group(g, p))
        .collect();
    let rates = rates(r, p);
    if let Some(name) = name {
        d.configurations.push(ConfigurationDecl {
            name,
            groups,
            rates,
        });
    }
}

/// The `rates` table: habitat names to rates in Hz, each in the habitats' range.
fn rates(r: &Reader<'_>, p: &mut Diagnostics) -> Vec<(String, f64, Location)> {
    let Some(raw) = r.raw("rates") else {
        return Vec::new();
    };
    let RawValue::Table(table) = &raw.value else {
        p.expected(
            &raw.at,
            format!("`rates` is {}", raw.value.kind()),
            "a table of habitat rates in Hz, e.g. rates = { servo = 500 }",
        );
        return Vec::new();
    };
    let mut rates = Vec::new();
    for (habitat, at, value) in &table.entries {
        let Some(hz) = number(value, habitat, p) else {
            continue;
        };
        if (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&hz) {
            rates.push((habitat.clone(), hz, at.clone()));
        } else {
            p.expected(
                &value.at,
                format!("the rate of `{habitat}` is {hz} Hz"),
                format!("a rate from {MIN_RATE_HZ:.6} to {MAX_RATE_HZ} Hz"),
            );
        }
    }
    rates
}

/// `(category, group, where)` of a `"CATEGORY/GROUP"`.
pub(super) fn category_group(
    named: &Named,
    p: &mut Diagnostics,
) -> Option<(String, String, Location)> {
    match named.name.split_once('/') {
        Some((c, g)) if !c.is_empty() && !g.is_empty() && !g.contains('/') => {
            Some((c.to_owned(), g.to_owned(), named.at.clone()))
        }
        _ => {
            p.expected(
                &named.at,
                format!("group `{}` does not name its category", named.name),
                "\"CATEGORY/GROUP\", e.g. \"controllers/PD\"",
            );
            None
        }
    }
}

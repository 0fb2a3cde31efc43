//! `[[configuration]]`: one group per category, from the components' `group` keys
//! (`CATEGORY/GROUP`).

use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use super::{Description, Named};
use crate::system::source::{Diagnostics, Location};

pub(super) const SECTION: Section = Section::list(
    "configuration",
    &[
        Key::new("name", TEXT),
        Key::new("groups", "a list of \"CATEGORY/GROUP\""),
    ],
    |d, r, _, p| read(d, r, p),
);

pub(crate) struct ConfigurationDecl {
    pub name: Named,
    pub groups: Vec<(String, String, Location)>,
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
    if let Some(name) = name {
        d.configurations.push(ConfigurationDecl { name, groups });
    }
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

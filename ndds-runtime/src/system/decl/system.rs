//! `[system]`: the system's name, starting configuration, displayed CSMats and description.
//! A later file (the including one) overrides what an earlier one set.

use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use super::{Description, Named};
use crate::system::source::Diagnostics;

pub(super) const SECTION: Section = Section::table(
    "system",
    &[
        Key::new("name", TEXT),
        Key::new("configuration", "the configuration active at start"),
        Key::new("display", "a list of CSMats"),
        Key::new("description", TEXT),
    ],
    |d, r, _, p| read(d, r, p),
);

fn read(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    if let Some(name) = r.text("name", p).and_then(|name| checked_name(name, p)) {
        d.name = Some(name);
    }
    if let Some(conf) = r.text("configuration", p) {
        d.configuration = Some(conf);
    }
    if let Some(text) = r.text("description", p) {
        d.description = Some(text.name);
    }
    if r.raw("display").is_some() {
        d.display = r.texts("display", p);
    }
}

/// `name`, if it can name topics (`cs/NAME/...`).
fn checked_name(name: Named, p: &mut Diagnostics) -> Option<Named> {
    let bad = |c: char| c == '/' || c.is_whitespace() || c.is_control();
    if !name.name.chars().any(bad) {
        return Some(name);
    }
    p.expected(
        &name.at,
        format!("bad system name `{}`", name.name),
        "a name without `/`, spaces or control characters (it names topics cs/NAME/...)",
    );
    None
}

//! `[[rate_transition]]`: a CSMat written in one habitat copied into one read in another.

use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use super::{Description, Named};
use crate::system::source::Diagnostics;

/// What `from` and `to` take.
const ENDPOINT: &str = "{ habitat = \"...\", mat = \"...\" }";

pub(super) const SECTION: Section = Section::list(
    "rate_transition",
    &[
        Key::new("name", TEXT),
        Key::new("from", ENDPOINT),
        Key::new("to", ENDPOINT),
    ],
    |d, r, _, p| read(d, r, p),
);

/// The keys of `from` and `to`.
const ENDPOINT_KEYS: &[Key] = &[Key::new("habitat", TEXT), Key::new("mat", TEXT)];

pub(crate) struct RateDecl {
    pub name: Named,
    /// `(habitat, CSMat)`.
    pub from: (Named, Named),
    /// `(habitat, CSMat)`.
    pub to: (Named, Named),
}

fn read(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    let from = endpoint(r, "from", p);
    let to = endpoint(r, "to", p);
    if let (Some(name), Some(from), Some(to)) = (name, from, to) {
        d.rates.push(RateDecl { name, from, to });
    }
}

/// `(habitat, CSMat)` of the table at `key`.
fn endpoint(r: &Reader<'_>, key: &str, p: &mut Diagnostics) -> Option<(Named, Named)> {
    let Some(raw) = r.raw(key) else {
        r.missing(key, p);
        return None;
    };
    let inner = Reader::new(raw, &format!("`{key}`"), ENDPOINT_KEYS, p)?;
    inner.known_keys(p);
    let habitat = inner.required_text("habitat", p);
    let mat = inner.required_text("mat", p);
    Some((habitat?, mat?))
}

//! From parsed files to checked declarations: every section, key and value of a description
//! is checked here, and every problem is reported where it was written.
//!
//! Each section of the format has a file holding its key table (a [`Section`]), the
//! declaration it makes and its reader. The key tables, collected in [`SECTION_KEYS`], drive
//! the reading (a [`Reader`](reader::Reader) reads through its table), the reports of unknown
//! keys (with the closest known one) and the test of the reference in
//! docs/description-files.md: a key is added to its section's table and nowhere else.
//!
//! Layout:
//! - `keys`: [`Key`](keys::Key) and [`Section`], the shape of a key table; `reader`: one table's values
//!   through its key table; `values`: numbers, strings, lists and matrices; `params`:
//!   component parameters as their type's spec says; `names`: lists of names and the
//!   did-you-mean in messages.
//! - one file per section: `system`, `habitat`, `mat`, `component`, `configuration`,
//!   `binding` (`[[subscribe]]` and `[[publish]]`), `rate` (`[[rate_transition]]`),
//!   `machine` (`[[state_machine]]`), `trigger`, `port`.
//! - `checks`: what no single section can tell (duplicates, references across sections);
//!   `provided`: the unknown-CSMat rule.

mod binding;
mod checks;
mod component;
mod configuration;
mod habitat;
mod keys;
mod machine;
mod mat;
mod names;
mod params;
mod port;
mod provided;
mod rate;
mod reader;
mod system;
#[cfg(test)]
mod tests;
mod trigger;
mod values;

use super::source::{Diagnostics, Location, SourceFile};
use crate::ComponentSpec;

pub(crate) use binding::{PublishDecl, SubscribeDecl};
pub(crate) use component::ComponentDecl;
pub(crate) use configuration::ConfigurationDecl;
pub(crate) use habitat::HabitatDecl;
pub use keys::Section;
pub(crate) use machine::MachineDecl;
pub(crate) use mat::MatDecl;
pub(crate) use names::{list, suggest};
pub(crate) use port::PortDecl;
pub use port::Serves;
pub(crate) use rate::RateDecl;
pub(crate) use trigger::TriggerDecl;

/// Every section's key table, in the order the reference lists them (docs/
/// description-files.md is checked against it).
pub const SECTION_KEYS: &[Section] = &[
    system::SECTION,
    habitat::SECTION,
    mat::SECTION,
    component::SECTION,
    configuration::SECTION,
    binding::SUBSCRIBE,
    binding::PUBLISH,
    rate::SECTION,
    machine::SECTION,
    trigger::SECTION,
    port::SECTION,
];

/// The top-level keys of a description file: `include`, then every section.
pub const SECTIONS: &[&str] = &TOP_LEVEL;

const TOP_LEVEL: [&str; SECTION_KEYS.len() + 1] = top_level();

const fn top_level<const N: usize>() -> [&'static str; N] {
    let mut names = ["include"; N];
    let mut i = 1;
    while i < N {
        names[i] = SECTION_KEYS[i - 1].name;
        i += 1;
    }
    names
}

/// A name with where it was written.
#[derive(Clone, Debug)]
pub(crate) struct Named {
    pub name: String,
    pub at: Location,
}

/// A whole description, checked.
#[derive(Default)]
pub(crate) struct Description {
    pub name: Option<Named>,
    pub configuration: Option<Named>,
    pub display: Vec<Named>,
    pub description: Option<String>,
    pub habitats: Vec<HabitatDecl>,
    pub mats: Vec<MatDecl>,
    pub components: Vec<ComponentDecl>,
    pub configurations: Vec<ConfigurationDecl>,
    pub subscribes: Vec<SubscribeDecl>,
    pub publishes: Vec<PublishDecl>,
    pub rates: Vec<RateDecl>,
    pub machines: Vec<MachineDecl>,
    pub triggers: Vec<TriggerDecl>,
    pub ports: Vec<PortDecl>,
    /// Where the top file starts.
    pub start: Option<Location>,
    /// Habitats declared with a problem (reported): references to them are not reported
    /// again as unknown.
    pub broken_habitats: Vec<String>,
    /// Texts standing in for files (state-machine files are read through it).
    pub overlay: std::sync::Arc<crate::system::source::Overlay>,
}

/// The documented parameters of a component type: `Ok(None)` for a type registered without
/// a spec, `Err(known types)` for no such type.
pub(crate) type SpecLookup<'a> =
    dyn Fn(&str) -> Result<Option<&'static ComponentSpec>, Vec<String>> + 'a;

/// Checks every section of every file. `spec` gives the documented parameters of a component
/// type (`Ok(None)`: a type registered without a spec; `Err(known)`: no such type).
pub(crate) fn describe(
    files: &[SourceFile],
    spec: &SpecLookup<'_>,
    overlay: &std::sync::Arc<crate::system::source::Overlay>,
    p: &mut Diagnostics,
) -> Description {
    let mut d = Description {
        start: files.last().map(|f| f.start.clone()),
        overlay: std::sync::Arc::clone(overlay),
        ..Description::default()
    };
    // Included files come first, the top file last: its [system] keys win.
    for file in files {
        for (key, at, raw) in &file.top.entries {
            match SECTION_KEYS.iter().find(|s| s.name == key) {
                Some(section) => section.read_all(&mut d, raw, at, spec, p),
                None if key == "include" => {} // resolved while reading
                None => keys::unknown_section(key, at, SECTIONS, p),
            }
        }
    }
    checks::cross_check(&d, p);
    d
}

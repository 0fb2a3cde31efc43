//! `[[component]]`: an instance of a library type in a habitat. Its own keys are in the key
//! table; every other key is a parameter, checked against the type's documented ones.

use std::collections::BTreeMap;

use super::configuration::category_group;
use super::keys::{Key, Section, TEXT};
use super::params::{generic, typed};
use super::reader::Reader;
use super::values::texts;
use super::{Description, Named, SpecLookup, list, suggest};
use crate::system::source::{Diagnostics, Location, Raw, RawValue};
use crate::{ComponentSpec, ParamKind, ParamSpec, ParamValue, Params};

pub(super) const SECTION: Section = Section::list(
    "component",
    &[
        Key::new("name", TEXT),
        Key::new("type", TEXT),
        Key::new("habitat", TEXT),
        Key::new("group", "\"CATEGORY/GROUP\""),
    ],
    read,
)
.open();

pub(crate) struct ComponentDecl {
    pub name: Named,
    pub type_name: Named,
    pub habitat: Named,
    /// `(category, group)`.
    pub group: Option<(String, String, Location)>,
    pub params: Params,
    /// CSMats named by parameters: name, where, and how the component uses it.
    pub mats: Vec<(String, Location, ParamKind)>,
    /// Where each parameter was written.
    pub param_at: BTreeMap<String, Location>,
}

fn read(d: &mut Description, r: &Reader<'_>, spec_of: &SpecLookup<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    let type_name = r.required_text("type", p);
    let habitat = r.required_text("habitat", p);
    let group = r.text("group", p).and_then(|g| category_group(&g, p));
    let (Some(name), Some(type_name), Some(habitat)) = (name, type_name, habitat) else {
        return;
    };
    let parameters = match spec_of(&type_name.name) {
        Ok(spec) => Parameters::read(r, &name, spec, p),
        Err(known) => {
            unknown_type(&type_name, &known, p);
            Parameters::guessed(r)
        }
    };
    // Pushed even when a parameter is wrong (the problem is reported and nothing is built):
    // its outputs still count as provided.
    d.components.push(ComponentDecl {
        name,
        type_name,
        habitat,
        group,
        params: parameters.params,
        mats: parameters.mats,
        param_at: parameters.at,
    });
}

fn unknown_type(type_name: &Named, known: &[String], p: &mut Diagnostics) {
    let expected = if known.is_empty() {
        "a registered type, but this runtime has none: load with a component library \
         (ndds_components::library() for the built-in one)"
            .to_owned()
    } else {
        let close = suggest(&type_name.name, known);
        // Not a typo: most likely a type of the user's own, which only the program that
        // registers it knows.
        let own = if close.is_empty() {
            format!(
                " (a component type of your own is known only to the program that registers \
                 it: run this file with that program instead of `ndds run`, e.g. \
                 `cargo run -- {}` in the crate `ndds new component` made; see \
                 docs/components.md, \"Your own components\")",
                type_name.at.file.display()
            )
        } else {
            String::new()
        };
        format!("a registered type{close}{own}: {}", known.join(", "))
    };
    p.expected(
        &type_name.at,
        format!("unknown component type `{}`", type_name.name),
        expected.chars().take(2048).collect::<String>(),
    );
}

/// The keys of a component's table that are parameters, with where each key is.
fn parameters_of<'a>(r: &Reader<'a>) -> impl Iterator<Item = (&'a String, &'a Location, &'a Raw)> {
    let own = SECTION.keys;
    r.table
        .entries
        .iter()
        .filter(|(k, _, _)| !own.iter().any(|o| o.name == k))
        .map(|(k, at, raw)| (k, at, raw))
}

/// A component's parameters, converted, and the CSMats they name.
#[derive(Default)]
struct Parameters {
    params: Params,
    mats: Vec<(String, Location, ParamKind)>,
    /// Where each parameter was written.
    at: BTreeMap<String, Location>,
    /// No parameter was wrong (so a missing one is worth reporting).
    ok: bool,
}

impl Parameters {
    /// The parameters as the type's spec says (`None`: a type registered without one).
    fn read(
        r: &Reader<'_>,
        name: &Named,
        spec: Option<&ComponentSpec>,
        p: &mut Diagnostics,
    ) -> Self {
        let mut out = Self {
            ok: true,
            ..Self::default()
        };
        for (key, key_at, raw) in parameters_of(r) {
            out.at.insert(key.clone(), raw.at.clone());
            let value = match spec {
                None => out.undocumented(key, raw, p),
                Some(spec) => out.documented(spec, key, key_at, raw, p),
            };
            match value {
                Some(v) => {
                    out.params.0.insert(key.clone(), v);
                }
                None => out.ok = false,
            }
        }
        if let Some(spec) = spec {
            out.missing_required(name, spec, p);
        }
        out
    }

    /// For a type nobody knows (already reported): its string parameters may be outputs,
    /// counted as provided so that one mistake gives one message.
    fn guessed(r: &Reader<'_>) -> Self {
        let mats = parameters_of(r)
            .filter_map(|(_, _, raw)| match &raw.value {
                RawValue::Text(s) => Some((s.clone(), raw.at.clone(), ParamKind::Output)),
                _ => None,
            })
            .collect();
        Self {
            mats,
            ..Self::default()
        }
    }

    /// A parameter of a type without a spec: any string may name a CSMat it writes.
    fn undocumented(&mut self, key: &str, raw: &Raw, p: &mut Diagnostics) -> Option<ParamValue> {
        if let RawValue::Text(s) = &raw.value {
            self.mats
                .push((s.clone(), raw.at.clone(), ParamKind::Output));
        }
        generic(raw, key, p)
    }

    /// A parameter checked against `spec`; the CSMats it names are noted.
    fn documented(
        &mut self,
        spec: &ComponentSpec,
        key: &str,
        key_at: &Location,
        raw: &Raw,
        p: &mut Diagnostics,
    ) -> Option<ParamValue> {
        let Some(param) = spec.param(key) else {
            no_such_parameter(spec, key, key_at, p);
            return None;
        };
        let value = typed(raw, key, param.kind, p);
        match (&value, param.kind) {
            (Some(ParamValue::Text(mat)), kind @ (ParamKind::Input | ParamKind::Output)) => {
                self.mats.push((mat.clone(), raw.at.clone(), kind));
            }
            (Some(ParamValue::Texts(_)), ParamKind::Inputs) => {
                for n in texts(raw, key, &mut Diagnostics::default()) {
                    self.mats.push((n.name, n.at, ParamKind::Input));
                }
            }
            _ => {}
        }
        value
    }

    /// Reports the first required parameter not given, when none was wrong (one mistake,
    /// one message).
    fn missing_required(&self, name: &Named, spec: &ComponentSpec, p: &mut Diagnostics) {
        let missing =
            |param: &&ParamSpec| param.default.is_none() && !self.params.0.contains_key(param.name);
        let Some(param) = spec.params.iter().find(missing).filter(|_| self.ok) else {
            return;
        };
        p.expected(
            &name.at,
            format!(
                "component `{}` ({}) has no `{}`",
                name.name, spec.name, param.name
            ),
            format!("`{} = ` {}", param.name, param.kind.describe()),
        );
    }
}

fn no_such_parameter(spec: &ComponentSpec, key: &str, at: &Location, p: &mut Diagnostics) {
    let known: Vec<&str> = spec.params.iter().map(|s| s.name).collect();
    p.expected(
        at,
        format!("`{}` has no parameter `{key}`", spec.name),
        format!(
            "one of {}{}, or {}",
            list(&known),
            suggest(key, &known),
            list(SECTION.keys)
        ),
    );
}

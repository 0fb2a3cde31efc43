//! The linking database: every named object of a runtime, by kind and name.
//!
//! Looking an object up before it is created gives a placeholder (an unbound [`Mat`], an
//! uncreated [`Habitat`], a group or configuration known only by the references to it) that is
//! bound when the object appears; [`verify`](super::Runtime::verify) reports whatever is still
//! unbound.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

use super::habitat::Habitat;
use super::mat::Mat;
use super::module::Interface;

/// The kinds of named objects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ObjectKind {
    /// A CSMat.
    Mat,
    /// A sample module.
    Module,
    /// A sample habitat (and the execution list it runs, which has its name).
    Habitat,
    /// A module group.
    Group,
    /// A category of module groups.
    Category,
    /// A named configuration.
    Configuration,
}

impl fmt::Display for ObjectKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ObjectKind::Mat => "CSMat",
            ObjectKind::Module => "module",
            ObjectKind::Habitat => "habitat",
            ObjectKind::Group => "module group",
            ObjectKind::Category => "category",
            ObjectKind::Configuration => "configuration",
        })
    }
}

pub(crate) struct MatEntry {
    pub(crate) mat: Mat,
    /// Created (given a value) by the application: a source that needs no writer module.
    pub(crate) by_application: bool,
    /// Looked up by the application (a reference that is not a module's).
    pub(crate) looked_up: bool,
}

pub(crate) struct ModuleEntry {
    pub(crate) habitat: String,
    pub(crate) interface: Interface,
    /// Whether it is in its habitat's active set now (mirrors the list's slot).
    pub(crate) active: bool,
}

pub(crate) struct GroupEntry {
    pub(crate) category: String,
    pub(crate) modules: Vec<String>,
}

#[derive(Default)]
pub(crate) struct CategoryEntry {
    pub(crate) groups: Vec<String>,
    pub(crate) active: Option<String>,
}

#[derive(Default)]
pub(crate) struct Database {
    pub(crate) mats: BTreeMap<String, MatEntry>,
    pub(crate) modules: BTreeMap<String, ModuleEntry>,
    pub(crate) habitats: BTreeMap<String, Habitat>,
    pub(crate) groups: BTreeMap<String, GroupEntry>,
    pub(crate) categories: BTreeMap<String, CategoryEntry>,
    /// configuration -> category -> group.
    pub(crate) configurations: BTreeMap<String, BTreeMap<String, String>>,
    pub(crate) current: Option<String>,
    /// configuration -> (habitat, Hz): rates a switch to it sets.
    pub(crate) rates: BTreeMap<String, Vec<(String, f64)>>,
    /// `(follower, leader)`: CSMats created with the shape of another once it exists.
    pub(crate) follows: Vec<(String, String)>,
}

impl Database {
    /// The CSMat named `name`, a placeholder if it does not exist.
    pub(crate) fn mat(&mut self, name: &str) -> Mat {
        self.mats
            .entry(name.to_owned())
            .or_insert_with(|| MatEntry {
                mat: Mat::placeholder(name),
                by_application: false,
                looked_up: false,
            })
            .mat
            .clone()
    }

    /// Creates every unbound follower whose leader is bound (zero, with the leader's shape
    /// and fields), until nothing changes.
    pub(crate) fn propagate_shapes(&mut self) {
        loop {
            let mut changed = false;
            for (follower, leader) in &self.follows {
                let (Some(f), Some(l)) = (self.mats.get(follower), self.mats.get(leader)) else {
                    continue;
                };
                if !f.mat.is_bound() && l.mat.is_bound() {
                    let mut value = l.mat.snapshot();
                    value.fill(0.0);
                    f.mat.bind(value);
                    changed = true;
                }
            }
            if !changed {
                return;
            }
        }
    }

    /// The groups containing `module`.
    pub(crate) fn groups_of<'a>(&'a self, module: &'a str) -> impl Iterator<Item = &'a str> + 'a {
        self.groups
            .iter()
            .filter(move |(_, g)| g.modules.iter().any(|m| m == module))
            .map(|(name, _)| name.as_str())
    }

    /// Whether `module` is active when `active` names each category's active group: modules
    /// in no group always are; grouped ones when one of their groups is active.
    pub(crate) fn is_active_with(
        &self,
        module: &str,
        active: &BTreeMap<String, Option<String>>,
    ) -> bool {
        let mut grouped = false;
        for group in self.groups_of(module) {
            grouped = true;
            let category = &self.groups[group].category;
            if active.get(category).and_then(Option::as_deref) == Some(group) {
                return true;
            }
        }
        !grouped
    }

    /// Each category's active group now.
    pub(crate) fn active_groups(&self) -> BTreeMap<String, Option<String>> {
        self.categories
            .iter()
            .map(|(name, c)| (name.clone(), c.active.clone()))
            .collect()
    }

    /// The modules declaring `mat` as an input or output.
    pub(crate) fn referrers_of_mat(&self, mat: &str) -> BTreeSet<String> {
        self.modules
            .iter()
            .filter(|(_, m)| {
                m.interface.inputs.iter().any(|(p, _)| p.mat.name() == mat)
                    || m.interface.outputs.iter().any(|p| p.mat.name() == mat)
            })
            .map(|(name, _)| name.clone())
            .collect()
    }
}

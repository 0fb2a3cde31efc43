//! The configuration manager: modules → module groups → categories (one active group each) →
//! named configurations, switched atomically at sample boundaries.

use std::collections::BTreeMap;

use super::database::{CategoryEntry, Database, GroupEntry, ObjectKind};
use super::error::RuntimeError;
use super::habitat::Habitat;
use super::list::ExecList;
use super::runtime::{Runtime, check_name, lock};
use std::sync::MutexGuard;

impl Runtime {
    /// Creates module group `group` in `category` with `modules` (which may be installed
    /// later). The first group of a category becomes its active group.
    pub fn group(&self, category: &str, group: &str, modules: &[&str]) -> Result<(), RuntimeError> {
        check_name(ObjectKind::Category, category)?;
        check_name(ObjectKind::Group, group)?;
        let mut db = self.db();
        if db.groups.contains_key(group) {
            return Err(RuntimeError::Duplicate {
                kind: ObjectKind::Group,
                name: group.to_owned(),
            });
        }
        let before = db.active_groups();
        db.groups.insert(
            group.to_owned(),
            GroupEntry {
                category: category.to_owned(),
                modules: modules.iter().map(|m| (*m).to_owned()).collect(),
            },
        );
        let entry = db.categories.entry(category.to_owned()).or_default();
        entry.groups.push(group.to_owned());
        if entry.active.is_none() {
            entry.active = Some(group.to_owned());
        }
        let after = db.active_groups();
        if let Err(err) = self.apply(&mut db, &after) {
            db.groups.remove(group);
            let entry = db.categories.entry(category.to_owned()).or_default();
            entry.groups.retain(|g| g != group);
            entry.active = before.get(category).cloned().flatten();
            if entry.groups.is_empty() {
                db.categories.remove(category);
            }
            return Err(err);
        }
        Ok(())
    }

    /// Names configuration `name`: which group is active in each category it lists (groups
    /// may be created later; categories it does not list keep their active group).
    pub fn configuration(
        &self,
        name: &str,
        selections: &[(&str, &str)],
    ) -> Result<(), RuntimeError> {
        check_name(ObjectKind::Configuration, name)?;
        let mut db = self.db();
        if db.configurations.contains_key(name) {
            return Err(RuntimeError::Duplicate {
                kind: ObjectKind::Configuration,
                name: name.to_owned(),
            });
        }
        let mut map = BTreeMap::new();
        for (category, group) in selections {
            if map
                .insert((*category).to_owned(), (*group).to_owned())
                .is_some()
            {
                return Err(RuntimeError::Duplicate {
                    kind: ObjectKind::Category,
                    name: format!("{category} (listed twice in configuration `{name}`)"),
                });
            }
        }
        db.configurations.insert(name.to_owned(), map);
        Ok(())
    }

    /// Switches to configuration `name`, atomically at each habitat's next sample boundary:
    /// the leaving modules' `disable`, then the entering modules' `enable` (which can still
    /// read the leaving modules' outputs), then the lists are re-sorted. If the new active
    /// set cannot be sorted nothing changes.
    pub fn switch(&self, name: &str) -> Result<(), RuntimeError> {
        let mut db = self.db();
        let selections =
            db.configurations
                .get(name)
                .cloned()
                .ok_or_else(|| RuntimeError::Unknown {
                    kind: ObjectKind::Configuration,
                    name: name.to_owned(),
                })?;
        let mut active = db.active_groups();
        for (category, group) in &selections {
            Self::check_group(&db, category, group)?;
            active.insert(category.clone(), Some(group.clone()));
        }
        self.apply(&mut db, &active)?;
        db.current = Some(name.to_owned());
        Ok(())
    }

    /// Makes `group` the active group of `category` (the configuration becomes unnamed).
    pub fn activate_group(&self, category: &str, group: &str) -> Result<(), RuntimeError> {
        let mut db = self.db();
        Self::check_group(&db, category, group)?;
        let mut active = db.active_groups();
        active.insert(category.to_owned(), Some(group.to_owned()));
        self.apply(&mut db, &active)?;
        db.current = None;
        Ok(())
    }

    fn check_group(db: &Database, category: &str, group: &str) -> Result<(), RuntimeError> {
        match db.groups.get(group) {
            None => Err(RuntimeError::Unknown {
                kind: ObjectKind::Group,
                name: group.to_owned(),
            }),
            Some(entry) if entry.category != category => Err(RuntimeError::WrongCategory {
                group: group.to_owned(),
                category: category.to_owned(),
                actual: entry.category.clone(),
            }),
            Some(_) => Ok(()),
        }
    }

    /// The configuration last switched to, if the active groups still are its.
    pub fn current_configuration(&self) -> Option<String> {
        self.db().current.clone()
    }

    /// Each category's active group.
    pub fn active_groups(&self) -> BTreeMap<String, String> {
        self.db()
            .categories
            .iter()
            .filter_map(|(c, e)| e.active.clone().map(|g| (c.clone(), g)))
            .collect()
    }

    /// Applies a new set of active groups to every habitat, all or nothing.
    fn apply(
        &self,
        db: &mut Database,
        active: &BTreeMap<String, Option<String>>,
    ) -> Result<(), RuntimeError> {
        // Writers in different habitats, from the database (no lock needed); writers in one
        // habitat are the sort's to refuse, with its own error.
        let mut writers: BTreeMap<&str, (&str, &str)> = BTreeMap::new();
        for (name, entry) in &db.modules {
            if !db.is_active_with(name, active) {
                continue;
            }
            for mat in entry.interface.output_names() {
                match writers.get(mat) {
                    Some((first, habitat)) if *habitat != entry.habitat => {
                        return Err(RuntimeError::DoubleWriter {
                            mat: mat.to_owned(),
                            first: (*first).to_owned(),
                            second: name.clone(),
                        });
                    }
                    Some(_) => {}
                    None => {
                        writers.insert(mat, (name, &entry.habitat));
                    }
                }
            }
        }
        // Only the habitats whose active set changes are locked (each at its next sample
        // boundary, all together, in name order), so a switch never waits on the others.
        let affected: Vec<Habitat> = db
            .habitats
            .values()
            .filter(|h| {
                db.modules.iter().any(|(name, m)| {
                    m.habitat == h.name() && m.active != db.is_active_with(name, active)
                })
            })
            .cloned()
            .collect();
        let mut lists: Vec<MutexGuard<'_, ExecList>> =
            affected.iter().map(|h| lock(&h.shared.list)).collect();
        let mut plans = Vec::with_capacity(lists.len());
        for (habitat, list) in affected.iter().zip(&lists) {
            let next: Vec<bool> = list
                .slots
                .iter()
                .map(|slot| db.is_active_with(&slot.name, active))
                .collect();
            let order = list
                .plan(|i| next[i])
                .map_err(|source| RuntimeError::Sort {
                    habitat: habitat.name().to_owned(),
                    source,
                })?;
            plans.push((next, order));
        }
        drop(writers);
        for (list, (next, _)) in lists.iter_mut().zip(&plans) {
            list.leave(next);
        }
        for (list, (next, order)) in lists.iter_mut().zip(plans) {
            list.enter(&next, order);
        }
        drop(lists);
        let flags: Vec<(String, bool)> = db
            .modules
            .keys()
            .map(|name| (name.clone(), db.is_active_with(name, active)))
            .collect();
        for (name, on) in flags {
            if let Some(entry) = db.modules.get_mut(&name) {
                entry.active = on;
            }
        }
        for (category, group) in active {
            if let Some(entry) = db.categories.get_mut(category) {
                entry.active = group.clone();
            } else if let Some(group) = group {
                db.categories.insert(
                    category.clone(),
                    CategoryEntry {
                        groups: vec![group.clone()],
                        active: Some(group.clone()),
                    },
                );
            }
        }
        Ok(())
    }
}

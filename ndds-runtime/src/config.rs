//! The configuration manager: modules → module groups → categories (one active group each) →
//! named configurations.
//!
//! A switch is prepared off the habitat threads and swapped in by each habitat at a sample
//! boundary, in the way ros2_control switches controllers:
//! 1. the next active set is checked against the database (a CSMat written in two habitats)
//!    and each affected habitat's next execution order is sorted, without any list lock: a
//!    failure changes nothing;
//! 2. the entering modules are lent out of their (sampling) lists and their `enable` runs on
//!    the calling thread while the habitats go on sampling the old set, so an expensive
//!    `enable` (an LQG design) costs no sample; it can read the leaving modules' outputs;
//! 3. the affected lists are taken together at their sample boundaries and the prepared
//!    orders swapped in (moves only: no routine runs, nothing is sorted);
//! 4. the leaving modules, lent out by the swap, get `disable` on the calling thread after
//!    their last sample, and go back into their lists.

use std::collections::BTreeMap;
use std::sync::{MutexGuard, TryLockError};
use std::time::Duration;

use super::database::{CategoryEntry, Database, GroupEntry, ObjectKind};
use super::error::RuntimeError;
use super::habitat::{Habitat, HabitatError};
use super::list::inside_routine;
use super::list::{ExecList, Lent, Routine};
use super::module::SampleContext;
use super::requests::Request;
use super::runtime::{Runtime, check_name, lock, refuse_inside_routine};

/// Which group each category has active (`None`: none).
type ActiveGroups = BTreeMap<String, Option<String>>;

/// One affected habitat's part of a switch.
struct Plan {
    habitat: Habitat,
    next: Vec<bool>,
    order: Vec<usize>,
    entering: Vec<usize>,
    lent: Vec<Lent>,
    ctx: SampleContext,
}

impl Runtime {
    /// Creates module group `group` in `category` with `modules` (which may be installed
    /// later). The first group of a category becomes its active group.
    pub fn group(&self, category: &str, group: &str, modules: &[&str]) -> Result<(), RuntimeError> {
        refuse_inside_routine("group")?;
        check_name(ObjectKind::Category, category)?;
        check_name(ObjectKind::Group, group)?;
        let _structure = self.inner.structure();
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
        drop(db);
        if let Err(err) = self.apply(&after) {
            let mut db = self.db();
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
        refuse_inside_routine("configuration")?;
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

    /// Makes a switch to configuration `name` (declared) also set these habitats' rates
    /// (created ones, refused otherwise), once its lists are swapped in: each habitat's
    /// modules see the new period, with `timing_changed`, at its next sample boundary.
    /// Replaces rates given before.
    pub fn configuration_rates(
        &self,
        name: &str,
        rates: &[(&str, f64)],
    ) -> Result<(), RuntimeError> {
        refuse_inside_routine("configuration_rates")?;
        let mut db = self.db();
        if !db.configurations.contains_key(name) {
            return Err(RuntimeError::Unknown {
                kind: ObjectKind::Configuration,
                name: name.to_owned(),
            });
        }
        for (habitat, hz) in rates {
            if !db.habitats.get(*habitat).is_some_and(Habitat::is_created) {
                return Err(RuntimeError::Unknown {
                    kind: ObjectKind::Habitat,
                    name: (*habitat).to_owned(),
                });
            }
            if crate::habitat::period_of(*hz).is_none() {
                return Err(RuntimeError::Habitat(HabitatError::InvalidRate {
                    habitat: (*habitat).to_owned(),
                    hz: *hz,
                }));
            }
        }
        let rates = rates.iter().map(|(h, hz)| ((*h).to_owned(), *hz)).collect();
        db.rates.insert(name.to_owned(), rates);
        Ok(())
    }

    /// Switches to configuration `name`: each affected habitat swaps in its prepared list at
    /// its next sample boundary (see the module doc for the steps, and where `enable` and
    /// `disable` run). If the new active set cannot be sorted nothing changes. Called from
    /// inside a module's routine, the switch is queued and carried out after the routine.
    pub fn switch(&self, name: &str) -> Result<(), RuntimeError> {
        if inside_routine() {
            self.inner.request(Request::Switch(name.to_owned()));
            return Ok(());
        }
        let rates = {
            let _structure = self.inner.structure();
            let active = {
                let db = self.db();
                let selections =
                    db.configurations
                        .get(name)
                        .ok_or_else(|| RuntimeError::Unknown {
                            kind: ObjectKind::Configuration,
                            name: name.to_owned(),
                        })?;
                let mut active = db.active_groups();
                for (category, group) in selections {
                    Self::check_group(&db, category, group)?;
                    active.insert(category.clone(), Some(group.clone()));
                }
                active
            };
            self.apply(&active)?;
            let mut db = self.db();
            db.current = Some(name.to_owned());
            db.rates.get(name).cloned().unwrap_or_default()
        };
        // The configuration's rates, once its lists are in (`set_rate` takes the structure
        // lock itself).
        for (habitat, hz) in rates {
            match self.find_habitat(&habitat) {
                Some(h) => h.set_rate(hz)?,
                None => {
                    return Err(RuntimeError::Unknown {
                        kind: ObjectKind::Habitat,
                        name: habitat,
                    });
                }
            }
        }
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

    /// Applies a new set of active groups to every habitat, all or nothing. The caller holds
    /// the structure lock and not the database's.
    fn apply(&self, active: &ActiveGroups) -> Result<(), RuntimeError> {
        let mut plans = self.plan_switch(active)?;
        for plan in &mut plans {
            lend_entering(plan);
            let ctx = plan.ctx;
            for lent in &mut plan.lent {
                lent.call(Routine::Enable, &ctx);
            }
        }
        let mut leaving = swap_at_boundaries(&mut plans);
        for (plan, lent) in plans.iter().zip(&mut leaving) {
            let ctx = plan.ctx;
            for module in lent.iter_mut() {
                module.call(Routine::Disable, &ctx);
            }
        }
        for (plan, lent) in plans.iter().zip(leaving) {
            lock(&plan.habitat.shared.list).restore(lent);
        }
        self.commit(active);
        Ok(())
    }

    /// Step 1: the checks, and each affected habitat's next order (nothing changes yet).
    fn plan_switch(&self, active: &ActiveGroups) -> Result<Vec<Plan>, RuntimeError> {
        let (affected, next_of) = {
            let db = self.db();
            check_writers(&db, active)?;
            let next_of: BTreeMap<String, bool> = db
                .modules
                .keys()
                .map(|name| (name.clone(), db.is_active_with(name, active)))
                .collect();
            (affected_habitats(&db, &next_of), next_of)
        };
        let mut plans = Vec::with_capacity(affected.len());
        for habitat in affected {
            let (layout, ctx) = {
                let list = lock(&habitat.shared.list);
                (list.layout(), list.ctx)
            };
            let next: Vec<bool> = layout
                .names()
                .map(|name| next_of.get(name).copied().unwrap_or(false))
                .collect();
            let order = layout
                .plan(|i, _| next[i])
                .map_err(|source| RuntimeError::Sort {
                    habitat: habitat.name().to_owned(),
                    source,
                })?;
            let entering = (0..next.len())
                .filter(|&i| next[i] && !layout.is_active(i))
                .collect();
            plans.push(Plan {
                habitat,
                next,
                order,
                entering,
                lent: Vec::new(),
                ctx,
            });
        }
        Ok(plans)
    }

    /// Records the new active set in the database.
    fn commit(&self, active: &ActiveGroups) {
        let mut db = self.db();
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
    }
}

/// A CSMat written by active modules of two habitats (writers in one habitat are the sort's
/// to refuse, with its own error).
fn check_writers(db: &Database, active: &ActiveGroups) -> Result<(), RuntimeError> {
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
    Ok(())
}

/// The habitats whose active set changes (the others are not touched at all), by name.
fn affected_habitats(db: &Database, next_of: &BTreeMap<String, bool>) -> Vec<Habitat> {
    db.habitats
        .values()
        .filter(|h| {
            db.modules
                .iter()
                .any(|(name, m)| m.habitat == h.name() && m.active != next_of[name])
        })
        .cloned()
        .collect()
}

/// Step 2: lends a sampling habitat's entering modules out, for their `enable`.
fn lend_entering(plan: &mut Plan) {
    let mut list = lock(&plan.habitat.shared.list);
    if list.sampling {
        plan.lent = list.lend(&plan.entering);
        plan.ctx = list.ctx;
    }
}

/// Step 3: every affected list at once, each at its sample boundary; returns the modules
/// that left, lent out for their `disable`.
fn swap_at_boundaries(plans: &mut [Plan]) -> Vec<Vec<Lent>> {
    let habitats: Vec<Habitat> = plans.iter().map(|p| p.habitat.clone()).collect();
    let handles: Vec<&Habitat> = habitats.iter().collect();
    let mut lists = lock_together(&handles);
    plans
        .iter_mut()
        .zip(lists.iter_mut())
        .map(|(plan, list)| {
            list.swap(
                &plan.next,
                std::mem::take(&mut plan.order),
                std::mem::take(&mut plan.lent),
            )
        })
        .collect()
}

/// Locks every list, each between two of its samples. With several, they are taken with
/// `try_lock` together and released and retried if one is in a sample, so no habitat waits
/// for another's sample; after about a second of that (a habitat sampling back to back), in
/// name order.
fn lock_together<'a>(habitats: &[&'a Habitat]) -> Vec<MutexGuard<'a, ExecList>> {
    if habitats.len() > 1 {
        for _ in 0..20_000 {
            if let Some(all) = try_lock_all(habitats) {
                return all;
            }
            std::thread::sleep(Duration::from_micros(50));
        }
    }
    habitats.iter().map(|h| lock(&h.shared.list)).collect()
}

fn try_lock_all<'a>(habitats: &[&'a Habitat]) -> Option<Vec<MutexGuard<'a, ExecList>>> {
    habitats
        .iter()
        .map(|h| match h.shared.list.try_lock() {
            Ok(guard) => Some(guard),
            Err(TryLockError::Poisoned(poisoned)) => Some(poisoned.into_inner()),
            Err(TryLockError::WouldBlock) => None,
        })
        .collect()
}

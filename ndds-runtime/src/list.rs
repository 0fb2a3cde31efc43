//! The execution list a habitat runs: its installed modules, which of them are active, and the
//! dependency-sorted order of the active ones. Entry routines are called from here only.
//!
//! Who calls what, where (the contract `SampleModule`'s table documents):
//! - The habitat's thread (or the caller of `step`) holds the list's lock for one sample and
//!   runs `execute` and `state_update`; at the start of a sample it first carries out the
//!   [`BoundaryTask`]s queued since the last one (`timing_changed`, `reset`).
//! - Other threads take the lock only for short moves that run no user code and sort nothing
//!   (lending modules out, swapping in a prepared order, installing a built module), so a
//!   habitat never waits on a lock held while a routine runs elsewhere or a list is sorted.
//! - `enable` and `disable` of a switch, and the routines of a module being installed into or
//!   removed from a sampling habitat, run on the thread that asked, on modules lent out of
//!   the list ([`ExecList::lend`]): the habitat keeps sampling meanwhile.

use std::cell::Cell;
use std::time::Duration;

use super::mat::{Owned, as_sampler};
use super::module::{Interface, ModuleError, RoutineResult, SampleContext, SampleModule};
use super::sort::{SortError, SortNode, sort};

thread_local! {
    /// Set while this thread runs a module's routine.
    static IN_ROUTINE: Cell<bool> = const { Cell::new(false) };
}

/// Whether the calling thread is inside a module's entry routine (requests to the runtime
/// made there are queued, never carried out re-entrantly).
pub(crate) fn inside_routine() -> bool {
    IN_ROUTINE.with(Cell::get)
}

/// One installed module.
pub(crate) struct Slot {
    pub(crate) name: String,
    pub(crate) interface: Interface,
    /// `None` while lent out to a thread running its `enable` or `disable`.
    module: Option<Box<dyn SampleModule>>,
    pub(crate) active: bool,
    errors: u64,
}

impl Slot {
    pub(crate) fn new(name: String, interface: Interface, module: Box<dyn SampleModule>) -> Self {
        Self {
            name,
            interface,
            module: Some(module),
            active: false,
            errors: 0,
        }
    }

    /// The module, while it is not lent out (a slot being installed always has it).
    pub(crate) fn module_mut(&mut self) -> &mut dyn SampleModule {
        self.module
            .as_deref_mut()
            .expect("a slot being installed holds its module")
    }
}

/// Which routine failed (for the log).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Routine {
    Execute,
    StateUpdate,
    Enable,
    Disable,
    Startup,
    Shutdown,
    TimingChanged,
    Reset,
}

/// Work a habitat does at its next sample boundary, on its own thread, before the sample.
#[derive(Clone, Copy, Debug)]
pub(crate) enum BoundaryTask {
    /// Adopt this period and call every module's `timing_changed`.
    Timing(Duration),
    /// Call every module's `reset`.
    Reset,
}

/// A module lent out of its list, with the outcome of the routines run on it meanwhile.
pub(crate) struct Lent {
    index: usize,
    module: Box<dyn SampleModule>,
    failures: Vec<(Routine, ModuleError)>,
}

impl Lent {
    /// Runs `routine` on the lent module (no list lock is held).
    pub(crate) fn call(&mut self, routine: Routine, ctx: &SampleContext) {
        if let Err(err) = run_routine(self.module.as_mut(), routine, ctx) {
            self.failures.push((routine, err));
        }
    }
}

/// The part of a list a plan is made from (cloned under the lock, sorted without it).
pub(crate) struct Layout {
    slots: Vec<(String, Interface, bool)>,
}

impl Layout {
    /// The slots for which `active(index, name)` holds, in execution order, or why they
    /// cannot be ordered.
    pub(crate) fn plan(
        &self,
        active: impl Fn(usize, &str) -> bool,
    ) -> Result<Vec<usize>, SortError> {
        let members: Vec<usize> = (0..self.slots.len())
            .filter(|&i| active(i, &self.slots[i].0))
            .collect();
        let nodes: Vec<SortNode<'_>> = members
            .iter()
            .map(|&i| {
                let (name, iface, _) = &self.slots[i];
                SortNode {
                    module: name,
                    reads: iface.feedthrough_names().collect(),
                    writes: iface.output_names().collect(),
                }
            })
            .collect();
        Ok(sort(&nodes)?.into_iter().map(|k| members[k]).collect())
    }

    /// The slots' names, in installation order.
    pub(crate) fn names(&self) -> impl Iterator<Item = &str> {
        self.slots.iter().map(|(name, _, _)| name.as_str())
    }

    /// Whether slot `i` is active now.
    pub(crate) fn is_active(&self, i: usize) -> bool {
        self.slots[i].2
    }

    /// Adds a slot at the end (the plan for an install).
    pub(crate) fn push(&mut self, name: &str, interface: Interface) {
        self.slots.push((name.to_owned(), interface, false));
    }
}

/// A habitat's modules. The habitat's list lock guards it; see the module doc for who holds
/// that lock when.
pub(crate) struct ExecList {
    pub(crate) slots: Vec<Slot>,
    /// Indices of the active slots, in execution order.
    pub(crate) order: Vec<usize>,
    pub(crate) sampling: bool,
    pub(crate) ctx: SampleContext,
    pub(crate) module_errors: u64,
    /// Carried out at the start of the next sample.
    pub(crate) boundary: Vec<BoundaryTask>,
    /// The CSMats only this habitat's modules name: its routines reach them without a lock.
    pub(crate) owned: Owned,
}

impl ExecList {
    pub(crate) fn new(period: Duration) -> Self {
        Self {
            slots: Vec::new(),
            order: Vec::new(),
            sampling: false,
            ctx: SampleContext {
                period,
                sample: 0,
                time: Duration::ZERO,
            },
            module_errors: 0,
            boundary: Vec::new(),
            owned: Owned::new(),
        }
    }

    pub(crate) fn position(&self, name: &str) -> Option<usize> {
        self.slots.iter().position(|slot| slot.name == name)
    }

    /// What a plan is made from (cheap clones: names and interfaces).
    pub(crate) fn layout(&self) -> Layout {
        Layout {
            slots: self
                .slots
                .iter()
                .map(|s| (s.name.clone(), s.interface.clone(), s.active))
                .collect(),
        }
    }

    /// Runs one sample: the queued boundary tasks, then every active module's `execute`, then
    /// every `state_update`.
    pub(crate) fn run_sample(&mut self) {
        if !self.boundary.is_empty() {
            self.run_boundary_tasks();
        }
        let ctx = self.ctx;
        // Marked once for the whole sample (not per routine): the hot path.
        let sampler = as_sampler(self.owned.id());
        self.owned.take_in();
        let outer = IN_ROUTINE.with(|flag| flag.replace(true));
        for k in 0..self.order.len() {
            let i = self.order[k];
            if let Some(module) = self.slots[i].module.as_deref_mut()
                && let Err(err) = guarded(|| module.execute(&ctx))
            {
                self.note_error(i, Routine::Execute, &err);
            }
        }
        for k in 0..self.order.len() {
            let i = self.order[k];
            if let Some(module) = self.slots[i].module.as_deref_mut()
                && let Err(err) = guarded(|| module.state_update(&ctx))
            {
                self.note_error(i, Routine::StateUpdate, &err);
            }
        }
        IN_ROUTINE.with(|flag| flag.set(outer));
        self.owned.publish();
        drop(sampler);
        self.ctx.sample += 1;
        self.ctx.time = self.ctx.time.saturating_add(ctx.period);
    }

    #[cold]
    pub(crate) fn run_boundary_tasks(&mut self) {
        for task in std::mem::take(&mut self.boundary) {
            match task {
                BoundaryTask::Timing(period) => self.set_period(period),
                BoundaryTask::Reset => self.call_all(Routine::Reset),
            }
        }
    }

    /// Sampling begins: startups (list order), then enables (execution order).
    pub(crate) fn start(&mut self) {
        self.ctx.sample = 0;
        self.ctx.time = Duration::ZERO;
        self.sampling = true;
        self.run_boundary_tasks();
        self.call_all(Routine::Startup);
        let ctx = self.ctx;
        for k in 0..self.order.len() {
            self.call(self.order[k], Routine::Enable, &ctx);
        }
    }

    /// Sampling ends: disables (execution order), then shutdowns (list order).
    pub(crate) fn stop(&mut self) {
        if !self.sampling {
            return;
        }
        let ctx = self.ctx;
        for k in 0..self.order.len() {
            self.call(self.order[k], Routine::Disable, &ctx);
        }
        self.call_all(Routine::Shutdown);
        self.sampling = false;
    }

    /// Takes the modules of slots `indices` out of the list, for routines to run on them
    /// without the lock. None of them may be active (the habitat would skip them).
    pub(crate) fn lend(&mut self, indices: &[usize]) -> Vec<Lent> {
        indices
            .iter()
            .filter_map(|&index| {
                debug_assert!(
                    !self.order.contains(&index),
                    "an active module is never lent"
                );
                let module = self.slots[index].module.take()?;
                Some(Lent {
                    index,
                    module,
                    failures: Vec::new(),
                })
            })
            .collect()
    }

    /// Puts lent modules back and counts the failures of what ran on them.
    pub(crate) fn restore(&mut self, lent: Vec<Lent>) {
        for Lent {
            index,
            module,
            failures,
        } in lent
        {
            self.slots[index].module = Some(module);
            for (routine, err) in failures {
                self.note_error(index, routine, &err);
            }
        }
    }

    /// Adopts a prepared switch at this sample boundary: `next_active` says which slots are
    /// active, `order` is their execution order (already sorted). `entering` (lent, enabled)
    /// come back; while sampling, the modules that leave the active set are lent out and
    /// returned, for their `disable` to run without the lock.
    pub(crate) fn swap(
        &mut self,
        next_active: &[bool],
        order: Vec<usize>,
        entering: Vec<Lent>,
    ) -> Vec<Lent> {
        self.restore(entering);
        let leaving: Vec<usize> = self
            .order
            .iter()
            .copied()
            .filter(|&i| !next_active[i])
            .collect();
        for (slot, &active) in self.slots.iter_mut().zip(next_active) {
            slot.active = active;
        }
        self.order = order;
        if !self.sampling {
            return Vec::new();
        }
        self.lend(&leaving)
    }

    /// Adds a module (already built, and if sampling already started and enabled) with its
    /// prepared execution order, counting the failures of the routines run on it before.
    pub(crate) fn install(
        &mut self,
        mut slot: Slot,
        active: bool,
        order: Vec<usize>,
        failures: Vec<(Routine, ModuleError)>,
    ) {
        slot.active = active;
        self.slots.push(slot);
        self.order = order;
        let index = self.slots.len() - 1;
        for (routine, err) in failures {
            self.note_error(index, routine, &err);
        }
    }

    /// Takes slot `index` out of the list (a removal); the caller runs its last routines.
    pub(crate) fn take(&mut self, index: usize) -> Option<(Slot, Box<dyn SampleModule>)> {
        let mut slot = self.slots.remove(index);
        self.order.retain(|&i| i != index);
        for i in &mut self.order {
            if *i > index {
                *i -= 1;
            }
        }
        let module = slot.module.take()?;
        Some((slot, module))
    }

    fn set_period(&mut self, period: Duration) {
        self.ctx.period = period;
        self.call_all(Routine::TimingChanged);
    }

    /// Carries out `task` now (no habitat thread samples), or queues it for the next sample.
    pub(crate) fn at_boundary(&mut self, task: BoundaryTask, now: bool) {
        self.boundary.push(task);
        if now {
            self.run_boundary_tasks();
        }
    }

    /// Unloads every module.
    pub(crate) fn terminate(&mut self) {
        self.stop();
        for slot in &mut self.slots {
            if let Some(module) = slot.module.as_deref_mut() {
                terminate(module);
            }
        }
        self.slots.clear();
        self.order.clear();
        self.owned.release_all();
    }

    /// Names of the active modules in execution order.
    pub(crate) fn order_names(&self) -> Vec<String> {
        self.order
            .iter()
            .map(|&i| self.slots[i].name.clone())
            .collect()
    }

    fn call_all(&mut self, routine: Routine) {
        let ctx = self.ctx;
        for i in 0..self.slots.len() {
            self.call(i, routine, &ctx);
        }
    }

    #[inline]
    fn call(&mut self, i: usize, routine: Routine, ctx: &SampleContext) {
        let Some(module) = self.slots[i].module.as_mut() else {
            return;
        };
        let _sampler = as_sampler(self.owned.id());
        self.owned.take_in();
        let result = run_routine(module.as_mut(), routine, ctx);
        self.owned.publish();
        if let Err(err) = result {
            self.note_error(i, routine, &err);
        }
    }

    #[cold]
    fn note_error(&mut self, i: usize, routine: Routine, err: &ModuleError) {
        let slot = &mut self.slots[i];
        slot.errors += 1;
        self.module_errors += 1;
        if slot.errors == 1 {
            tracing::warn!(module = %slot.name, ?routine, error = %err,
                "module routine failed (counted in the habitat's module_errors; later failures of this module are only counted)");
        }
    }
}

/// Runs one routine of `module`, marked as inside a routine for the thread's duration.
#[inline]
pub(crate) fn run_routine(
    module: &mut dyn SampleModule,
    routine: Routine,
    ctx: &SampleContext,
) -> RoutineResult {
    let outer = IN_ROUTINE.with(|flag| flag.replace(true));
    let result = guarded(|| dispatch(module, routine, ctx));
    IN_ROUTINE.with(|flag| flag.set(outer));
    result
}

#[inline]
fn dispatch(module: &mut dyn SampleModule, routine: Routine, ctx: &SampleContext) -> RoutineResult {
    match routine {
        Routine::Execute => module.execute(ctx),
        Routine::StateUpdate => module.state_update(ctx),
        Routine::Enable => module.enable(ctx),
        Routine::Disable => module.disable(ctx),
        Routine::Startup => module.startup(ctx),
        Routine::Shutdown => module.shutdown(ctx),
        Routine::TimingChanged => module.timing_changed(ctx),
        Routine::Reset => module.reset(ctx),
    }
}

/// Runs `build` (a module's factory) marked as inside a routine: the factory runs while its
/// runtime's structure and database are locked, so what it asks of its runtime or habitat
/// (a rate, a start) must be queued or refused like a routine's request, never carried out.
pub(crate) fn as_routine<T>(build: impl FnOnce() -> T) -> T {
    let outer = IN_ROUTINE.with(|flag| flag.replace(true));
    let result = build();
    IN_ROUTINE.with(|flag| flag.set(outer));
    result
}

/// Unloads a module (`terminate`), a panic in it caught.
pub(crate) fn terminate(module: &mut dyn SampleModule) {
    let outer = IN_ROUTINE.with(|flag| flag.replace(true));
    let _ = guarded(|| {
        module.terminate();
        Ok(())
    });
    IN_ROUTINE.with(|flag| flag.set(outer));
}

/// Runs a routine; a panic becomes an error (counted like any failure) instead of taking the
/// habitat's thread, its lock and every other module down with it.
fn guarded(routine: impl FnOnce() -> RoutineResult) -> RoutineResult {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(routine)).unwrap_or_else(|payload| {
        let text = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a non-string payload".to_owned());
        Err(ModuleError::Failed(format!("panicked: {text}")))
    })
}

impl Drop for ExecList {
    fn drop(&mut self) {
        self.terminate();
    }
}

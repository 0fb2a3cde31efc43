//! The execution list a habitat runs: its installed modules, which of them are active, and the
//! dependency-sorted order of the active ones. Entry routines are called from here only.

use std::time::Duration;

use super::module::{Interface, ModuleError, RoutineResult, SampleContext, SampleModule};
use super::sort::{SortError, SortNode, sort};

/// One installed module.
pub(crate) struct Slot {
    pub(crate) name: String,
    pub(crate) interface: Interface,
    module: Box<dyn SampleModule>,
    pub(crate) active: bool,
    errors: u64,
}

impl Slot {
    pub(crate) fn new(name: String, interface: Interface, module: Box<dyn SampleModule>) -> Self {
        Self {
            name,
            interface,
            module,
            active: false,
            errors: 0,
        }
    }
}

/// Which routine failed (for the log).
#[derive(Clone, Copy, Debug)]
enum Routine {
    Execute,
    StateUpdate,
    Enable,
    Disable,
    Startup,
    Shutdown,
    TimingChanged,
    Reset,
}

/// A habitat's modules. Every method is called with the habitat's list lock held, so routines
/// of one habitat never run concurrently and changes land between two samples.
pub(crate) struct ExecList {
    pub(crate) slots: Vec<Slot>,
    /// Indices of the active slots, in execution order.
    pub(crate) order: Vec<usize>,
    pub(crate) sampling: bool,
    pub(crate) ctx: SampleContext,
    pub(crate) module_errors: u64,
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
        }
    }

    pub(crate) fn position(&self, name: &str) -> Option<usize> {
        self.slots.iter().position(|slot| slot.name == name)
    }

    /// The execution order if `active(i)` said which slots are active.
    pub(crate) fn plan(&self, active: impl Fn(usize) -> bool) -> Result<Vec<usize>, SortError> {
        let members: Vec<usize> = (0..self.slots.len()).filter(|&i| active(i)).collect();
        let nodes: Vec<SortNode<'_>> = members
            .iter()
            .map(|&i| {
                let iface = &self.slots[i].interface;
                SortNode {
                    module: &self.slots[i].name,
                    reads: iface.feedthrough_names().collect(),
                    writes: iface.output_names().collect(),
                }
            })
            .collect();
        Ok(sort(&nodes)?.into_iter().map(|k| members[k]).collect())
    }

    /// Runs one sample: every active module's `execute`, then every `state_update`.
    pub(crate) fn run_sample(&mut self) {
        let ctx = self.ctx;
        for k in 0..self.order.len() {
            let i = self.order[k];
            let module = &mut self.slots[i].module;
            let result = guarded(|| module.execute(&ctx));
            self.check(i, Routine::Execute, result);
        }
        for k in 0..self.order.len() {
            let i = self.order[k];
            let module = &mut self.slots[i].module;
            let result = guarded(|| module.state_update(&ctx));
            self.check(i, Routine::StateUpdate, result);
        }
        self.ctx.sample += 1;
        self.ctx.time = self.ctx.time.saturating_add(ctx.period);
    }

    /// Sampling begins: startups (list order), then enables (execution order).
    pub(crate) fn start(&mut self) {
        self.ctx.sample = 0;
        self.ctx.time = Duration::ZERO;
        self.sampling = true;
        for i in 0..self.slots.len() {
            self.call(i, Routine::Startup);
        }
        for k in 0..self.order.len() {
            self.call(self.order[k], Routine::Enable);
        }
    }

    /// Sampling ends: disables (execution order), then shutdowns (list order).
    pub(crate) fn stop(&mut self) {
        if !self.sampling {
            return;
        }
        for k in 0..self.order.len() {
            self.call(self.order[k], Routine::Disable);
        }
        for i in 0..self.slots.len() {
            self.call(i, Routine::Shutdown);
        }
        self.sampling = false;
    }

    /// First half of a switch: disables the active modules that `next_active` drops.
    pub(crate) fn leave(&mut self, next_active: &[bool]) {
        for k in 0..self.order.len() {
            let i = self.order[k];
            if !next_active[i] && self.sampling {
                self.call(i, Routine::Disable);
            }
        }
    }

    /// Second half: enables the modules that join, in the new order, and adopts it.
    pub(crate) fn enter(&mut self, next_active: &[bool], order: Vec<usize>) {
        for &i in &order {
            if !self.slots[i].active && self.sampling {
                self.call(i, Routine::Enable);
            }
        }
        for (slot, &active) in self.slots.iter_mut().zip(next_active) {
            slot.active = active;
        }
        self.order = order;
    }

    /// Adds a module (already built); `active` says whether it joins the active set.
    pub(crate) fn install(&mut self, slot: Slot, active: bool) -> Result<(), SortError> {
        let n = self.slots.len();
        self.slots.push(slot);
        let order = match self.plan(|i| if i == n { active } else { self.slots[i].active }) {
            Ok(order) => order,
            Err(err) => {
                if let Some(mut slot) = self.slots.pop() {
                    slot.module.terminate();
                }
                return Err(err);
            }
        };
        if self.sampling {
            self.call(n, Routine::Startup);
        }
        let mut next: Vec<bool> = self.slots.iter().map(|s| s.active).collect();
        next[n] = active;
        self.enter(&next, order);
        Ok(())
    }

    /// Removes a module: disable (if active and sampling), shutdown (if sampling), terminate.
    pub(crate) fn remove(&mut self, index: usize) {
        if self.sampling {
            if self.slots[index].active {
                self.call(index, Routine::Disable);
            }
            self.call(index, Routine::Shutdown);
        }
        let mut slot = self.slots.remove(index);
        let _ = guarded(|| {
            slot.module.terminate();
            Ok(())
        });
        self.order.retain(|&i| i != index);
        for i in &mut self.order {
            if *i > index {
                *i -= 1;
            }
        }
    }

    pub(crate) fn set_period(&mut self, period: Duration) {
        self.ctx.period = period;
        for i in 0..self.slots.len() {
            self.call(i, Routine::TimingChanged);
        }
    }

    pub(crate) fn reset(&mut self) {
        for i in 0..self.slots.len() {
            self.call(i, Routine::Reset);
        }
    }

    /// Unloads every module.
    pub(crate) fn terminate(&mut self) {
        self.stop();
        for slot in &mut self.slots {
            let _ = guarded(|| {
                slot.module.terminate();
                Ok(())
            });
        }
        self.slots.clear();
        self.order.clear();
    }

    /// Names of the active modules in execution order.
    pub(crate) fn order_names(&self) -> Vec<String> {
        self.order
            .iter()
            .map(|&i| self.slots[i].name.clone())
            .collect()
    }

    fn call(&mut self, i: usize, routine: Routine) {
        let ctx = self.ctx;
        let module = &mut self.slots[i].module;
        let result = guarded(|| match routine {
            Routine::Execute => module.execute(&ctx),
            Routine::StateUpdate => module.state_update(&ctx),
            Routine::Enable => module.enable(&ctx),
            Routine::Disable => module.disable(&ctx),
            Routine::Startup => module.startup(&ctx),
            Routine::Shutdown => module.shutdown(&ctx),
            Routine::TimingChanged => module.timing_changed(&ctx),
            Routine::Reset => module.reset(&ctx),
        });
        self.check(i, routine, result);
    }

    fn check(&mut self, i: usize, routine: Routine, result: RoutineResult) {
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

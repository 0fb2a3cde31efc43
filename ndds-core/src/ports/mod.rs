//! Port-directed communication (Shin, 1985) without IO: the pieces of the port primitives that
//! are pure logic. So far: [`select`], the priority select over several ports;
//! [`schedule`], a module's work schedule (`perform`, `more`, `reinstate`); [`order`],
//! which of a module's sections may interrupt which; [`usage`], the message direction
//! restriction; and [`module`], module specifications and their load-time check.

pub mod module;
pub mod order;
pub mod schedule;
pub mod select;
pub mod usage;

pub use module::{LoadError, LoadProblem, ModuleSpec, PortDecl, check_system};
pub use order::{Order, OrderError, Sections};
pub use schedule::{Performed, ScheduleError, WorkSchedule};
pub use select::{Full, PrioritySelect, SelectError};
pub use usage::Usage;

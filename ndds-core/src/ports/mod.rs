//! Port-directed communication (Shin, 1985) without IO: the pieces of the port primitives that
//! are pure logic. So far: [`select`], the priority select over several ports, and
//! [`schedule`], a module's work schedule (`perform`, `more`, `reinstate`).

pub mod schedule;
pub mod select;

pub use schedule::{Performed, ScheduleError, WorkSchedule};
pub use select::{Full, PrioritySelect, SelectError};

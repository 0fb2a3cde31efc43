//! Port-directed communication (Shin, 1985) without IO: the pieces of the port primitives that
//! are pure logic. So far: [`select`], the priority select over several ports.

pub mod select;

pub use select::{Full, PrioritySelect, SelectError};

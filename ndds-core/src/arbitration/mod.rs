//! Consumer-side NDDS semantics, without IO: arbitration between redundant producers by
//! strength and persistence, minimum separation, deadlines, and the statuses and notifications
//! they produce. See [`arbiter`] for the rules and the call order.

pub mod arbiter;
pub mod status;

pub use arbiter::{Arbiter, ArbiterStats, Incoming, Output, Rules};
pub use status::{Notification, SampleStatus};

#[cfg(test)]
mod tests;

//! Controllers: PD, PID and LQG as component types, and the two halves of a hand-assembled
//! LQG controller (a steady-state Kalman estimator and state feedback) for Rust code.
//!
//! | type    | module                     | reads                         | writes               |
//! |---------|----------------------------|-------------------------------|----------------------|
//! | `pd`    | [`Pd`](crate::Pd)          | `measured`, `reference`       | `output`             |
//! | `pid`   | [`Pid`](crate::Pid)        | `measured`, `reference`       | `output`             |
//! | `lqg`   | [`Lqg`](crate::Lqg)        | `measured`, `reference`       | `output`, `estimate`? |
//! | —       | [`Estimator`](crate::Estimator) | `measured`, `command` (state) | `estimate`      |
//! | —       | [`StateFeedback`](crate::StateFeedback) | `estimate`, `reference` | `output`       |
//!
//! The gains of the last two come from [`design_lqg`](crate::design_lqg) (or
//! [`dlqr`](crate::dlqr), [`kalman_gain`](crate::kalman_gain) and
//! [`reference_gain`](crate::reference_gain)); `lqg` designs its own at its habitat's rate.

pub(crate) mod estimator;
pub(crate) mod lqg;
pub(crate) mod pd;
pub(crate) mod pid;
pub(crate) mod state_feedback;

use ndds_runtime::Registry;

/// Registers the controllers that have a component type.
pub(crate) fn register(registry: &mut Registry) {
    pd::register(registry);
    pid::register(registry);
    lqg::register(registry);
}

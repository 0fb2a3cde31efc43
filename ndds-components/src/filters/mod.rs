//! Filters and dynamic systems: a first-order low-pass, discrete transfer functions and
//! state-space systems.
//!
//! | type                | module                                          | reads                   | writes   |
//! |---------------------|-------------------------------------------------|-------------------------|----------|
//! | `lowpass`           | [`LowPass`](crate::LowPass)                     | `input`                 | `output` |
//! | `transfer_function` | [`TransferFunction`](crate::TransferFunction)   | `input` (state if b0=0) | `output` |
//! | `state_space`       | [`StateSpace`](crate::StateSpace)               | `input` (state if D=0)  | `output` |
//!
//! A system without direct feedthrough (`b0 = 0`, `D = 0`) reads its input only in
//! `state_update`, so it can close a loop with a controller (a simulated plant). Every state
//! starts from its initial value when sampling begins (`startup`) and on `reset`.

pub(crate) mod lowpass;
pub(crate) mod state_space;
pub(crate) mod transfer_function;

use ndds_runtime::Registry;

/// Registers the filters and dynamic systems.
pub(crate) fn register(registry: &mut Registry) {
    lowpass::register(registry);
    transfer_function::register(registry);
    state_space::register(registry);
}

//! Simulated plants: physical systems to close loops around, each reading its command only in
//! `state_update` (no direct feedthrough), so a controller and its plant can share a habitat.
//!
//! | type                 | module                                         | reads (state) | writes                             |
//! |----------------------|------------------------------------------------|---------------|------------------------------------|
//! | `mass_spring_damper` | [`MassSpringDamper`](crate::MassSpringDamper)  | `force`       | `position`, `angle`                |
//! | `two_link_arm`       | [`TwoLinkArm`](crate::TwoLinkArm)              | `torque`      | `angles`, `endpoint`, `velocities`? |
//!
//! The arm's physics (dynamics, kinematics, linearisation) is [`ArmModel`](crate::ArmModel),
//! in `arm_model.rs`, which `lqg` also uses to linearise it.

pub(crate) mod arm_model;
pub(crate) mod mass_spring_damper;
pub(crate) mod two_link_arm;

use ndds_runtime::Registry;

/// Registers the simulated plants.
pub(crate) fn register(registry: &mut Registry) {
    mass_spring_damper::register(registry);
    two_link_arm::register(registry);
}

//! Design maths, no modules: discretisation, discrete LQR and steady-state Kalman gains, the
//! reference feedforward and a whole LQG design. Components that design their own gains
//! (`lqg`, `mass_spring_damper`) call these; Rust code may call them to give an
//! [`Estimator`](crate::Estimator) and a [`StateFeedback`](crate::StateFeedback) their gains.
//!
//! | file           | holds                                                             |
//! |----------------|-------------------------------------------------------------------|
//! | `discrete.rs`  | [`discretize`] (zero-order hold), `spectral_radius` (stability)   |
//! | `riccati.rs`   | the discrete Riccati iteration, [`dlqr`], [`kalman_gain`]         |
//! | `lqg.rs`       | [`LqgWeights`], [`LqgDesign`], [`design_lqg`], [`reference_gain`] |

mod discrete;
mod lqg;
mod riccati;

pub use discrete::discretize;
pub(crate) use discrete::spectral_radius;
pub use lqg::{LqgDesign, LqgWeights, design_lqg, reference_gain};
pub use riccati::{dlqr, kalman_gain};

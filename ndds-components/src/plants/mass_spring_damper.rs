//! `mass_spring_damper`: a simulated mass on a spring and damper, driven by a force.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::design::discretize;
use crate::params::failed;

/// Physical constants of [`MassSpringDamper`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Physical {
    /// kg.
    pub mass: f64,
    /// N/m.
    pub stiffness: f64,
    /// N·s/m.
    pub damping: f64,
    /// Lever length (m) relating the position to the `angle` output (rad = m / length).
    pub length: f64,
}

impl Physical {
    /// Itself, unless the mass or the length is not positive (a failure of the module, not
    /// of one parameter: description files report it at the component).
    fn checked(self) -> Result<Self, ModuleError> {
        if self.mass > 0.0 && self.length > 0.0 {
            Ok(self)
        } else {
            Err(failed("mass and length must be positive"))
        }
    }

    /// The continuous model `ẋ = A·x + B·u`, `x = [position, velocity]`.
    pub fn model(&self) -> (DMatrix<f64>, DMatrix<f64>) {
        let a = DMatrix::from_row_slice(
            2,
            2,
            &[
                0.0,
                1.0,
                -self.stiffness / self.mass,
                -self.damping / self.mass,
            ],
        );
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0 / self.mass]);
        (a, b)
    }
}

/// Simulated plant m·p̈ = f − c·ṗ − k·p, exact zero-order-hold integration; writes the
/// position and a lever angle (position / length).
///
/// Integrated exactly for a force held over each sample. `execute` writes the position (m)
/// and the lever angle (rad, position / length); `state_update` reads the force and advances
/// the state, so a controller reading the position and writing the force closes a legal
/// loop. `reset` puts it back at rest at 0.
#[derive(Component)]
#[component(name = "mass_spring_damper")]
pub struct MassSpringDamper {
    /// f (N, 1 × 1), read in state_update
    #[input(state, shape = (1, 1))]
    force: Mat,
    /// p (m, 1 × 1)
    #[output(shape = (1, 1))]
    position: Mat,
    /// p / length (rad, 1 × 1)
    #[output(shape = (1, 1))]
    angle: Mat,
    /// m
    #[param(default = 1.0, unit = "kg")]
    _mass: f64,
    /// k
    #[param(default = 4.0, unit = "N/m")]
    _stiffness: f64,
    /// c
    #[param(default = 0.4, unit = "N·s/m")]
    _damping: f64,
    /// lever length
    #[param(default = 0.5, unit = "m")]
    _length: f64,
    #[state(init = Physical {
        mass: _mass,
        stiffness: _stiffness,
        damping: _damping,
        length: _length,
    }
    .checked()?)]
    physical: Physical,
    #[state(init = DMatrix::zeros(2, 1))]
    state: DMatrix<f64>,
    #[state(init = DMatrix::zeros(2, 1))]
    next: DMatrix<f64>,
    #[state(init = DMatrix::identity(2, 2))]
    ad: DMatrix<f64>,
    #[state(init = DMatrix::zeros(2, 1))]
    bd: DMatrix<f64>,
    dt: f64,
}

impl MassSpringDamper {
    /// Reads `force` (1 × 1), writes `position` and `angle` (1 × 1 each).
    pub fn new(
        b: &mut Binder<'_>,
        force: &str,
        position: &str,
        angle: &str,
        physical: Physical,
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("force", force)
            .with("position", position)
            .with("angle", angle)
            .with("mass", physical.mass)
            .with("stiffness", physical.stiffness)
            .with("damping", physical.damping)
            .with("length", physical.length);
        Self::build(b, &params)
    }

    /// Puts the mass at `position` (m), at rest.
    pub fn set_position(&mut self, position: f64) {
        self.state[0] = position;
        self.state[1] = 0.0;
    }

    fn discretize(&mut self, dt: f64) {
        let (a, b) = self.physical.model();
        (self.ad, self.bd) = discretize(&a, &b, dt);
        self.dt = dt;
    }
}

impl SampleModule for MassSpringDamper {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let p = self.state[0];
        self.position.write().set(0, 0, p)?;
        self.angle.write().set(0, 0, p / self.physical.length)?;
        Ok(())
    }

    fn state_update(&mut self, ctx: &SampleContext) -> RoutineResult {
        if self.dt != ctx.dt() {
            self.discretize(ctx.dt());
        }
        let f = self.force.read().get(0, 0)?;
        self.next.gemm(1.0, &self.ad, &self.state, 0.0);
        self.next[0] += self.bd[0] * f;
        self.next[1] += self.bd[1] * f;
        std::mem::swap(&mut self.state, &mut self.next);
        Ok(())
    }

    fn startup(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.discretize(ctx.dt());
        Ok(())
    }

    fn timing_changed(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.discretize(ctx.dt());
        Ok(())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.state.fill(0.0);
        Ok(())
    }
}

/// Registers `mass_spring_damper`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<MassSpringDamper>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use super::{MassSpringDamper, Physical};
    use crate::testing::{TestResult, runtime, trace};

    /// Released from `p0` at rest with no force, it follows the underdamped free response
    /// `p(t) = p0·e^(−ζω·t)·(cos ω_d·t + ζω/ω_d·sin ω_d·t)` exactly at the samples.
    #[test]
    fn set_position_releases_it_into_its_free_response() -> TestResult {
        let physical = Physical {
            mass: 1.0,
            stiffness: 4.0,
            damping: 0.4,
            length: 0.5,
        };
        let rt = runtime(100.0, &[("force", &[0.0])])?;
        rt.install("h", "plant", |b| {
            let mut plant = MassSpringDamper::new(b, "force", "position", "angle", physical)?;
            plant.set_position(0.2);
            Ok(plant)
        })?;
        let out = trace(&rt, &["position", "angle"], 300)?;
        let omega = (physical.stiffness / physical.mass).sqrt();
        let zeta_omega = physical.damping / (2.0 * physical.mass);
        let omega_d = (omega * omega - zeta_omega * zeta_omega).sqrt();
        for (k, (p, angle)) in out[0].iter().zip(&out[1]).enumerate() {
            let t = k as f64 * 0.01;
            let expected = 0.2
                * (-zeta_omega * t).exp()
                * ((omega_d * t).cos() + zeta_omega / omega_d * (omega_d * t).sin());
            assert!(
                (p - expected).abs() < 1e-9,
                "p({t}) = {p}, expected {expected}"
            );
            assert!((angle - p / physical.length).abs() < 1e-12);
        }
        // A reset puts it back at rest at 0.
        rt.habitat("h").reset();
        rt.habitat("h").step()?;
        assert_eq!(rt.mat("position").value(0, 0), 0.0);
        Ok(())
    }

    #[test]
    fn a_mass_that_is_not_positive_is_refused() -> TestResult {
        let rt = runtime(100.0, &[])?;
        let params = Params::new()
            .with("force", "f")
            .with("position", "p")
            .with("angle", "a")
            .with("mass", 0.0);
        let err = crate::testing::refusal(&rt, "mass_spring_damper", &params).to_string();
        assert!(err.contains("mass"), "{err}");
        Ok(())
    }
}

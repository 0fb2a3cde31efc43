//! `mass_spring_damper`: a simulated mass on a spring and damper, driven by a force.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use crate::design::discretize;
use crate::mats::distinct;
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

/// `m·p̈ = f − c·ṗ − k·p`, integrated exactly for a force held over each sample (zero-order
/// hold). `execute` writes the position (m) and the lever angle (rad, position / length);
/// `state_update` reads the force and advances the state, so a controller reading the
/// position and writing the force closes a legal loop. `reset` puts it back at rest at 0.
pub struct MassSpringDamper {
    force: Mat,
    position: Mat,
    angle: Mat,
    physical: Physical,
    state: DMatrix<f64>,
    next: DMatrix<f64>,
    ad: DMatrix<f64>,
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
        distinct(&[force, position, angle])?;
        if !(physical.mass > 0.0 && physical.length > 0.0) {
            return Err(failed("mass and length must be positive"));
        }
        Ok(Self {
            force: b.state_input(force, (1, 1)),
            position: b.output(position, (1, 1)),
            angle: b.output(angle, (1, 1)),
            physical,
            state: DMatrix::zeros(2, 1),
            next: DMatrix::zeros(2, 1),
            ad: DMatrix::identity(2, 2),
            bd: DMatrix::zeros(2, 1),
            dt: 0.0,
        })
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

const MASS_SPRING_DAMPER: ComponentSpec = ComponentSpec {
    name: "mass_spring_damper",
    summary: "Simulated plant m·p̈ = f − c·ṗ − k·p, exact zero-order-hold integration; \
              writes the position and a lever angle (position / length).",
    params: &[
        P::required("force", K::Input, "f (N, 1 × 1), read in state_update"),
        P::required("position", K::Output, "p (m, 1 × 1)"),
        P::required("angle", K::Output, "p / length (rad, 1 × 1)"),
        P::optional("mass", K::Number, "1", "m (kg)"),
        P::optional("stiffness", K::Number, "4", "k (N/m)"),
        P::optional("damping", K::Number, "0.4", "c (N·s/m)"),
        P::optional("length", K::Number, "0.5", "lever length (m)"),
    ],
};

/// Registers `mass_spring_damper`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add_with(&MASS_SPRING_DAMPER, |b, p| {
        MassSpringDamper::new(
            b,
            p.text("force")?,
            p.text("position")?,
            p.text("angle")?,
            Physical {
                mass: p.number_or("mass", 1.0)?,
                stiffness: p.number_or("stiffness", 4.0)?,
                damping: p.number_or("damping", 0.4)?,
                length: p.number_or("length", 0.5)?,
            },
        )
    });
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

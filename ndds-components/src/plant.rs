//! A simulated plant: a mass on a spring and damper, driven by a force.

use nalgebra::DMatrix;

use super::control::discretize;
use super::distinct;
use ndds_runtime::Mat;
use ndds_runtime::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule};

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
            return Err(ModuleError::Failed(
                "mass and length must be positive".into(),
            ));
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

//! The planar two-link arm as a model: [`ArmModel`], its rigid-body dynamics, kinematics and
//! linearisation (the sample module that integrates it is [`TwoLinkArm`](crate::TwoLinkArm)).
//!
//! Both links are uniform rods: link `i` has mass `mᵢ` spread evenly over its length `lᵢ`, so
//! its centre of mass is at `lᵢ/2` and its inertia about that centre is `mᵢ·lᵢ²/12`. Joint
//! angles follow the usual convention: `q1` is link 1's angle from the plane's x axis, `q2`
//! link 2's angle relative to link 1 (counter-clockwise positive). The equations of motion are
//!
//! ```text
//! M(q)·q̈ + C(q, q̇)·q̇ + d·q̇ + g(q) = τ
//!
//! M = [[a1 + a2 + 2·a3·cos q2,  a2 + a3·cos q2],     a1 = m1·l1²/3 + m2·l1²
//!      [a2 + a3·cos q2,         a2            ]]     a2 = m2·l2²/3
//! C·q̇ = a3·sin q2 · [−(2·q̇1·q̇2 + q̇2²), q̇1²]         a3 = m2·l1·l2/2
//! g = G·[(m1·l1/2 + m2·l1)·cos q1 + m2·l2/2·cos(q1+q2), m2·l2/2·cos(q1+q2)]
//! ```
//!
//! with `d` the viscous damping of each joint and `G` the gravity acting along −y (0: the arm
//! moves in a horizontal plane). The endpoint is `x = l1·cos q1 + l2·cos(q1+q2)`,
//! `y = l1·sin q1 + l2·sin(q1+q2)`.

use nalgebra::DMatrix;

use ndds_runtime::{ParamError, Params};

/// The physical constants of a planar two-link arm of uniform rods (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmModel {
    /// Length of link 1 (m).
    pub l1: f64,
    /// Length of link 2 (m).
    pub l2: f64,
    /// Mass of link 1 (kg).
    pub m1: f64,
    /// Mass of link 2 (kg).
    pub m2: f64,
    /// Viscous damping at each joint (N·m·s/rad).
    pub damping: f64,
    /// Gravity along the plane's −y axis (m/s²); 0 for a horizontal plane.
    pub gravity: f64,
}

impl Default for ArmModel {
    /// `l1 = 1`, `l2 = 0.8`, `m1 = 2`, `m2 = 1`, `damping = 0.5`, `gravity = 0` (the
    /// `two_link_arm` defaults).
    fn default() -> Self {
        Self {
            l1: 1.0,
            l2: 0.8,
            m1: 2.0,
            m2: 1.0,
            damping: 0.5,
            gravity: 0.0,
        }
    }
}

/// Solves the 2 × 2 system `m·x = v` (Cramer's rule; `m` is a mass matrix, so invertible).
fn solve2(m: [[f64; 2]; 2], v: [f64; 2]) -> [f64; 2] {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    [
        (m[1][1] * v[0] - m[0][1] * v[1]) / det,
        (m[0][0] * v[1] - m[1][0] * v[0]) / det,
    ]
}

impl ArmModel {
    /// The longest RK4 substep [`integrate`](Self::integrate) takes (s).
    pub const MAX_SUBSTEP: f64 = 1e-3;

    /// Reads `l1`, `l2`, `m1`, `m2`, `damping` and `gravity` from `p`, with the defaults of
    /// [`ArmModel::default`] for those absent, and [checks](Self::check) them.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let d = Self::default();
        let model = Self {
            l1: p.number_or("l1", d.l1)?,
            l2: p.number_or("l2", d.l2)?,
            m1: p.number_or("m1", d.m1)?,
            m2: p.number_or("m2", d.m2)?,
            damping: p.number_or("damping", d.damping)?,
            gravity: p.number_or("gravity", d.gravity)?,
        };
        model.check()?;
        Ok(model)
    }

    /// Lengths and masses must be positive, the damping non-negative, all finite.
    pub fn check(&self) -> Result<(), ParamError> {
        let positive = [
            ("l1", self.l1, "m"),
            ("l2", self.l2, "m"),
            ("m1", self.m1, "kg"),
            ("m2", self.m2, "kg"),
        ];
        for (name, value, unit) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(ParamError {
                    name: name.into(),
                    problem: format!("expected a positive number ({unit}), got {value}"),
                });
            }
        }
        if !(self.damping.is_finite() && self.damping >= 0.0) {
            return Err(ParamError {
                name: "damping".into(),
                problem: format!(
                    "expected a non-negative number (N·m·s/rad), got {}",
                    self.damping
                ),
            });
        }
        if !self.gravity.is_finite() {
            return Err(ParamError {
                name: "gravity".into(),
                problem: format!("expected a finite number (m/s²), got {}", self.gravity),
            });
        }
        Ok(())
    }

    /// The inertia constants `a1`, `a2`, `a3` of the module docs.
    fn inertia(&self) -> (f64, f64, f64) {
        let (l1, l2, m1, m2) = (self.l1, self.l2, self.m1, self.m2);
        (
            m1 * l1 * l1 / 3.0 + m2 * l1 * l1,
            m2 * l2 * l2 / 3.0,
            m2 * l1 * l2 / 2.0,
        )
    }

    /// The mass matrix `M(q)` (kg·m², symmetric positive definite).
    pub fn mass_matrix(&self, q: [f64; 2]) -> [[f64; 2]; 2] {
        let (a1, a2, a3) = self.inertia();
        let c2 = q[1].cos();
        let off = a2 + a3 * c2;
        [[a1 + a2 + 2.0 * a3 * c2, off], [off, a2]]
    }

    /// The Coriolis and centrifugal torques `C(q, q̇)·q̇` (N·m).
    pub fn coriolis(&self, q: [f64; 2], qd: [f64; 2]) -> [f64; 2] {
        let h = self.inertia().2 * q[1].sin();
        [
            -h * (2.0 * qd[0] * qd[1] + qd[1] * qd[1]),
            h * qd[0] * qd[0],
        ]
    }

    /// The gravity torques `g(q)` (N·m): what holds the arm still at `q`.
    pub fn gravity_torque(&self, q: [f64; 2]) -> [f64; 2] {
        let (k1, k2) = self.gravity_moments();
        let (c1, c12) = (q[0].cos(), (q[0] + q[1]).cos());
        [k1 * c1 + k2 * c12, k2 * c12]
    }

    /// `(G·(m1·l1/2 + m2·l1), G·m2·l2/2)`.
    fn gravity_moments(&self) -> (f64, f64) {
        (
            self.gravity * (self.m1 * self.l1 / 2.0 + self.m2 * self.l1),
            self.gravity * self.m2 * self.l2 / 2.0,
        )
    }

    /// The joint accelerations `q̈` (rad/s²) at `state = [q1, q2, q̇1, q̇2]` under `torque`.
    pub fn dynamics(&self, state: [f64; 4], torque: [f64; 2]) -> [f64; 2] {
        let (q, qd) = ([state[0], state[1]], [state[2], state[3]]);
        let c = self.coriolis(q, qd);
        let g = self.gravity_torque(q);
        let rhs = [
            torque[0] - c[0] - self.damping * qd[0] - g[0],
            torque[1] - c[1] - self.damping * qd[1] - g[1],
        ];
        solve2(self.mass_matrix(q), rhs)
    }

    /// The endpoint `[x, y]` (m) at joint angles `q`.
    pub fn forward_kinematics(&self, q: [f64; 2]) -> [f64; 2] {
        let q12 = q[0] + q[1];
        [
            self.l1 * q[0].cos() + self.l2 * q12.cos(),
            self.l1 * q[0].sin() + self.l2 * q12.sin(),
        ]
    }

    /// The endpoint Jacobian `∂[x, y]/∂q` (m/rad), rows x and y; singular at `q2 = 0, π`.
    pub fn jacobian(&self, q: [f64; 2]) -> [[f64; 2]; 2] {
        let q12 = q[0] + q[1];
        let (s1, c1, s12, c12) = (q[0].sin(), q[0].cos(), q12.sin(), q12.cos());
        [
            [-self.l1 * s1 - self.l2 * s12, -self.l2 * s12],
            [self.l1 * c1 + self.l2 * c12, self.l2 * c12],
        ]
    }

    /// Kinetic plus potential energy (J) at `state` (potential 0 at `y = 0`).
    pub fn energy(&self, state: [f64; 4]) -> f64 {
        let (q, qd) = ([state[0], state[1]], [state[2], state[3]]);
        let m = self.mass_matrix(q);
        let kinetic = 0.5
            * (m[0][0] * qd[0] * qd[0] + 2.0 * m[0][1] * qd[0] * qd[1] + m[1][1] * qd[1] * qd[1]);
        let (k1, k2) = self.gravity_moments();
        kinetic + k1 * q[0].sin() + k2 * (q[0] + q[1]).sin()
    }

    /// `ẋ` for `x = [q1, q2, q̇1, q̇2]`.
    fn derivative(&self, x: [f64; 4], torque: [f64; 2]) -> [f64; 4] {
        let acc = self.dynamics(x, torque);
        [x[2], x[3], acc[0], acc[1]]
    }

    /// Advances `state` by `dt` seconds with `torque` held constant: classical RK4 in equal
    /// substeps of at most [`MAX_SUBSTEP`](Self::MAX_SUBSTEP). A `dt` that is not positive changes nothing.
    pub fn integrate(&self, state: [f64; 4], torque: [f64; 2], dt: f64) -> [f64; 4] {
        if !(dt > 0.0 && dt.is_finite()) {
            return state;
        }
        let steps = (dt / Self::MAX_SUBSTEP).ceil().max(1.0) as u64;
        let h = dt / steps as f64;
        let add = |x: [f64; 4], k: [f64; 4], s: f64| std::array::from_fn(|i| x[i] + s * k[i]);
        let mut x = state;
        for _ in 0..steps {
            let k1 = self.derivative(x, torque);
            let k2 = self.derivative(add(x, k1, h / 2.0), torque);
            let k3 = self.derivative(add(x, k2, h / 2.0), torque);
            let k4 = self.derivative(add(x, k3, h), torque);
            x = std::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]));
        }
        x
    }

    /// The continuous-time linearisation `δẋ = A·δx + B·δτ` about rest at `q_op`
    /// (`x = [q1, q2, q̇1, q̇2]`, holding torque `g(q_op)`):
    /// `A = [[0, I], [−M⁻¹·∂g/∂q, −M⁻¹·d]]` (4 × 4), `B = [[0], [M⁻¹]]` (4 × 2). The Coriolis
    /// terms are quadratic in `q̇` and vanish at rest.
    pub fn linearize(&self, q_op: [f64; 2]) -> (DMatrix<f64>, DMatrix<f64>) {
        let m = self.mass_matrix(q_op);
        let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        let inv = [
            [m[1][1] / det, -m[0][1] / det],
            [-m[1][0] / det, m[0][0] / det],
        ];
        let (k1, k2) = self.gravity_moments();
        let (s1, s12) = (q_op[0].sin(), (q_op[0] + q_op[1]).sin());
        let dg = [[-k1 * s1 - k2 * s12, -k2 * s12], [-k2 * s12, -k2 * s12]];
        let mut a = DMatrix::zeros(4, 4);
        let mut b = DMatrix::zeros(4, 2);
        for i in 0..2 {
            a[(i, i + 2)] = 1.0;
            for j in 0..2 {
                let inv_dg = inv[i][0] * dg[0][j] + inv[i][1] * dg[1][j];
                a[(i + 2, j)] = -inv_dg;
                a[(i + 2, j + 2)] = -inv[i][j] * self.damping;
                b[(i + 2, j)] = inv[i][j];
            }
        }
        (a, b)
    }

    /// Reads a pair of joint angles (rad) `name` from `p`, or `default` if absent.
    pub(crate) fn joint_pair(
        p: &Params,
        name: &str,
        default: [f64; 2],
    ) -> Result<[f64; 2], ParamError> {
        Self::pair(name, &p.numbers_or(name, &default)?)
    }

    /// `values` as two finite joint angles, refused under the parameter `name` otherwise.
    pub(crate) fn pair(name: &str, values: &[f64]) -> Result<[f64; 2], ParamError> {
        match values[..] {
            [a, b] if a.is_finite() && b.is_finite() => Ok([a, b]),
            _ => Err(ParamError {
                name: name.into(),
                problem: format!("expected two finite joint angles [q1, q2] (rad), got {values:?}"),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::FRAC_PI_2;

    use nalgebra::DMatrix;

    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn kinetic_energy_is_conserved_without_damping_or_torque() {
        let model = ArmModel {
            damping: 0.0,
            ..ArmModel::default()
        };
        let start = [0.3, 0.6, 1.5, -2.0];
        let e0 = model.energy(start);
        let mut x = start;
        for _ in 0..400 {
            x = model.integrate(x, [0.0; 2], 0.005);
        }
        let drift = (model.energy(x) - e0).abs() / e0;
        assert!(drift < 1e-6, "relative drift {drift:e}");
        assert!(x[2] != start[2], "the arm moved");
    }

    #[test]
    fn total_energy_is_conserved_under_gravity() {
        let model = ArmModel {
            damping: 0.0,
            gravity: 9.81,
            ..ArmModel::default()
        };
        let start = [0.3, 0.6, 0.0, 0.0];
        let e0 = model.energy(start);
        let x = model.integrate(start, [0.0; 2], 2.0);
        let drift = (model.energy(x) - e0).abs() / model.energy([0.3, 0.6, 1.0, 1.0]).abs();
        assert!(drift < 1e-6, "relative drift {drift:e}");
        assert!(x[0] < 0.0, "it fell: {x:?}");
    }

    #[test]
    fn damping_dissipates() {
        let model = ArmModel::default();
        let start = [0.3, 0.6, 1.5, -2.0];
        let x = model.integrate(start, [0.0; 2], 2.0);
        assert!(model.energy(x) < 0.9 * model.energy(start));
    }

    #[test]
    fn forward_kinematics_at_known_angles() {
        let model = ArmModel::default();
        let [x, y] = model.forward_kinematics([0.0, FRAC_PI_2]);
        assert!(close(x, 1.0, 1e-12) && close(y, 0.8, 1e-12), "({x}, {y})");
        let [x, y] = model.forward_kinematics([0.0, 0.0]);
        assert!(close(x, 1.8, 1e-12) && close(y, 0.0, 1e-12), "({x}, {y})");
        let [x, y] = model.forward_kinematics([FRAC_PI_2, 0.0]);
        assert!(close(x, 0.0, 1e-12) && close(y, 1.8, 1e-12), "({x}, {y})");
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let model = ArmModel::default();
        let q = [0.4, 1.1];
        let j = model.jacobian(q);
        let h = 1e-6;
        for col in 0..2 {
            let mut plus = q;
            let mut minus = q;
            plus[col] += h;
            minus[col] -= h;
            let (p, m) = (
                model.forward_kinematics(plus),
                model.forward_kinematics(minus),
            );
            for row in 0..2 {
                let fd = (p[row] - m[row]) / (2.0 * h);
                assert!(close(j[row][col], fd, 1e-8), "J[{row}][{col}]");
            }
        }
    }

    #[test]
    fn mass_matrix_matches_hand_computation() {
        // l1 = 1, l2 = 0.8, m1 = 2, m2 = 1: a1 = 2/3 + 1, a2 = 0.64/3, a3 = 0.4.
        let model = ArmModel::default();
        let straight = model.mass_matrix([0.7, 0.0]);
        let (m11, m12, m22) = (2.68, 0.64 / 3.0 + 0.4, 0.64 / 3.0);
        assert!(close(straight[0][0], m11, 1e-12), "{straight:?}");
        assert!(close(straight[0][1], m12, 1e-12), "{straight:?}");
        assert!(close(straight[1][1], m22, 1e-12), "{straight:?}");
        let bent = model.mass_matrix([0.7, FRAC_PI_2]);
        assert!(close(bent[0][0], 1.88, 1e-12), "{bent:?}");
        assert!(close(bent[0][1], 0.64 / 3.0, 1e-12), "{bent:?}");
        assert!(close(bent[1][1], 0.64 / 3.0, 1e-12), "{bent:?}");
        for k in 0..64 {
            let m = model.mass_matrix([0.0, f64::from(k) * 0.1]);
            assert_eq!(m[0][1], m[1][0]);
            assert!(m[0][0] > 0.0 && m[0][0] * m[1][1] - m[0][1] * m[1][0] > 0.0);
        }
    }

    #[test]
    fn linearization_matches_finite_differences() {
        let model = ArmModel {
            gravity: 9.81,
            ..ArmModel::default()
        };
        let q_op = [0.5, 1.0];
        let (a, b) = model.linearize(q_op);
        let hold = model.gravity_torque(q_op);
        let rest = [q_op[0], q_op[1], 0.0, 0.0];
        let accel = model.dynamics(rest, hold);
        assert!(accel.iter().all(|a| a.abs() < 1e-12), "g(q) holds it");
        let h = 1e-6;
        for j in 0..4 {
            let (mut plus, mut minus) = (rest, rest);
            plus[j] += h;
            minus[j] -= h;
            let (p, m) = (model.dynamics(plus, hold), model.dynamics(minus, hold));
            for i in 0..2 {
                let fd = (p[i] - m[i]) / (2.0 * h);
                assert!(close(a[(i + 2, j)], fd, 1e-6), "A[{}][{j}]", i + 2);
            }
        }
        for j in 0..2 {
            let (mut plus, mut minus) = (hold, hold);
            plus[j] += h;
            minus[j] -= h;
            let (p, m) = (model.dynamics(rest, plus), model.dynamics(rest, minus));
            for i in 0..2 {
                let fd = (p[i] - m[i]) / (2.0 * h);
                assert!(close(b[(i + 2, j)], fd, 1e-6), "B[{}][{j}]", i + 2);
            }
        }
        assert_eq!(
            a.view((0, 0), (2, 4)),
            DMatrix::from_row_slice(2, 4, &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0])
        );
        assert!(b.view((0, 0), (2, 2)).iter().all(|x| *x == 0.0));
    }
}

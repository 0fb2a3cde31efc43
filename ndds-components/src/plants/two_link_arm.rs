//! `two_link_arm`: a simulated planar two-link arm (the model is [`ArmModel`]).

use ndds_runtime::csmat::CsMat;
use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::ArmModel;
use crate::params::failed;

/// Simulated planar two-link arm of uniform rods, M(q)·q̈ + C(q,q̇)·q̇ + d·q̇ + g(q) = τ,
/// integrated with RK4 in ≤ 1 ms substeps, the torque held over each sample; writes the joint
/// angles, the endpoint and optionally the joint velocities.
///
/// The model is [`ArmModel`]. `execute` writes the joint angles (rad), the endpoint (m) and,
/// if asked for, the joint velocities (rad/s), each 2 × 1 with field names and units;
/// `state_update` reads the torque (N·m, 2 × 1) and integrates over the sample period with
/// [`ArmModel::integrate`], so a controller reading the arm's outputs and writing its torque
/// closes a legal loop. Enabling it publishes its current state at once (so controllers
/// enabled after it start from the real measurement); `reset` puts it back at rest at `q0`.
#[derive(Component)]
#[component(name = "two_link_arm")]
pub struct TwoLinkArm {
    #[state(init = arm_model([_l1, _l2, _m1, _m2], _damping, _gravity)?)]
    model: ArmModel,
    #[state(init = ArmModel::pair("q0", &_q0)?)]
    q0: [f64; 2],
    /// τ (N·m, 2 × 1), read in state_update
    #[input(state, shape = (2, 1))]
    torque: Mat,
    /// q (rad, 2 × 1): q1 from the x axis, q2 relative to link 1
    #[output(like = pair(q0, [("q1", "rad"), ("q2", "rad")])?)]
    angles: Mat,
    /// tip position [x, y] (m, 2 × 1)
    #[output(like = pair(model.forward_kinematics(q0), [("x", "m"), ("y", "m")])?)]
    endpoint: Mat,
    /// q̇ (rad/s, 2 × 1)
    #[output(like = pair([0.0; 2], [("q1dot", "rad/s"), ("q2dot", "rad/s")])?)]
    velocities: Option<Mat>,
    /// length of link 1
    #[param(default = 1.0, unit = "m", above = 0)]
    _l1: f64,
    /// length of link 2
    #[param(default = 0.8, unit = "m", above = 0)]
    _l2: f64,
    /// mass of link 1, a uniform rod
    #[param(default = 2.0, unit = "kg", above = 0)]
    _m1: f64,
    /// mass of link 2, a uniform rod
    #[param(default = 1.0, unit = "kg", above = 0)]
    _m2: f64,
    /// viscous damping at each joint (≥ 0)
    #[param(default = 0.5, unit = "N·m·s/rad")]
    _damping: f64,
    /// gravity along the plane's −y axis; 0: a horizontal plane
    #[param(default = 0.0, unit = "m/s²")]
    _gravity: f64,
    /// initial joint angles [q1, q2], at rest
    #[param(default = vec![0.3, 0.6], default_doc = "[0.3, 0.6]", unit = "rad")]
    _q0: Vec<f64>,
    #[state(init = [q0[0], q0[1], 0.0, 0.0])]
    state: [f64; 4],
    active: bool,
}

/// The arm of these constants, checked.
fn arm_model(
    [l1, l2, m1, m2]: [f64; 4],
    damping: f64,
    gravity: f64,
) -> Result<ArmModel, ModuleError> {
    let model = ArmModel {
        l1,
        l2,
        m1,
        m2,
        damping,
        gravity,
    };
    model.check()?;
    Ok(model)
}

/// A 2 × 1 template with field names and units (its name is the output's once bound).
fn pair(values: [f64; 2], fields: [(&str, &str); 2]) -> Result<CsMat, ModuleError> {
    Ok(CsMat::from_row_slice("pair", 2, 1, &values)?.with_row_fields(fields)?)
}

impl TwoLinkArm {
    /// Reads `torque`; writes `angles`, `endpoint` and `velocities` (if given). Starts at rest
    /// at `q0` (rad).
    pub fn new(
        b: &mut Binder<'_>,
        torque: &str,
        angles: &str,
        endpoint: &str,
        velocities: Option<&str>,
        model: ArmModel,
        q0: [f64; 2],
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("torque", torque)
            .with("angles", angles)
            .with("endpoint", endpoint)
            .with("l1", model.l1)
            .with("l2", model.l2)
            .with("m1", model.m1)
            .with("m2", model.m2)
            .with("damping", model.damping)
            .with("gravity", model.gravity)
            .with("q0", q0.to_vec());
        let params = match velocities {
            Some(velocities) => params.with("velocities", velocities),
            None => params,
        };
        Self::build(b, &params)
    }

    /// The state `[q1, q2, q̇1, q̇2]` (rad, rad/s).
    pub fn state(&self) -> [f64; 4] {
        self.state
    }

    /// Sets the state `[q1, q2, q̇1, q̇2]` (rad, rad/s).
    pub fn set_state(&mut self, state: [f64; 4]) {
        self.state = state;
    }

    /// Its physical constants.
    pub fn model(&self) -> &ArmModel {
        &self.model
    }

    fn publish(&self) -> RoutineResult {
        let q = [self.state[0], self.state[1]];
        write_pair(&self.angles, q)?;
        write_pair(&self.endpoint, self.model.forward_kinematics(q))?;
        if let Some(velocities) = &self.velocities {
            write_pair(velocities, [self.state[2], self.state[3]])?;
        }
        Ok(())
    }
}

/// Writes a 2 × 1 CSMat (one guard, released on return).
fn write_pair(mat: &Mat, values: [f64; 2]) -> RoutineResult {
    let mut out = mat.write();
    out.set(0, 0, values[0])?;
    out.set(1, 0, values[1])?;
    Ok(())
}

impl SampleModule for TwoLinkArm {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        self.publish()
    }

    fn state_update(&mut self, ctx: &SampleContext) -> RoutineResult {
        let tau = {
            let t = self.torque.read();
            [t.get(0, 0)?, t.get(1, 0)?]
        };
        if !(tau[0].is_finite() && tau[1].is_finite()) {
            return Err(failed(format!(
                "torque `{}` is not finite: {tau:?} (the arm holds its state)",
                self.torque.name()
            )));
        }
        self.state = self.model.integrate(self.state, tau, ctx.dt());
        Ok(())
    }

    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        self.active = true;
        self.publish()
    }

    fn disable(&mut self, _: &SampleContext) -> RoutineResult {
        self.active = false;
        Ok(())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.state = [self.q0[0], self.q0[1], 0.0, 0.0];
        if self.active {
            self.publish()?;
        }
        Ok(())
    }
}

/// Registers `two_link_arm`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<TwoLinkArm>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::{CsMat, Params};

    use super::TwoLinkArm;
    use crate::ArmModel;
    use crate::testing::{TestResult, assert_refuses, refusal, runtime};

    #[test]
    fn bad_parameters_are_refused_by_name() -> TestResult {
        let rt = runtime(200.0, &[])?;
        let base = Params::new()
            .with("torque", "torque")
            .with("angles", "angles")
            .with("endpoint", "endpoint");
        for (params, name, says) in [
            (base.clone().with("l2", -1.0), "l2", "positive"),
            (
                base.clone().with("damping", -0.1),
                "damping",
                "non-negative",
            ),
            (base.clone().with("gravity", f64::NAN), "gravity", "finite"),
            (
                base.clone().with("q0", vec![0.1, 0.2, 0.3]),
                "q0",
                "two finite",
            ),
        ] {
            assert_refuses(&refusal(&rt, "two_link_arm", &params), name, &[says]);
        }
        let err = refusal(&rt, "two_link_arm", &base.with("endpoint", "angles")).to_string();
        assert!(err.contains("`angles`") && err.contains("twice"), "{err}");
        Ok(())
    }

    /// Sampling continues from the state set before the arm is installed: the first sample
    /// publishes it, the next one the state integrated from it over one period.
    #[test]
    fn set_state_is_where_sampling_continues_from() -> TestResult {
        let rt = runtime(200.0, &[("torque", &[0.0, 0.0])])?;
        let model = ArmModel::default();
        let start = [0.1, 0.2, 1.0, -1.5];
        rt.install("h", "arm", |b| {
            let mut arm = TwoLinkArm::new(
                b,
                "torque",
                "angles",
                "endpoint",
                Some("velocities"),
                model,
                [0.3, 0.6],
            )?;
            arm.set_state(start);
            assert_eq!(arm.state(), start);
            Ok(arm)
        })?;
        let out = {
            let h = rt.habitat("h");
            h.start()?;
            let mut out = Vec::new();
            for _ in 0..2 {
                h.step()?;
                let (angles, velocities) = (rt.mat("angles"), rt.mat("velocities"));
                out.push([
                    angles.value(0, 0),
                    angles.value(1, 0),
                    velocities.value(0, 0),
                    velocities.value(1, 0),
                ]);
            }
            out
        };
        assert_eq!(out[0], start);
        let next = model.integrate(start, [0.0; 2], 1.0 / 200.0);
        for (got, want) in out[1].iter().zip(next) {
            assert!((got - want).abs() < 1e-12, "{:?} vs {next:?}", out[1]);
        }
        let tip = model.forward_kinematics([next[0], next[1]]);
        assert!((rt.mat("endpoint").value(0, 0) - tip[0]).abs() < 1e-12);
        Ok(())
    }

    #[test]
    fn pd_on_the_joint_angles_reaches_its_reference() {
        let rt = runtime(200.0, &[]).unwrap();
        let goal = [0.5, 0.9];
        rt.create_mat(CsMat::from_row_slice("reference", 2, 1, &goal).unwrap())
            .unwrap();
        let arm = Params::new()
            .with("torque", "torque")
            .with("angles", "angles")
            .with("endpoint", "endpoint")
            .with("velocities", "velocities");
        rt.install_component("h", "arm", "two_link_arm", &arm)
            .unwrap();
        let pd = Params::new()
            .with("measured", "angles")
            .with("reference", "reference")
            .with("output", "torque")
            .with("kp", 50.0)
            .with("kd", 10.0);
        rt.install_component("h", "pd", "pd", &pd).unwrap();
        let angles = rt.mat("angles");
        assert_eq!(angles.read().row_fields()[1].unit, "rad");
        assert_eq!(angles.value(0, 0), 0.3, "starts at q0");
        let habitat = rt.habitat("h");
        habitat.start().unwrap();
        let mut settled = None;
        for k in 0..1000 {
            habitat.step().unwrap();
            let error = (0..2)
                .map(|i| (angles.value(i, 0) - goal[i]).abs())
                .fold(0.0, f64::max);
            match (error < 1e-3, settled) {
                (true, None) => settled = Some(k),
                (false, _) => settled = None,
                _ => {}
            }
        }
        habitat.stop();
        let settled = settled.expect("within 1e-3 rad after 5 s") as f64 / 200.0;
        assert!(settled < 4.0, "settled at {settled} s");
        assert!(rt.mat("velocities").value(0, 0).abs() < 1e-3);
        assert_eq!(habitat.stats_total().module_errors, 0);
        eprintln!("pd on the arm: |q − r| < 1e-3 rad from {settled:.3} s");
    }
}

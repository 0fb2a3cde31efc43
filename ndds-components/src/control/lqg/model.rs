//! The model an `lqg` is designed on: explicit matrices, or a library plant linearised about
//! an operating point, read from the component's parameters and checked.

use nalgebra::DMatrix;

use ndds_runtime::{ModuleError, Params};

use crate::params::{all_finite, in_table};
use crate::{ArmModel, Physical};

/// What an LQG controller of a `mass_spring_damper` measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MassOutput {
    /// The position `p` (m): `C = [1, 0]`.
    Position,
    /// The lever angle `p / length` (rad): `C = [1/length, 0]`.
    Angle,
}

/// What an LQG controller of a `two_link_arm` measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArmOutput {
    /// The joint angles (rad): `C = [I, 0]`, `y0 = at`.
    Angles,
    /// The endpoint (m): `C = [J(at), 0]` (the Jacobian), `y0 = FK(at)`.
    Endpoint,
}

/// The model an [`Lqg`](crate::Lqg) is designed on.
#[derive(Clone, Debug, PartialEq)]
pub enum LqgModel {
    /// `ẋ = a·x + b·u`, `y = c·x` (a n × n, b n × m, c p × n), operating point 0.
    Explicit {
        /// A (n × n).
        a: DMatrix<f64>,
        /// B (n × m).
        b: DMatrix<f64>,
        /// C (p × n).
        c: DMatrix<f64>,
    },
    /// A [`MassSpringDamper`](crate::MassSpringDamper) (`x = [p, ṗ]`, `u` = force), exactly
    /// linear, operating point 0.
    MassSpringDamper {
        /// Its constants.
        physical: Physical,
        /// What is measured.
        output: MassOutput,
    },
    /// A [`TwoLinkArm`](crate::TwoLinkArm) linearised about rest at `at`
    /// (`δx = [q − at, q̇]`, `u0 = g(at)`, the gravity torque: 0 in a horizontal plane).
    TwoLinkArm {
        /// Its constants.
        model: ArmModel,
        /// The operating point (rad); for `Endpoint`, not singular (`q2 ≠ 0, π`).
        at: [f64; 2],
        /// What is measured.
        output: ArmOutput,
    },
}

/// A model linearised: `(A, B, C)` and the operating point `(y0, u0)`.
pub(super) struct Linear {
    pub(super) a: DMatrix<f64>,
    pub(super) b: DMatrix<f64>,
    pub(super) c: DMatrix<f64>,
    pub(super) y0: DMatrix<f64>,
    pub(super) u0: DMatrix<f64>,
}

impl Linear {
    /// `(n, m, p)`: states, commands, measurements.
    pub(super) fn dims(&self) -> (usize, usize, usize) {
        (self.a.nrows(), self.b.ncols(), self.c.nrows())
    }
}

/// A failure of the key `err.name` of the table parameter `plant`.
fn plant_error(err: ndds_runtime::ParamError) -> ModuleError {
    in_table("plant", err)
}

impl LqgModel {
    /// States (and commands, measurements) a model has at most: the design iterates a
    /// Riccati equation when the component is built.
    pub const MAX_STATES: usize = 16;

    /// The model of an `lqg` component's parameters: `a`, `b` and `c`, or `plant` (a table
    /// with `type = "mass_spring_damper"` or `"two_link_arm"`; see the `lqg` component in
    /// docs/components.md).
    pub fn from_params(p: &Params) -> Result<Self, ModuleError> {
        let matrix = |key: &str| p.has(key).then(|| p.matrix(key)).transpose();
        let table = p.has("plant").then(|| p.table("plant")).transpose()?;
        let (a, b, c) = (matrix("a")?, matrix("b")?, matrix("c")?);
        Self::from_parts(table, [a.as_ref(), b.as_ref(), c.as_ref()])
    }

    /// The parameters of an `lqg` component that give this model (`from_params` reads it
    /// back): `a`, `b` and `c`, or the table `plant`.
    pub(super) fn params(&self) -> Params {
        match self {
            LqgModel::Explicit { a, b, c } => Params::new()
                .with("a", a.clone())
                .with("b", b.clone())
                .with("c", c.clone()),
            LqgModel::MassSpringDamper { physical, output } => {
                let output = match output {
                    MassOutput::Position => "position",
                    MassOutput::Angle => "angle",
                };
                let plant = Params::new()
                    .with("type", "mass_spring_damper")
                    .with("mass", physical.mass)
                    .with("stiffness", physical.stiffness)
                    .with("damping", physical.damping)
                    .with("length", physical.length)
                    .with("output", output);
                Params::new().with("plant", plant)
            }
            LqgModel::TwoLinkArm { model, at, output } => {
                let output = match output {
                    ArmOutput::Angles => "angles",
                    ArmOutput::Endpoint => "endpoint",
                };
                let plant = Params::new()
                    .with("type", "two_link_arm")
                    .with("l1", model.l1)
                    .with("l2", model.l2)
                    .with("m1", model.m1)
                    .with("m2", model.m2)
                    .with("damping", model.damping)
                    .with("gravity", model.gravity)
                    .with("at", at.to_vec())
                    .with("output", output);
                Params::new().with("plant", plant)
            }
        }
    }

    /// The model of `plant` or of the matrices `[a, b, c]`, whichever is given (one, not
    /// both; all three matrices or none).
    pub(super) fn from_parts(
        plant: Option<&Params>,
        abc: [Option<&DMatrix<f64>>; 3],
    ) -> Result<Self, ModuleError> {
        let keys = ["a", "b", "c"];
        let given: Vec<&str> = keys
            .into_iter()
            .zip(abc)
            .filter_map(|(k, m)| m.map(|_| k))
            .collect();
        match (plant, abc) {
            (Some(plant), [None, None, None]) => Self::from_plant(plant),
            (None, [Some(a), Some(b), Some(c)]) => Ok(LqgModel::Explicit {
                a: a.clone(),
                b: b.clone(),
                c: c.clone(),
            }),
            (Some(_), _) => Err(ModuleError::param(
                "plant",
                format!(
                    "give either `plant` or `a`, `b`, `c`, not both (also given: {})",
                    given.join(", ")
                ),
            )),
            (None, [None, None, None]) => Err(ModuleError::param(
                "plant",
                "missing: give `plant` (a table naming a library plant) or the matrices `a`, \
                 `b` and `c`",
            )),
            (None, _) => {
                let missing = keys.into_iter().find(|k| !given.contains(k));
                Err(ModuleError::param(
                    missing.unwrap_or("a"),
                    format!(
                        "missing: `a`, `b` and `c` go together, all three are needed (only {} \
                         given)",
                        given.join(", ")
                    ),
                ))
            }
        }
    }

    fn from_plant(t: &Params) -> Result<Self, ModuleError> {
        let kind = t.text("type").map_err(plant_error)?;
        let known: &[&str] = match kind {
            "mass_spring_damper" => &["type", "mass", "stiffness", "damping", "length", "output"],
            "two_link_arm" => &[
                "type", "l1", "l2", "m1", "m2", "damping", "gravity", "at", "output",
            ],
            other => {
                return Err(ModuleError::param(
                    "plant.type",
                    format!("unknown plant `{other}` (known: mass_spring_damper, two_link_arm)"),
                ));
            }
        };
        if let Some(extra) = t.0.keys().find(|k| !known.contains(&k.as_str())) {
            return Err(ModuleError::param(
                format!("plant.{extra}"),
                format!(
                    "not a parameter of a `{kind}` plant (known: {})",
                    known.join(", ")
                ),
            ));
        }
        if kind == "mass_spring_damper" {
            Self::mass_spring_damper(t)
        } else {
            Self::two_link_arm(t)
        }
    }

    fn mass_spring_damper(t: &Params) -> Result<Self, ModuleError> {
        let output = match t.text_or("output", "position").map_err(plant_error)? {
            "position" => MassOutput::Position,
            "angle" => MassOutput::Angle,
            other => {
                return Err(ModuleError::param(
                    "plant.output",
                    format!("expected \"position\" or \"angle\", got \"{other}\""),
                ));
            }
        };
        let physical = Physical {
            mass: t.number_or("mass", 1.0).map_err(plant_error)?,
            stiffness: t.number_or("stiffness", 4.0).map_err(plant_error)?,
            damping: t.number_or("damping", 0.4).map_err(plant_error)?,
            length: t.number_or("length", 0.5).map_err(plant_error)?,
        };
        Ok(LqgModel::MassSpringDamper { physical, output })
    }

    fn two_link_arm(t: &Params) -> Result<Self, ModuleError> {
        let output = match t.text_or("output", "angles").map_err(plant_error)? {
            "angles" => ArmOutput::Angles,
            "endpoint" => ArmOutput::Endpoint,
            other => {
                return Err(ModuleError::param(
                    "plant.output",
                    format!("expected \"angles\" or \"endpoint\", got \"{other}\""),
                ));
            }
        };
        if !t.has("at") {
            return Err(ModuleError::param(
                "plant.at",
                "missing (the operating point [q1, q2] in rad)",
            ));
        }
        Ok(LqgModel::TwoLinkArm {
            model: ArmModel::from_params(t).map_err(plant_error)?,
            at: ArmModel::joint_pair(t, "at", [0.0; 2]).map_err(plant_error)?,
            output,
        })
    }

    /// `(n, m, p)`: the numbers of states, commands and measurements, once the model checks.
    pub fn dimensions(&self) -> Result<(usize, usize, usize), ModuleError> {
        Ok(self.linear()?.dims())
    }

    /// Checks the model and linearises it.
    pub(super) fn linear(&self) -> Result<Linear, ModuleError> {
        match self {
            LqgModel::Explicit { a, b, c } => explicit(a, b, c),
            LqgModel::MassSpringDamper { physical, output } => {
                mass_spring_damper_linear(physical, *output)
            }
            LqgModel::TwoLinkArm { model, at, output } => arm_linear(model, *at, *output),
        }
    }
}

fn explicit(a: &DMatrix<f64>, b: &DMatrix<f64>, c: &DMatrix<f64>) -> Result<Linear, ModuleError> {
    let n = a.nrows();
    let dims = |name: &str, m: &DMatrix<f64>, expected: String| {
        ModuleError::param(
            name,
            format!("expected {expected}, got {} × {}", m.nrows(), m.ncols()),
        )
    };
    if n == 0 || a.ncols() != n {
        return Err(dims("a", a, "a square matrix (n × n, n ≥ 1)".into()));
    }
    let max = LqgModel::MAX_STATES;
    if n > max || b.ncols() > max || c.nrows() > max {
        return Err(ModuleError::param(
            "a",
            format!(
                "at most {max} states, commands and measurements (the design iterates a \
                 Riccati equation at load time)"
            ),
        ));
    }
    if b.nrows() != n || b.ncols() == 0 {
        return Err(dims("b", b, format!("{n} rows (n × m, `a` is {n} × {n})")));
    }
    if c.ncols() != n || c.nrows() == 0 {
        return Err(dims(
            "c",
            c,
            format!("{n} columns (p × n, `a` is {n} × {n})"),
        ));
    }
    for (name, m) in [("a", a), ("b", b), ("c", c)] {
        all_finite(name, m.as_slice())?;
    }
    Ok(Linear {
        a: a.clone(),
        b: b.clone(),
        c: c.clone(),
        y0: DMatrix::zeros(c.nrows(), 1),
        u0: DMatrix::zeros(b.ncols(), 1),
    })
}

fn mass_spring_damper_linear(ph: &Physical, output: MassOutput) -> Result<Linear, ModuleError> {
    let ok = ph.mass.is_finite() && ph.mass > 0.0 && ph.length.is_finite();
    if !(ok && ph.length > 0.0 && ph.stiffness.is_finite() && ph.damping.is_finite()) {
        return Err(ModuleError::param(
            "plant",
            format!("mass and length must be positive, stiffness and damping finite; got {ph:?}"),
        ));
    }
    let (a, b) = ph.model();
    let scale = match output {
        MassOutput::Position => 1.0,
        MassOutput::Angle => 1.0 / ph.length,
    };
    Ok(Linear {
        a,
        b,
        c: DMatrix::from_row_slice(1, 2, &[scale, 0.0]),
        y0: DMatrix::zeros(1, 1),
        u0: DMatrix::zeros(1, 1),
    })
}

fn arm_linear(model: &ArmModel, at: [f64; 2], output: ArmOutput) -> Result<Linear, ModuleError> {
    model.check().map_err(plant_error)?;
    if !(at[0].is_finite() && at[1].is_finite()) {
        return Err(ModuleError::param(
            "plant.at",
            format!("expected finite angles (rad), got {at:?}"),
        ));
    }
    let (a, b) = model.linearize(at);
    let mut c = DMatrix::zeros(2, 4);
    let y0 = match output {
        ArmOutput::Angles => {
            c[(0, 0)] = 1.0;
            c[(1, 1)] = 1.0;
            at
        }
        ArmOutput::Endpoint => {
            let j = model.jacobian(at);
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            if det.abs() < 1e-6 * model.l1 * model.l2 {
                return Err(ModuleError::param(
                    "plant.at",
                    format!(
                        "the arm is singular at {at:?} (q2 = 0 or π): the endpoint does not \
                         determine the joint angles there"
                    ),
                ));
            }
            for (i, row) in j.iter().enumerate() {
                c[(i, 0)] = row[0];
                c[(i, 1)] = row[1];
            }
            model.forward_kinematics(at)
        }
    };
    Ok(Linear {
        a,
        b,
        c,
        y0: DMatrix::from_column_slice(2, 1, &y0),
        u0: DMatrix::from_column_slice(2, 1, &model.gravity_torque(at)),
    })
}

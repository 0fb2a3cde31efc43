//! The files `ndds new` writes. Placeholders: `{crate}` (the crate's name), `{type}` (the
//! component type's name in description files), `{Type}` (the Rust struct), `{ndds}` (the ndds
//! checkout the crate depends on, as a TOML string's content).

/// The component crate's manifest.
pub const CARGO_TOML: &str = r#"[package]
name = "{crate}"
version = "0.1.0"
edition = "2024"
publish = false

# A workspace of its own, wherever it is made.
[workspace]

[dependencies]
# `ndds run` as a library (`run_main`): the built-in components, the live status, Ctrl-C.
ndds-cli = { path = "{ndds}/ndds-cli" }
# `#[derive(Component)]`, CSMats, habitats.
ndds-runtime = { path = "{ndds}/ndds-runtime" }
"#;

/// The component, with its known-answer test.
pub const LIB_RS: &str = r#"//! `{type}`: a component type of its own, for `ndds run`-style systems (see README.md).

use ndds_runtime::nalgebra::DMatrix;
use ndds_runtime::{Component, Mat, RoutineResult, SampleContext, SampleModule};

/// First-order low-pass filter: y ← y + a·(u − y), a = dt/(tau + dt), element by element.
#[derive(Component)]
#[component(name = "{type}")]
pub struct {Type} {
    /// u, any shape
    #[input]
    input: Mat,
    /// y, the shape of u
    #[output(same_as = input)]
    output: Mat,
    /// time constant (a 1 × 1 CSMat `<module>.tau`, tunable while it runs)
    #[param(tunable, default = 0.1, unit = "s", min = 0.0)]
    tau: Mat,
    /// the filter's state (not a parameter: no attribute)
    y: DMatrix<f64>,
    /// whether `y` holds a value yet
    primed: bool,
}

impl SampleModule for {Type} {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let tau = self.tau.value(0, 0);
        let a = ctx.dt() / (tau + ctx.dt());
        let u = self.input.read();
        if !self.primed || self.y.shape() != u.shape() {
            // The first sample (and after a reset) starts from the input: no jump.
            self.y = u.matrix().clone();
            self.primed = true;
        } else {
            self.y.zip_apply(u.matrix(), |y, u| *y += a * (u - *y));
        }
        drop(u);
        self.output.write().matrix_mut().copy_from(&self.y);
        Ok(())
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.primed = false;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndds_runtime::{Clock, CsMat, HabitatOptions, Params, Registry, Runtime};

    #[test]
    fn a_step_approaches_its_value_by_the_known_factor() -> Result<(), Box<dyn std::error::Error>> {
        let rt = Runtime::new("test");
        let mut library = Registry::empty();
        library.add::<{Type}>();
        rt.add_library(library);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        rt.create_mat(CsMat::from_row_slice("u", 1, 1, &[0.0])?)?;
        let params = Params::new().with("input", "u").with("output", "y").with("tau", 0.09);
        rt.install_component("h", "f", "{type}", &params)?;
        let h = rt.habitat("h");
        h.start()?;
        h.step()?; // primed at u = 0
        rt.mat("u").write().set(0, 0, 1.0)?;
        // dt = 0.01 s, tau = 0.09 s: a = 0.1, so after n samples y = 1 − 0.9ⁿ.
        for n in 1..=10 {
            h.step()?;
            let expected = 1.0 - 0.9_f64.powi(n);
            let y = rt.mat("y").value(0, 0);
            assert!((y - expected).abs() < 1e-12, "sample {n}: y = {y}, expected {expected}");
        }
        assert_eq!(h.stats().module_errors, 0);
        Ok(())
    }
}
"#;

/// The binary: `ndds run` with the component added.
pub const MAIN_RS: &str = r#"//! `{crate} FILE`: runs a system description, as `ndds run FILE` does, with the component
//! type `{type}` added to the built-in library. Every `ndds run` flag works (`--check`,
//! `--simulate 10`, `--seconds 5`, `--plain`, `--domain`, ...).

fn main() -> std::process::ExitCode {
    ndds_cli::run_main("{crate}", |library| {
        library.add::<{crate_ident}::{Type}>();
    })
}
"#;

/// A description file using the component.
pub const COMPONENT_SYSTEM: &str = r#"# A sine through `{type}`: run it with `cargo run -- system.toml` (not the plain `ndds run`,
# which does not know `{type}`).

[system]
name = "{crate}"
description = "a noisy sine, smoothed by {type}"
display = ["raw", "smooth"]

[[habitat]]
name = "filter"
rate = 200.0

[[component]]
name = "source"
type = "sine"
habitat = "filter"
output = "clean"
amplitude = 1.0
frequency = 0.5

[[component]]
name = "noise"
type = "noise"
habitat = "filter"
output = "disturbance"
std_dev = 0.1
seed = 7

[[component]]
name = "measure"
type = "sum"
habitat = "filter"
inputs = ["clean", "disturbance"]
output = "raw"

[[component]]
name = "smoother"
type = "{type}"
habitat = "filter"
input = "raw"
output = "smooth"
tau = 0.05
"#;

/// A description file of built-in components only.
pub const SYSTEM: &str = r#"# `{crate}`: run it with `ndds run system.toml` (see docs/description-files.md).

[system]
name = "{crate}"
description = "a step response of a mass-spring-damper under PD control"
display = ["position", "reference"]

[[habitat]]
name = "servo"
rate = 500.0

[[component]]
name = "setpoint"
type = "step"
habitat = "servo"
output = "reference"
final = [1.0]
at = 0.5

[[component]]
name = "controller"
type = "pd"
habitat = "servo"
measured = "position"
reference = "reference"
output = "force"
kp = 40.0
kd = 6.0

[[component]]
name = "plant"
type = "mass_spring_damper"
habitat = "servo"
force = "force"
position = "position"
angle = "angle"
"#;

/// The component crate's README.
pub const COMPONENT_README: &str = r#"# {crate}

A component type of its own (`{type}`, the struct `{Type}` in `src/lib.rs`) and a program that
runs description files with it: `ndds run`'s behaviour with `{type}` added to the built-in
library.

- `src/lib.rs`: the component. Its inputs, outputs and parameters are the struct's fields,
  marked `#[input]`, `#[output]`, `#[param]` (see `ndds_runtime::Component`); the derive makes
  the spec description files are checked against and the factory. You write the routines
  (`impl SampleModule`: `execute`, and `reset`, `enable`, `timing_changed`, ... as needed).
  A known-answer test drives it in a manual habitat.
- `src/main.rs`: `ndds_cli::run_main`, which takes every `ndds run` flag.
- `system.toml`: a description file using it.

Build, test and run:

    cargo test
    cargo run -- system.toml --check      # load and verify only
    cargo run -- system.toml --simulate 5 # 5 s of simulated time, as fast as it goes
    cargo run -- system.toml              # live, until Ctrl-C

The plain `ndds run system.toml` refuses the file: it does not know `{type}`, and says so.
While it runs, the other `ndds` tools see it like any system (`ndds shell`, `ndds habitat`,
`ndds studio`).
"#;

/// The system's README.
pub const SYSTEM_README: &str = r#"# {crate}

A system description (`system.toml`) of built-in components: a step setpoint, a PD
controller and a simulated mass-spring-damper.

    ndds run system.toml --check       # load and verify only
    ndds run system.toml --simulate 5  # 5 s of simulated time
    ndds run system.toml               # live, until Ctrl-C

The component types and their parameters are in docs/components.md; the file's format in
docs/description-files.md.
"#;

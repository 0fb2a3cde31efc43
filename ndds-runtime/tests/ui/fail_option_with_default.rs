//! An `Option` parameter is `None` when absent: a default too says two things.

use ndds_runtime::{Component, Mat, RoutineResult, SampleContext, SampleModule};

/// Clamps its input.
#[derive(Component)]
#[component(name = "clamp")]
struct Clamp {
    /// u
    #[input]
    input: Mat,
    /// y
    #[output(same_as = input)]
    output: Mat,
    /// the largest output
    #[param(default = 1.0)]
    limit: Option<f64>,
}

impl SampleModule for Clamp {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        Ok(())
    }
}

fn main() {}

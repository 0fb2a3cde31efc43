//! `#[input]` on a field that is not a CSMat.

use ndds_runtime::{Component, Mat, RoutineResult, SampleContext, SampleModule};

/// Doubles its input.
#[derive(Component)]
#[component(name = "double")]
struct Double {
    /// u
    #[input]
    input: f64,
    /// y
    #[output]
    output: Mat,
}

impl SampleModule for Double {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        Ok(())
    }
}

fn main() {}

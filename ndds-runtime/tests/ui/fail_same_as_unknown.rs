//! `same_as` naming no field at all.

use ndds_runtime::{Component, Mat, RoutineResult, SampleContext, SampleModule};

/// Copies its input.
#[derive(Component)]
#[component(name = "copy")]
struct Copy {
    /// u
    #[input]
    input: Mat,
    /// y, the shape of u
    #[output(same_as = inptu)]
    output: Mat,
}

impl SampleModule for Copy {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        Ok(())
    }
}

fn main() {}

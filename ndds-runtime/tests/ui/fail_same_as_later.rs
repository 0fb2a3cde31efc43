//! `same_as` naming a field declared after it (its shape is not known yet).

use ndds_runtime::{Component, Mat, RoutineResult, SampleContext, SampleModule};

/// Copies its input.
#[derive(Component)]
#[component(name = "copy")]
struct Copy {
    /// y, the shape of u
    #[output(same_as = input)]
    output: Mat,
    /// u
    #[input]
    input: Mat,
}

impl SampleModule for Copy {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        Ok(())
    }
}

fn main() {}

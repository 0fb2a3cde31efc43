//! A component without the type name description files give.

use ndds_runtime::{Component, Mat, RoutineResult, SampleContext, SampleModule};

/// Copies its input.
#[derive(Component)]
struct Copy {
    /// u
    #[input]
    input: Mat,
    /// y
    #[output(same_as = input)]
    output: Mat,
}

impl SampleModule for Copy {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        Ok(())
    }
}

fn main() {}

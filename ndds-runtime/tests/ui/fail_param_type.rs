//! A parameter of a type the derive cannot read from a description file.

use std::collections::HashMap;

use ndds_runtime::{Component, Mat, RoutineResult, SampleContext, SampleModule};

/// Looks things up.
#[derive(Component)]
#[component(name = "lookup")]
struct Lookup {
    /// y
    #[output]
    output: Mat,
    /// the table of values
    #[param]
    table: HashMap<String, f64>,
}

impl SampleModule for Lookup {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        Ok(())
    }
}

fn main() {}

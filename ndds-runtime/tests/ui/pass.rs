//! Every role and option the derive takes, in one component that compiles.

use std::path::PathBuf;

use nalgebra::DMatrix;
use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry};
use ndds_runtime::{RoutineResult, SampleContext, SampleModule};

/// Everything at once: a kitchen sink.
///
/// More words.
#[derive(Component)]
#[component(name = "sink", finish = Self::finish)]
pub struct Sink {
    #[state(init = _taps.len())]
    taps_count: usize,
    /// the terms
    #[inputs(same_shape)]
    terms: Vec<Mat>,
    /// a state input, the shape of the first term
    #[input(state, same_as = terms)]
    fed_back: Mat,
    /// read in state_update when there are several taps
    #[input(state = taps_count > 1)]
    maybe: Option<Mat>,
    /// the sum
    #[output(same_as = terms)]
    output: Mat,
    /// taps_count × 1
    #[output(shape = (taps_count, 1))]
    extra: Option<Mat>,
    /// a gain
    #[param(tunable, default = 1.0, unit = "1/s", min = 0.0)]
    k: Mat,
    /// bounds, infinite allowed
    #[param(tunable, column, finite = false)]
    bounds: Mat,
    /// the taps
    #[param(default = vec![1.0], default_doc = "[1]")]
    _taps: Vec<f64>,
    /// a count
    #[param(default = 3, min = 1, max = 10)]
    count: u16,
    /// a matrix
    #[param]
    gain: Option<DMatrix<f64>>,
    /// a table
    #[param]
    options: Option<Params>,
    /// a file
    #[param(default = "out.csv")]
    file: PathBuf,
    /// a flag
    #[param(default = true)]
    on: bool,
    /// a keyword key
    #[param(key = "final", default = 0.0)]
    final_value: f64,
    #[state]
    scratch: Vec<f64>,
    samples: u64,
}

impl Sink {
    fn finish(&mut self, _: &mut Binder<'_>) -> Result<(), ModuleError> {
        self.scratch = vec![0.0; usize::from(self.count)];
        Ok(())
    }
}

impl SampleModule for Sink {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        self.samples += 1;
        let _ = (&self.terms, &self.fed_back, &self.maybe, &self.output, &self.extra);
        let _ = (&self.k, &self.bounds, &self.gain, &self.options, &self.file);
        let _ = (self.on, self.final_value, self.taps_count);
        Ok(())
    }
}

fn main() {
    let mut library = Registry::empty();
    library.add::<Sink>();
    let spec = Sink::spec();
    assert_eq!(spec.summary, "Everything at once: a kitchen sink.");
    assert_eq!(spec.params.len(), 14);
}

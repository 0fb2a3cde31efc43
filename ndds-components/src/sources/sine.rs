//! `sine`: a sine wave.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::{seconds, source_columns};
use crate::mats::copy_out;

/// output = offset + amplitude·sin(2π·frequency·t + phase).
#[derive(Component)]
#[component(name = "sine")]
pub struct Sine {
    /// `[amplitude, frequency, phase, offset]` as columns of one length.
    #[state(init = source_columns(
        _rows,
        [
            ("amplitude", &_amplitude),
            ("frequency", &_frequency),
            ("phase", &_phase),
            ("offset", &_offset),
        ],
    )?)]
    values: [DMatrix<f64>; 4],
    /// y (n × 1)
    #[output(shape = values[0].shape())]
    output: Mat,
    /// peak deviation from `offset`
    #[param]
    _amplitude: Vec<f64>,
    /// frequency
    #[param(unit = "Hz")]
    _frequency: Vec<f64>,
    /// phase at t = 0
    #[param(default = vec![0.0], default_doc = "0", unit = "rad")]
    _phase: Vec<f64>,
    /// mean value
    #[param(default = vec![0.0], default_doc = "0")]
    _offset: Vec<f64>,
    /// output rows n (every list then has one value or n)
    #[param(default_doc = "the length of the longest list", min = 1, max = 65536)]
    _rows: Option<usize>,
    #[state(init = values[3].clone())]
    buffer: DMatrix<f64>,
}

impl Sine {
    /// Writes the sine wave to `output` (frequency in Hz, phase in radians).
    pub fn new(
        b: &mut Binder<'_>,
        output: &str,
        amplitude: &[f64],
        frequency: &[f64],
        phase: &[f64],
        offset: &[f64],
    ) -> Result<Self, ModuleError> {
        let params = Params::new()
            .with("output", output)
            .with("amplitude", amplitude.to_vec())
            .with("frequency", frequency.to_vec())
            .with("phase", phase.to_vec())
            .with("offset", offset.to_vec());
        Self::build(b, &params)
    }
}

impl SampleModule for Sine {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let t = seconds(ctx);
        let [amplitude, frequency, phase, offset] = &self.values;
        for (i, out) in self.buffer.iter_mut().enumerate() {
            let angle = std::f64::consts::TAU * frequency[i] * t + phase[i];
            *out = offset[i] + amplitude[i] * angle.sin();
        }
        copy_out(&self.output, &self.buffer)
    }
}

/// Registers `sine`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Sine>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::sources::testing::{refused, run, with};
    use crate::testing::{TestResult, assert_refuses};

    #[test]
    fn sine_peaks_at_a_quarter_period() -> TestResult {
        let params = Params::new()
            .with("amplitude", 2.0)
            .with("frequency", 1.0)
            .with("offset", 0.5)
            .with("phase", vec![0.0, std::f64::consts::FRAC_PI_2]);
        let out = run(&with("sine", params)?, 51)?;
        assert!((out[0][0] - 0.5).abs() < 1e-12);
        assert!((out[0][1] - 2.5).abs() < 1e-12);
        assert!((out[25][0] - 2.5).abs() < 1e-12, "{:?}", out[25]);
        assert!((out[50][0] - 0.5).abs() < 1e-12, "{:?}", out[50]);
        assert!((out[50][1] + 1.5).abs() < 1e-12, "{:?}", out[50]);
        Ok(())
    }

    #[test]
    fn a_missing_frequency_is_refused_by_name() {
        let params = Params::new().with("amplitude", 1.0);
        assert_refuses(&refused("sine", params), "frequency", &["missing"]);
    }
}

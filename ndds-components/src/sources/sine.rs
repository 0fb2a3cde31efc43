//! `sine`: a sine wave.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use super::{ROWS_DEFAULT, ROWS_DOC, list, rows, seconds};
use crate::mats::copy_out;
use crate::params::columns;

/// A sine wave: `output = offset + amplitude·sin(2π·frequency·t + phase)` (frequency in Hz,
/// phase in radians).
pub struct Sine {
    output: Mat,
    amplitude: DMatrix<f64>,
    frequency: DMatrix<f64>,
    phase: DMatrix<f64>,
    offset: DMatrix<f64>,
    buffer: DMatrix<f64>,
}

impl Sine {
    /// Writes the sine wave to `output`.
    pub fn new(
        b: &mut Binder<'_>,
        output: &str,
        amplitude: &[f64],
        frequency: &[f64],
        phase: &[f64],
        offset: &[f64],
    ) -> Result<Self, ModuleError> {
        let [amplitude, frequency, phase, offset] = columns([
            ("amplitude", amplitude),
            ("frequency", frequency),
            ("phase", phase),
            ("offset", offset),
        ])?;
        Ok(Self {
            output: b.output(output, offset.shape()),
            buffer: offset.clone(),
            amplitude,
            frequency,
            phase,
            offset,
        })
    }
}

impl SampleModule for Sine {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let t = seconds(ctx);
        for (i, out) in self.buffer.iter_mut().enumerate() {
            let angle = std::f64::consts::TAU * self.frequency[i] * t + self.phase[i];
            *out = self.offset[i] + self.amplitude[i] * angle.sin();
        }
        copy_out(&self.output, &self.buffer)
    }
}

const SINE: ComponentSpec = ComponentSpec {
    name: "sine",
    summary: "output = offset + amplitude·sin(2π·frequency·t + phase).",
    params: &[
        P::required("output", K::Output, "y (n × 1)"),
        P::required("amplitude", K::Numbers, "peak deviation from `offset`"),
        P::required("frequency", K::Numbers, "frequency (Hz)"),
        P::optional("phase", K::Numbers, "0", "phase at t = 0 (rad)"),
        P::optional("offset", K::Numbers, "0", "mean value"),
        P::optional("rows", K::Number, ROWS_DEFAULT, ROWS_DOC),
    ],
};

/// Registers `sine`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add_with(&SINE, |b, p| {
        let n = rows(p)?;
        Sine::new(
            b,
            p.text("output")?,
            &list(p, "amplitude", None, n)?,
            &list(p, "frequency", None, n)?,
            &list(p, "phase", Some(0.0), n)?,
            &list(p, "offset", Some(0.0), n)?,
        )
    });
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

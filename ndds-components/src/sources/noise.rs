//! `noise`: seeded Gaussian white noise.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use super::source_columns;
use crate::mats::copy_out;

/// Gaussian white noise, output = mean + std_dev·N(0, 1), a new draw each sample; the same
/// sequence for the same seed, restarted by a reset.
///
/// The draws come from a generator seeded with `seed` (Box–Muller on `fastrand`), so the
/// sequence is the same every run.
#[derive(Component)]
#[component(name = "noise")]
pub struct Noise {
    /// `[mean, std_dev]` as columns of one length.
    #[state(init = source_columns(_rows, [("mean", &_mean), ("std_dev", &_std_dev)])?)]
    values: [DMatrix<f64>; 2],
    /// y (n × 1)
    #[output(shape = values[0].shape())]
    output: Mat,
    /// standard deviation
    #[param(min = 0)]
    _std_dev: Vec<f64>,
    /// mean value
    #[param(default = vec![0.0], default_doc = "0")]
    _mean: Vec<f64>,
    /// seed of the generator (a whole number ≥ 0)
    #[param(default = 1)]
    seed: u64,
    /// output rows n (every list then has one value or n)
    #[param(default_doc = "the length of the longest list", min = 1, max = 65536)]
    _rows: Option<usize>,
    #[state(init = fastrand::Rng::with_seed(seed))]
    rng: fastrand::Rng,
    /// The second value of the last Box–Muller pair, not used yet.
    spare: Option<f64>,
    #[state(init = values[0].clone())]
    buffer: DMatrix<f64>,
}

impl Noise {
    /// Writes noise with `mean` and standard deviation `std_dev` (≥ 0) to `output`.
    pub fn new(
        b: &mut Binder<'_>,
        output: &str,
        mean: &[f64],
        std_dev: &[f64],
        seed: u64,
    ) -> Result<Self, ModuleError> {
        // The seed is set here, not as a parameter: a description file's number holds only
        // seeds below 2^53 exactly.
        let params = Params::new()
            .with("output", output)
            .with("mean", mean.to_vec())
            .with("std_dev", std_dev.to_vec());
        let mut noise = Self::build(b, &params)?;
        noise.seed = seed;
        noise.rng = fastrand::Rng::with_seed(seed);
        Ok(noise)
    }

    /// One standard normal draw.
    fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let u1 = 1.0 - self.rng.f64(); // in (0, 1]: ln is finite
        let u2 = self.rng.f64();
        let radius = (-2.0 * u1.ln()).sqrt();
        let angle = std::f64::consts::TAU * u2;
        self.spare = Some(radius * angle.sin());
        radius * angle.cos()
    }
}

impl SampleModule for Noise {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        for i in 0..self.buffer.len() {
            let [mean, std_dev] = &self.values;
            let (mean, std_dev) = (mean[i], std_dev[i]);
            self.buffer[i] = mean + std_dev * self.normal();
        }
        copy_out(&self.output, &self.buffer)
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.rng = fastrand::Rng::with_seed(self.seed);
        self.spare = None;
        Ok(())
    }
}

/// Registers `noise`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Noise>();
}

#[cfg(test)]
mod tests {
    use ndds_runtime::Params;

    use crate::sources::testing::{refused, run, with};
    use crate::testing::{TestResult, assert_refuses};

    #[test]
    fn noise_has_its_mean_and_deviation_and_repeats_by_seed() -> TestResult {
        let params = || Params::new().with("mean", 1.0).with("std_dev", 2.0);
        let out: Vec<f64> = run(&with("noise", params())?, 20_000)?
            .iter()
            .map(|row| row[0])
            .collect();
        let n = out.len() as f64;
        let mean = out.iter().sum::<f64>() / n;
        let std = (out.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        assert!((mean - 1.0).abs() < 0.03 * 2.0, "mean {mean}");
        assert!((std - 2.0).abs() < 0.03 * 2.0, "standard deviation {std}");

        let again: Vec<f64> = run(&with("noise", params())?, 100)?
            .iter()
            .map(|row| row[0])
            .collect();
        assert_eq!(again, out[..100]);
        let other = run(&with("noise", params().with("seed", 7.0))?, 100)?;
        assert_ne!(other.iter().map(|row| row[0]).collect::<Vec<_>>(), again);

        let rt = with("noise", params())?;
        let first = run(&rt, 5)?;
        rt.habitat("h").reset();
        assert_eq!(run(&rt, 5)?, first);
        Ok(())
    }

    #[test]
    fn a_negative_deviation_or_seed_is_refused_by_name() {
        let params = Params::new().with("std_dev", -1.0);
        assert_refuses(&refused("noise", params), "std_dev", &["negative"]);
        let params = Params::new().with("std_dev", 1.0).with("seed", -1.0);
        assert_refuses(&refused("noise", params), "seed", &["whole number"]);
    }
}

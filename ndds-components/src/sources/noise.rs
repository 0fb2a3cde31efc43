//! `noise`: seeded Gaussian white noise.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use super::{ROWS_DEFAULT, ROWS_DOC, list, rows};
use crate::mats::copy_out;
use crate::params::{columns, whole_number};

/// Gaussian white noise: each element of `output` is `mean + std_dev·N(0, 1)`, a new draw each
/// sample. The draws come from a generator seeded with `seed` (Box–Muller on `fastrand`), so
/// the sequence is the same every run; `reset` restarts it.
pub struct Noise {
    output: Mat,
    mean: DMatrix<f64>,
    std_dev: DMatrix<f64>,
    seed: u64,
    rng: fastrand::Rng,
    /// The second value of the last Box–Muller pair, not used yet.
    spare: Option<f64>,
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
        let [mean, std_dev] = columns([("mean", mean), ("std_dev", std_dev)])?;
        if let Some(bad) = std_dev.iter().find(|s| **s < 0.0) {
            return Err(ModuleError::param("std_dev", format!("{bad} is negative")));
        }
        Ok(Self {
            output: b.output(output, mean.shape()),
            buffer: mean.clone(),
            mean,
            std_dev,
            seed,
            rng: fastrand::Rng::with_seed(seed),
            spare: None,
        })
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
            self.buffer[i] = self.mean[i] + self.std_dev[i] * self.normal();
        }
        copy_out(&self.output, &self.buffer)
    }

    fn reset(&mut self, _: &SampleContext) -> RoutineResult {
        self.rng = fastrand::Rng::with_seed(self.seed);
        self.spare = None;
        Ok(())
    }
}

const NOISE: ComponentSpec = ComponentSpec {
    name: "noise",
    summary: "Gaussian white noise, output = mean + std_dev·N(0, 1), a new draw each sample; \
              the same sequence for the same seed, restarted by a reset.",
    params: &[
        P::required("output", K::Output, "y (n × 1)"),
        P::required("std_dev", K::Numbers, "standard deviation (≥ 0)"),
        P::optional("mean", K::Numbers, "0", "mean value"),
        P::optional(
            "seed",
            K::Number,
            "1",
            "seed of the generator (a whole number ≥ 0)",
        ),
        P::optional("rows", K::Number, ROWS_DEFAULT, ROWS_DOC),
    ],
};

/// Registers `noise`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add_with(&NOISE, |b, p| {
        let n = rows(p)?;
        let seed = whole_number("seed", p.number_or("seed", 1.0)?, 0.0, 2f64.powi(53))?;
        Noise::new(
            b,
            p.text("output")?,
            &list(p, "mean", Some(0.0), n)?,
            &list(p, "std_dev", None, n)?,
            seed,
        )
    });
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

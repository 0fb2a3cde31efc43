//! Signal sources: modules without inputs that write a column `output` each sample, as a
//! function of the sample's nominal time `t` (seconds since sampling began).
//!
//! | type       | module       | writes   | value                                            |
//! |------------|--------------|----------|--------------------------------------------------|
//! | `constant` | [`Constant`] | `output` | `value` (a tunable CSMat `<module>.value`)       |
//! | `step`     | [`Step`]     | `output` | `initial` before `at`, `final` from `at` on      |
//! | `ramp`     | [`Ramp`]     | `output` | `start + slope·max(t − at, 0)`                   |
//! | `sine`     | [`Sine`]     | `output` | `offset + amplitude·sin(2π·frequency·t + phase)` |
//! | `noise`    | [`Noise`]    | `output` | Gaussian white noise, `mean` and `std_dev`       |
//!
//! Every value is a list with one value per element of the output, or a single value for all
//! of them. The output is `n × 1`, where `n` is the parameter `rows` when given (every list
//! then has one value or `rows`), else the length of the longest list (every other list has one
//! value or that many).

use nalgebra::DMatrix;

use super::{copy_in, copy_out, matrix_param};
use ndds_runtime::Mat;
use ndds_runtime::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Params, Registry};

/// Times within this of `at` count as reaching it: nominal times are sums of whole-nanosecond
/// periods, so `3 × (1/3 s)` is 1 ns short of 1 s.
const TIME_TOLERANCE: f64 = 1e-6;

/// Largest `rows` a source accepts.
const MAX_ROWS: f64 = 65536.0;

/// Checks of parameter values shared by the component files (kept in a module so that the
/// `components` glob re-exports do not spread these names).
pub(crate) mod param_checks {
    use nalgebra::DMatrix;

    use ndds_runtime::ModuleError;

    /// A failure naming parameter `name` (worded like a `ParamError`).
    pub(crate) fn problem(name: &str, text: impl std::fmt::Display) -> ModuleError {
        ModuleError::Failed(format!("parameter `{name}`: {text}"))
    }

    /// The length the lists `(name, values)` agree on: each has one value or the longest one's
    /// count. Every value must be finite.
    pub(crate) fn common_length(lists: &[(&str, &[f64])]) -> Result<usize, ModuleError> {
        let n = lists.iter().map(|(_, v)| v.len()).max().unwrap_or(1);
        for (name, values) in lists {
            if values.is_empty() {
                return Err(problem(name, "expected at least one value"));
            }
            if values.len() != 1 && values.len() != n {
                let longest = lists.iter().find(|(_, v)| v.len() == n).map_or("", |l| l.0);
                return Err(problem(
                    name,
                    format!(
                        "has {} values but `{longest}` has {n}; give one value or {n}",
                        values.len()
                    ),
                ));
            }
            if let Some(bad) = values.iter().find(|x| !x.is_finite()) {
                return Err(problem(name, format!("{bad} is not a finite number")));
            }
        }
        Ok(n)
    }

    /// `values` as `n` values: a single value is repeated; otherwise there must be `n`.
    pub(crate) fn broadcast(name: &str, values: &[f64], n: usize) -> Result<Vec<f64>, ModuleError> {
        match values.len() {
            1 => Ok(vec![values[0]; n]),
            len if len == n => Ok(values.to_vec()),
            len => Err(problem(
                name,
                format!("has {len} values; expected one value or {n}"),
            )),
        }
    }

    /// `x` as a whole number in `min..=max` (for counts, sizes and seeds).
    pub(crate) fn whole_number(name: &str, x: f64, min: f64, max: f64) -> Result<u64, ModuleError> {
        if x.fract() == 0.0 && (min..=max).contains(&x) {
            Ok(x as u64)
        } else {
            Err(problem(
                name,
                format!("expected a whole number from {min} to {max}, got {x}"),
            ))
        }
    }

    /// The lists `(name, values)` as columns of one length `n`: the longest list's, every other
    /// list having one value (repeated) or as many.
    pub(crate) fn columns<const N: usize>(
        lists: [(&str, &[f64]); N],
    ) -> Result<[DMatrix<f64>; N], ModuleError> {
        let n = common_length(&lists)?;
        // Each list has one value or n (checked above): `i % len` repeats a single value.
        Ok(lists.map(|(_, values)| DMatrix::from_fn(n, 1, |i, _| values[i % values.len()])))
    }

    /// Fails unless `x` is a finite number.
    pub(crate) fn finite(name: &str, x: f64) -> Result<f64, ModuleError> {
        if x.is_finite() {
            Ok(x)
        } else {
            Err(problem(name, format!("{x} is not a finite number")))
        }
    }
}

use param_checks::{broadcast, columns, finite, problem, whole_number};

fn seconds(ctx: &SampleContext) -> f64 {
    ctx.time.as_secs_f64()
}

/// `output = value`: a tunable constant. `value` is the `n × 1` parameter CSMat
/// `"{module}.value"`; the application may change it while sampling runs.
pub struct Constant {
    output: Mat,
    value: Mat,
    buffer: DMatrix<f64>,
}

impl Constant {
    /// Writes `value` (a column) to `output`.
    pub fn new(b: &mut Binder<'_>, output: &str, value: &[f64]) -> Result<Self, ModuleError> {
        let [value] = columns([("value", value)])?;
        Ok(Self {
            output: b.output(output, value.shape()),
            value: matrix_param(b, "value", &value),
            buffer: value,
        })
    }
}

impl SampleModule for Constant {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        copy_in(&self.value, &mut self.buffer);
        copy_out(&self.output, &self.buffer)
    }
}

/// A step: `output = initial` while `t < at`, `final` from the first sample with `t ≥ at` on.
pub struct Step {
    output: Mat,
    initial: DMatrix<f64>,
    final_value: DMatrix<f64>,
    at: f64,
}

impl Step {
    /// Steps `output` from `initial` to `final_value` at `at` seconds.
    pub fn new(
        b: &mut Binder<'_>,
        output: &str,
        initial: &[f64],
        final_value: &[f64],
        at: f64,
    ) -> Result<Self, ModuleError> {
        let [initial, final_value] = columns([("initial", initial), ("final", final_value)])?;
        finite("at", at)?;
        Ok(Self {
            output: b.output(output, initial.shape()),
            initial,
            final_value,
            at,
        })
    }
}

impl SampleModule for Step {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        if seconds(ctx) + TIME_TOLERANCE >= self.at {
            copy_out(&self.output, &self.final_value)
        } else {
            copy_out(&self.output, &self.initial)
        }
    }
}

/// A ramp: `output = start + slope·max(t − at, 0)` (`slope` per second).
pub struct Ramp {
    output: Mat,
    start: DMatrix<f64>,
    slope: DMatrix<f64>,
    at: f64,
    buffer: DMatrix<f64>,
}

impl Ramp {
    /// Ramps `output` from `start` at `slope` per second from `at` seconds on.
    pub fn new(
        b: &mut Binder<'_>,
        output: &str,
        start: &[f64],
        slope: &[f64],
        at: f64,
    ) -> Result<Self, ModuleError> {
        let [start, slope] = columns([("start", start), ("slope", slope)])?;
        finite("at", at)?;
        Ok(Self {
            output: b.output(output, start.shape()),
            buffer: start.clone(),
            start,
            slope,
            at,
        })
    }
}

impl SampleModule for Ramp {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let elapsed = (seconds(ctx) - self.at).max(0.0);
        for (i, out) in self.buffer.iter_mut().enumerate() {
            *out = self.start[i] + self.slope[i] * elapsed;
        }
        copy_out(&self.output, &self.buffer)
    }
}

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
            return Err(problem("std_dev", format!("{bad} is negative")));
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

const ROWS_DOC: &str = "output rows n (every list then has one value or n)";
const ROWS_DEFAULT: &str = "the length of the longest list";

/// `constant`.
pub const CONSTANT: ComponentSpec = ComponentSpec {
    name: "constant",
    summary: "output = value, a tunable n × 1 CSMat `<module>.value`.",
    params: &[
        P::required("output", K::Output, "y (n × 1)"),
        P::required("value", K::Numbers, "the value, one per row or one for all"),
        P::optional("rows", K::Number, ROWS_DEFAULT, ROWS_DOC),
    ],
};

/// `step`.
pub const STEP: ComponentSpec = ComponentSpec {
    name: "step",
    summary: "output = initial while t < at, final from the first sample with t ≥ at on.",
    params: &[
        P::required("output", K::Output, "y (n × 1)"),
        P::required("final", K::Numbers, "the value from `at` on"),
        P::optional("initial", K::Numbers, "0", "the value before `at`"),
        P::optional(
            "at",
            K::Number,
            "0",
            "when it steps (s since sampling began)",
        ),
        P::optional("rows", K::Number, ROWS_DEFAULT, ROWS_DOC),
    ],
};

/// `ramp`.
pub const RAMP: ComponentSpec = ComponentSpec {
    name: "ramp",
    summary: "output = start + slope·max(t − at, 0).",
    params: &[
        P::required("output", K::Output, "y (n × 1)"),
        P::required("slope", K::Numbers, "rate of change (per s)"),
        P::optional("start", K::Numbers, "0", "the value until `at`"),
        P::optional("at", K::Number, "0", "when it starts rising (s)"),
        P::optional("rows", K::Number, ROWS_DEFAULT, ROWS_DOC),
    ],
};

/// `sine`.
pub const SINE: ComponentSpec = ComponentSpec {
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

/// `noise`.
pub const NOISE: ComponentSpec = ComponentSpec {
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

/// The list parameter `name` (or `default` when absent and optional), stretched to `rows`
/// when that is given.
fn list(
    p: &Params,
    name: &str,
    default: Option<f64>,
    rows: Option<usize>,
) -> Result<Vec<f64>, ModuleError> {
    let values = match default {
        Some(x) => p.numbers_or(name, &[x])?,
        None => p.numbers(name)?,
    };
    match rows {
        Some(n) => broadcast(name, &values, n),
        None => Ok(values),
    }
}

/// The `rows` parameter, if given.
fn rows(p: &Params) -> Result<Option<usize>, ModuleError> {
    if !p.has("rows") {
        return Ok(None);
    }
    let n = whole_number("rows", p.number("rows")?, 1.0, MAX_ROWS)?;
    Ok(Some(n as usize))
}

/// Registers this file's component types.
pub(crate) fn register(registry: &mut Registry) {
    registry.add(&CONSTANT, |b, p| {
        let n = rows(p)?;
        Constant::new(b, p.text("output")?, &list(p, "value", None, n)?)
    });
    registry.add(&STEP, |b, p| {
        let n = rows(p)?;
        Step::new(
            b,
            p.text("output")?,
            &list(p, "initial", Some(0.0), n)?,
            &list(p, "final", None, n)?,
            p.number_or("at", 0.0)?,
        )
    });
    registry.add(&RAMP, |b, p| {
        let n = rows(p)?;
        Ramp::new(
            b,
            p.text("output")?,
            &list(p, "start", Some(0.0), n)?,
            &list(p, "slope", None, n)?,
            p.number_or("at", 0.0)?,
        )
    });
    registry.add(&SINE, |b, p| {
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
    registry.add(&NOISE, |b, p| {
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
    use ndds_runtime::{Clock, HabitatOptions, Params, Runtime};

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    /// A runtime with a manual 100 Hz habitat `h` holding one module `m` of `type_name`.
    fn with(type_name: &str, params: Params) -> Result<Runtime, Box<dyn std::error::Error>> {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        rt.install_component("h", "m", type_name, &params.with("output", "y"))?;
        rt.habitat("h").start()?;
        Ok(rt)
    }

    /// Runs `samples` samples; returns `y` (all rows) after each.
    fn run(rt: &Runtime, samples: usize) -> Result<Vec<Vec<f64>>, Box<dyn std::error::Error>> {
        let h = rt.habitat("h");
        let y = rt.mat("y");
        let mut out = Vec::new();
        for _ in 0..samples {
            h.step()?;
            out.push(y.read().matrix().iter().copied().collect());
        }
        Ok(out)
    }

    fn build_error(type_name: &str, params: Params) -> String {
        let rt = Runtime::new("t");
        crate::register(&rt);
        match rt.install_component("h", "m", type_name, &params.with("output", "y")) {
            Ok(()) => panic!("{type_name} with bad parameters was installed"),
            Err(err) => err.to_string(),
        }
    }

    #[test]
    fn constant_writes_its_tunable_value() -> TestResult {
        let rt = with("constant", Params::new().with("value", vec![1.0, 2.0, 3.0]))?;
        assert_eq!(run(&rt, 1)?, [[1.0, 2.0, 3.0]]);
        rt.mat("m.value").write().set(1, 0, -5.0)?;
        assert_eq!(run(&rt, 1)?, [[1.0, -5.0, 3.0]]);
        let rt = with(
            "constant",
            Params::new().with("value", 4.0).with("rows", 2.0),
        )?;
        assert_eq!(run(&rt, 1)?, [[4.0, 4.0]]);
        Ok(())
    }

    #[test]
    fn step_switches_exactly_at_its_time() -> TestResult {
        let params = Params::new()
            .with("initial", 1.0)
            .with("final", vec![2.0, 3.0])
            .with("at", 0.5);
        let out = run(&with("step", params)?, 52)?;
        // Sample k runs at t = k·10 ms: sample 50 is the first at t ≥ 0.5 s.
        assert_eq!(out[0], [1.0, 1.0]);
        assert_eq!(out[49], [1.0, 1.0]);
        assert_eq!(out[50], [2.0, 3.0]);
        assert_eq!(out[51], [2.0, 3.0]);
        // A period that does not divide `at` in nanoseconds still switches on time.
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(3.0).clock(Clock::Manual))?;
        let params = Params::new().with("final", 1.0).with("at", 1.0);
        rt.install_component("h", "m", "step", &params.with("output", "y"))?;
        rt.habitat("h").start()?;
        assert_eq!(run(&rt, 4)?, [[0.0], [0.0], [0.0], [1.0]]);
        Ok(())
    }

    #[test]
    fn ramp_rises_at_its_slope_after_its_start() -> TestResult {
        let params = Params::new()
            .with("start", 1.0)
            .with("slope", vec![2.0, -1.0])
            .with("at", 0.1);
        let out = run(&with("ramp", params)?, 31)?;
        assert_eq!(out[5], [1.0, 1.0]);
        assert_eq!(out[10], [1.0, 1.0]);
        // t = 0.3 s: 0.2 s after the start.
        assert!((out[30][0] - 1.4).abs() < 1e-12, "{:?}", out[30]);
        assert!((out[30][1] - 0.8).abs() < 1e-12, "{:?}", out[30]);
        Ok(())
    }

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
    fn bad_parameters_fail_the_install_naming_them() {
        let err = build_error(
            "step",
            Params::new()
                .with("initial", vec![0.0, 0.0])
                .with("final", vec![1.0, 1.0, 1.0]),
        );
        assert!(err.contains("`initial`") && err.contains("3"), "{err}");
        let err = build_error("noise", Params::new().with("std_dev", -1.0));
        assert!(
            err.contains("`std_dev`") && err.contains("negative"),
            "{err}"
        );
        let err = build_error(
            "constant",
            Params::new().with("value", 1.0).with("rows", 0.0),
        );
        assert!(err.contains("`rows`"), "{err}");
        let err = build_error(
            "constant",
            Params::new()
                .with("value", vec![1.0, 2.0])
                .with("rows", 3.0),
        );
        assert!(err.contains("`value`"), "{err}");
        let err = build_error("sine", Params::new().with("amplitude", 1.0));
        assert!(
            err.contains("`frequency`") && err.contains("missing"),
            "{err}"
        );
        let err = build_error("ramp", Params::new().with("slope", f64::NAN));
        assert!(err.contains("`slope`") && err.contains("finite"), "{err}");
    }
}

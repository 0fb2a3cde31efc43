//! Signal sources: modules without inputs that write a column `output` each sample, as a
//! function of the sample's nominal time `t` (seconds since sampling began).
//!
//! | type       | module                      | value                                            |
//! |------------|-----------------------------|--------------------------------------------------|
//! | `constant` | [`Constant`](crate::Constant) | `value` (a tunable CSMat `<module>.value`)     |
//! | `step`     | [`Step`](crate::Step)       | `initial` before `at`, `final` from `at` on      |
//! | `ramp`     | [`Ramp`](crate::Ramp)       | `start + slope·max(t − at, 0)`                   |
//! | `sine`     | [`Sine`](crate::Sine)       | `offset + amplitude·sin(2π·frequency·t + phase)` |
//! | `noise`    | [`Noise`](crate::Noise)     | Gaussian white noise, `mean` and `std_dev`       |
//!
//! Every value is a list with one value per element of the output, or a single value for all
//! of them. The output is `n × 1`, where `n` is the parameter `rows` when given (every list
//! then has one value or `rows`), else the length of the longest list (every other list has one
//! value or that many). This file holds what the sources' registry entries share.

pub(crate) mod constant;
pub(crate) mod noise;
pub(crate) mod ramp;
pub(crate) mod sine;
pub(crate) mod step;

use ndds_runtime::{ModuleError, Params, Registry, SampleContext};

use crate::params::{broadcast, whole_number};

/// Times within this of `at` count as reaching it: nominal times are sums of whole-nanosecond
/// periods, so `3 × (1/3 s)` is 1 ns short of 1 s.
const TIME_TOLERANCE: f64 = 1e-6;

/// Largest `rows` a source accepts.
const MAX_ROWS: f64 = 65536.0;

/// The doc of every source's `rows` parameter, and its default.
const ROWS_DOC: &str = "output rows n (every list then has one value or n)";
const ROWS_DEFAULT: &str = "the length of the longest list";

/// The sample's nominal time (s since sampling began).
fn seconds(ctx: &SampleContext) -> f64 {
    ctx.time.as_secs_f64()
}

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

/// Registers the sources.
pub(crate) fn register(registry: &mut Registry) {
    constant::register(registry);
    step::register(registry);
    ramp::register(registry);
    sine::register(registry);
    noise::register(registry);
}

#[cfg(test)]
pub(crate) mod testing {
    use ndds_runtime::{ModuleError, Params, Runtime};

    use crate::testing::{Outcome, refusal, runtime};

    /// A runtime with a manual 100 Hz habitat `h` holding one module `m` of `type_name`
    /// writing `y`, started.
    pub(crate) fn with(type_name: &str, params: Params) -> Outcome<Runtime> {
        let rt = runtime(100.0, &[])?;
        rt.install_component("h", "m", type_name, &params.with("output", "y"))?;
        rt.habitat("h").start()?;
        Ok(rt)
    }

    /// Runs `samples` samples; returns `y` (all rows) after each.
    pub(crate) fn run(rt: &Runtime, samples: usize) -> Outcome<Vec<Vec<f64>>> {
        let h = rt.habitat("h");
        let y = rt.mat("y");
        let mut out = Vec::new();
        for _ in 0..samples {
            h.step()?;
            out.push(y.read().matrix().iter().copied().collect());
        }
        Ok(out)
    }

    /// Why a source `type_name` writing `y` refuses `params`.
    pub(crate) fn refused(type_name: &str, params: Params) -> ModuleError {
        let rt = runtime(100.0, &[]).expect("a runtime");
        refusal(&rt, type_name, &params.with("output", "y"))
    }
}

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
//! value or that many). This file holds what the sources share: the time and the columns.
//!
//! Each source is a `#[derive(Component)]` struct whose list parameters (and `rows`) are
//! fields named with a leading `_`: they are read only while building, into the columns the
//! routines use (a state field initialised before the output, whose shape it gives).

pub(crate) mod constant;
pub(crate) mod noise;
pub(crate) mod ramp;
pub(crate) mod sine;
pub(crate) mod step;

use nalgebra::DMatrix;

use ndds_runtime::{ModuleError, Registry, SampleContext};

use crate::params::{broadcast, columns};

/// Times within this of `at` count as reaching it: nominal times are sums of whole-nanosecond
/// periods, so `3 × (1/3 s)` is 1 ns short of 1 s.
const TIME_TOLERANCE: f64 = 1e-6;

/// The sample's nominal time (s since sampling began).
fn seconds(ctx: &SampleContext) -> f64 {
    ctx.time.as_secs_f64()
}

/// The lists `(key, values)` as columns of one length: `rows` when given (each list then has
/// one value or `rows`), else the longest list's (each other list has one value or as many).
fn source_columns<const N: usize>(
    rows: Option<usize>,
    lists: [(&str, &[f64]); N],
) -> Result<[DMatrix<f64>; N], ModuleError> {
    let stretched = match rows {
        Some(n) => lists
            .iter()
            .map(|(key, values)| broadcast(key, values, n))
            .collect::<Result<Vec<_>, _>>()?,
        None => lists.iter().map(|(_, values)| values.to_vec()).collect(),
    };
    columns(std::array::from_fn(|i| {
        (lists[i].0, stretched[i].as_slice())
    }))
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

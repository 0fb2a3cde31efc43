//! CSMats that only one habitat's modules name are owned by that habitat: its routines reach
//! them without a lock, others see them as of the end of its last sample, and what others
//! write reaches its modules at its next sample (the `mat` module's doc). CSMats that cross
//! habitats stay behind their lock. Real threads and habitats; no timing is asserted beyond
//! generous waits for a condition.

#[path = "../../ndds-client/tests/common/mod.rs"]
mod common;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use ndds_runtime::csmat::CsMat;
use ndds_runtime::{
    Binder, Clock, HabitatOptions, Mat, RoutineResult, Runtime, SampleContext, SampleModule, Shape,
};

type TestResult = Result<(), Box<dyn std::error::Error>>;

fn eventually(check: impl FnMut() -> bool) -> bool {
    common::eventually(Duration::from_secs(20), check)
}

/// `output = k · input` (k a parameter CSMat `<name>.k`).
struct Scale {
    input: Mat,
    output: Mat,
    k: Mat,
}

impl Scale {
    fn build(b: &mut Binder<'_>, input: &str, output: &str) -> Self {
        let k = format!("{}.k", b.module_name());
        Self {
            input: b.input(input, (1, 1)),
            output: b.output(output, (1, 1)),
            k: b.param_or(&k, CsMat::from_row_slice(&k, 1, 1, &[1.0]).expect("1x1")),
        }
    }
}

impl SampleModule for Scale {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let k = self.k.read().get(0, 0)?;
        let u = self.input.read().get(0, 0)?;
        self.output.write().set(0, 0, k * u)?;
        Ok(())
    }
}

/// Fills its 4 × 4 output with the sample number (every element equal).
struct Fill {
    output: Mat,
}

impl SampleModule for Fill {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.output.write().fill((ctx.sample + 1) as f64);
        Ok(())
    }
}

fn manual() -> HabitatOptions {
    HabitatOptions::rate(100.0).clock(Clock::Manual)
}

#[test]
fn a_csmat_one_habitat_names_is_owned_and_one_that_crosses_habitats_is_not() -> TestResult {
    let rt = Runtime::new("own");
    rt.create_habitat("a", manual())?;
    rt.create_habitat("b", manual())?;
    rt.create_mat(CsMat::from_row_slice("x", 1, 1, &[2.0])?)?;
    rt.install("a", "ax", |b| Ok(Scale::build(b, "x", "y")))?;
    assert!(rt.mat("x").is_owned(), "only a's module names x");
    assert!(rt.mat("y").is_owned());
    assert!(rt.mat("ax.k").is_owned());

    rt.install("b", "by", |b| Ok(Scale::build(b, "y", "z")))?;
    assert!(!rt.mat("y").is_owned(), "y crosses from a to b");
    assert!(rt.mat("z").is_owned() && rt.mat("x").is_owned());

    // Across habitats the value still flows, through the lock.
    rt.habitat("a").start()?;
    rt.habitat("b").start()?;
    rt.habitat("a").step()?;
    rt.habitat("b").step()?;
    assert_eq!(rt.mat("z").value(0, 0), 2.0);

    rt.remove("by")?;
    assert!(rt.mat("y").is_owned(), "y is a's alone again");
    Ok(())
}

#[test]
fn others_see_the_last_finished_sample_and_their_writes_reach_the_next() -> TestResult {
    let rt = Runtime::new("own");
    rt.create_habitat("a", manual())?;
    rt.create_mat(CsMat::from_row_slice("x", 1, 1, &[1.0])?)?;
    rt.install("a", "s", |b| Ok(Scale::build(b, "x", "y")))?;
    let habitat = rt.habitat("a");
    habitat.start()?;
    habitat.step()?;
    assert_eq!(rt.mat("y").value(0, 0), 1.0);

    // A tuning from this thread (not the habitat's sampler) and a new input.
    rt.mat("s.k").write().set(0, 0, 3.0)?;
    rt.mat("x").write().set(0, 0, 5.0)?;
    assert_eq!(
        rt.mat("s.k").value(0, 0),
        3.0,
        "the writer reads its own write"
    );
    assert_eq!(rt.mat("y").value(0, 0), 1.0, "not sampled yet");
    habitat.step()?;
    assert_eq!(rt.mat("y").value(0, 0), 15.0);
    assert!(rt.mat("s.k").is_owned());
    Ok(())
}

#[test]
fn a_running_habitat_takes_in_writes_from_other_threads() -> TestResult {
    let rt = Runtime::new("own");
    rt.create_habitat("a", HabitatOptions::rate(500.0))?;
    rt.create_mat(CsMat::from_row_slice("x", 1, 1, &[1.0])?)?;
    rt.install("a", "s", |b| Ok(Scale::build(b, "x", "y")))?;
    rt.habitat("a").start()?;
    assert!(eventually(|| rt.mat("y").value(0, 0) == 1.0));
    rt.mat("s.k").write().set(0, 0, -4.0)?;
    assert!(
        eventually(|| rt.mat("y").value(0, 0) == -4.0),
        "the tuning reached the module: y = {}",
        rt.mat("y").value(0, 0)
    );
    rt.habitat("a").stop();
    Ok(())
}

#[test]
fn readers_elsewhere_see_whole_samples_of_a_running_habitat() -> TestResult {
    let rt = Runtime::new("own");
    rt.create_habitat("a", HabitatOptions::rate(1000.0))?;
    rt.install("a", "fill", |b| {
        Ok(Fill {
            output: b.output("m", Shape::Exact(4, 4)),
        })
    })?;
    assert!(rt.mat("m").is_owned());
    rt.habitat("a").start()?;
    let done = Arc::new(AtomicBool::new(false));
    let mat = rt.mat("m");
    let reader = {
        let done = Arc::clone(&done);
        std::thread::spawn(move || {
            let (mut reads, mut last) = (0_u64, 0.0_f64);
            while !done.load(Ordering::Relaxed) {
                let value = mat.snapshot();
                let first = value.get(0, 0).unwrap_or(f64::NAN);
                if value.matrix().iter().any(|&v| v != first) || first < last {
                    return Err(format!("torn or backwards: {value:?} after {last}"));
                }
                last = first;
                reads += 1;
            }
            Ok((reads, last))
        })
    };
    assert!(eventually(|| rt.mat("m").value(0, 0) >= 200.0));
    done.store(true, Ordering::Relaxed);
    let (reads, last) = reader.join().map_err(|_| "reader panicked")??;
    rt.habitat("a").stop();
    assert!(reads > 0 && last > 0.0, "{reads} reads, last {last}");
    Ok(())
}

//! `ndds perf runtime`: what the ControlShell runtime costs, without any network.
//!
//! 1. **Overhead**: a manual habitat runs `--samples` samples of `--modules` modules, first
//!    modules that do nothing (the runtime's own cost: the list lock, two routine calls per
//!    module, the counters), then a chain of 1 × 1 gains (each reads its gain and its input
//!    and writes its output, copying the value in and out; the habitat owns all three, so no
//!    lock is taken, and publishes each output after the sample). Reported per sample and
//!    per module.
//! 2. **Jitter**: a timer habitat of `--modules` gains at `--rate` for `--seconds`: how late
//!    each sample started against its absolute deadline, how far each period was from the
//!    nominal one, and execution times. `--load N` runs N busy threads meanwhile (pinned to
//!    `--load-cpu`), `--cpu` pins the habitat, `--fifo` asks for `SCHED_FIFO`.
//! 3. **Switch under load**: the same timer habitat again, now with a configuration switch
//!    every `--switch-every` between two groups: a 1 × 1 gain, and a controller whose
//!    `enable` designs an LQR gain for a `--design-states`-state model (a Riccati iteration,
//!    as the LQG component's design). Its start latency (p99, max) and overruns are printed
//!    beside the run without switches, with the ratio of the two p99s.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use hdrhistogram::Histogram;
use nalgebra::DMatrix;
use ndds_components::{Gain, dlqr};
use ndds_runtime::{
    Clock, CsMat, HabitatOptions, HabitatStats, Mat, ModuleError, Percentiles, RoutineResult,
    Runtime, SampleContext, SampleModule, pin_to_cpu,
};
use serde_json::json;

use crate::outln;

/// Options of `ndds perf runtime`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Modules in the list.
    #[arg(long, default_value_t = 50)]
    modules: usize,
    /// Samples timed for the overhead figures.
    #[arg(long, default_value_t = 200_000)]
    samples: u64,
    /// Rate of the timer habitat (Hz).
    #[arg(long, default_value_t = 1000.0)]
    rate: f64,
    /// Seconds the timer habitat runs.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Busy threads running during the jitter measurement.
    #[arg(long, default_value_t = 0)]
    load: usize,
    /// Pin the busy threads to this CPU.
    #[arg(long)]
    load_cpu: Option<usize>,
    /// Pin the habitat thread to this CPU.
    #[arg(long)]
    cpu: Option<usize>,
    /// SCHED_FIFO priority for the habitat thread (needs CAP_SYS_NICE).
    #[arg(long)]
    fifo: Option<i32>,
    /// Skip the overhead measurement.
    #[arg(long)]
    jitter_only: bool,
    /// Seconds between configuration switches in the switch-under-load run (0 skips it).
    #[arg(long, value_parser = crate::seconds::parse, default_value = "0.1")]
    switch_every: Duration,
    /// States of the model the switched-in controller designs its gain for in `enable`.
    #[arg(long, default_value_t = 24)]
    design_states: usize,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// A module that does nothing: the runtime's own cost.
struct Nop;
impl SampleModule for Nop {}

/// Runs `ndds perf runtime`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.modules > 0, "--modules must be at least 1");
    anyhow::ensure!(
        args.seconds > 0.0 && args.seconds <= 3600.0,
        "--seconds must be in (0, 3600]"
    );
    let overhead = if args.jitter_only {
        None
    } else {
        Some((
            overhead(args.modules, args.samples, false)?,
            overhead(args.modules, args.samples, true)?,
        ))
    };
    let jitter = jitter(args)?;
    let switching = if args.switch_every.is_zero() {
        None
    } else {
        Some(switching(args)?)
    };
    if args.json {
        let mut value = json!({
            "modules": args.modules,
            "rate_hz": args.rate,
            "seconds": args.seconds,
            "load_threads": args.load,
            "load_cpu": args.load_cpu,
            "cpu": args.cpu,
            "fifo": args.fifo,
            "jitter": {
                "samples": jitter.samples,
                "expected_samples": (args.rate * args.seconds).round(),
                "overruns": jitter.overruns,
                "latency_us": percentiles(&jitter.latency),
                "period_jitter_us": percentiles(&jitter.period_jitter),
                "exec_us": percentiles(&jitter.exec),
            },
        });
        if let Some((nop, gain)) = &overhead {
            value["overhead"] = json!({ "nop": nop.json(), "gain": gain.json() });
        }
        if let Some(run) = &switching {
            value["switching"] = run.json(&jitter);
        }
        outln!("{value}")?;
    } else {
        if let Some((nop, gain)) = &overhead {
            nop.print("modules that do nothing")?;
            gain.print(
                "1x1 gains (three CSMat accesses without a lock: gain, input, output; two copies)",
            )?;
        }
        print_jitter(args, &jitter)?;
        if let Some(run) = &switching {
            run.print(args, &jitter)?;
        }
    }
    Ok(())
}

struct Overhead {
    modules: usize,
    samples: u64,
    mean_ns: f64,
    per_sample: Histogram<u64>,
}

impl Overhead {
    fn json(&self) -> serde_json::Value {
        json!({
            "samples": self.samples,
            "mean_ns_per_sample": self.mean_ns,
            "mean_ns_per_module": self.mean_ns / self.modules as f64,
            "p50_ns": self.per_sample.value_at_quantile(0.5),
            "p99_ns": self.per_sample.value_at_quantile(0.99),
            "max_ns": self.per_sample.max(),
        })
    }

    fn print(&self, what: &str) -> anyhow::Result<()> {
        outln!(
            "overhead, {} {what}: {:.0} ns per sample ({:.1} ns per module); per sample p50 {} ns, p99 {} ns, max {} ns, over {} samples",
            self.modules,
            self.mean_ns,
            self.mean_ns / self.modules as f64,
            self.per_sample.value_at_quantile(0.5),
            self.per_sample.value_at_quantile(0.99),
            self.per_sample.max(),
            self.samples
        )?;
        Ok(())
    }
}

fn overhead(modules: usize, samples: u64, gains: bool) -> anyhow::Result<Overhead> {
    let rt = Runtime::new("perf");
    rt.create_habitat("bench", HabitatOptions::rate(1000.0).clock(Clock::Manual))?;
    if gains {
        install_gains(&rt, modules)?;
    } else {
        for i in 0..modules {
            rt.install("bench", &format!("nop{i}"), |_| Ok(Nop))?;
        }
    }
    let habitat = rt.habitat("bench");
    habitat.start()?;
    for _ in 0..samples.min(10_000) {
        habitat.step()?;
    }
    let mut per_sample = Histogram::<u64>::new_with_bounds(1, 1_000_000_000, 3)?;
    let start = Instant::now();
    for _ in 0..samples {
        let t = Instant::now();
        habitat.step()?;
        per_sample.saturating_record(t.elapsed().as_nanos().max(1) as u64);
    }
    let total = start.elapsed();
    habitat.stop();
    Ok(Overhead {
        modules,
        samples,
        mean_ns: total.as_nanos() as f64 / samples.max(1) as f64,
        per_sample,
    })
}

fn install_gains(rt: &Runtime, modules: usize) -> anyhow::Result<()> {
    rt.create_mat(CsMat::from_row_slice("c0", 1, 1, &[1.0])?)?;
    for i in 0..modules {
        rt.install("bench", &format!("gain{i}"), |b| {
            Gain::new(b, &format!("c{i}"), &format!("c{}", i + 1), 1.0)
        })?;
    }
    Ok(())
}

fn jitter(args: &Args) -> anyhow::Result<HabitatStats> {
    let rt = Runtime::new("perf");
    let mut options = HabitatOptions::rate(args.rate);
    options.cpu = args.cpu;
    options.realtime_priority = args.fifo;
    rt.create_habitat("bench", options)?;
    install_gains(&rt, args.modules)?;
    let stop = Arc::new(AtomicBool::new(false));
    let load: Vec<_> = (0..args.load)
        .map(|_| {
            let stop = Arc::clone(&stop);
            let cpu = args.load_cpu;
            std::thread::spawn(move || busy(&stop, cpu))
        })
        .collect();
    std::thread::sleep(Duration::from_millis(100));
    let habitat = rt.habitat("bench");
    habitat.start().context("starting the timer habitat")?;
    std::thread::sleep(Duration::from_secs_f64(args.seconds));
    habitat.stop();
    stop.store(true, Ordering::Relaxed);
    for thread in load {
        let _ = thread.join();
    }
    Ok(habitat.stats_total())
}

/// A controller whose `enable` designs its gain: an LQR for an `n`-state chain of coupled
/// first-order lags (`x⁺ = A·x + B·u`, the input on the last one), the kind of work the LQG
/// component does when it is designed.
struct Designer {
    input: Mat,
    output: Mat,
    n: usize,
    gain: f64,
    design_ns: Arc<AtomicU64>,
}

impl SampleModule for Designer {
    fn enable(&mut self, _: &SampleContext) -> RoutineResult {
        let start = Instant::now();
        let n = self.n;
        let a = DMatrix::from_fn(n, n, |i, j| match j.cmp(&i) {
            std::cmp::Ordering::Equal => 0.95,
            std::cmp::Ordering::Greater if j == i + 1 => 0.05,
            _ => 0.0,
        });
        let b = DMatrix::from_fn(n, 1, |i, _| if i + 1 == n { 0.1 } else { 0.0 });
        let k = dlqr(&a, &b, &DMatrix::identity(n, n), &DMatrix::identity(1, 1))
            .ok_or_else(|| ModuleError::Failed("no LQR design".into()))?;
        self.gain = k[(0, 0)];
        self.design_ns
            .fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
        Ok(())
    }

    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let x = self.input.value(0, 0);
        self.output.write().set(0, 0, -self.gain * x)?;
        Ok(())
    }
}

/// The switch-under-load run.
struct Switching {
    stats: HabitatStats,
    switches: u64,
    designs: u64,
    design_ns: u64,
}

impl Switching {
    fn ratio(&self, idle: &HabitatStats) -> f64 {
        self.stats.latency.p99_us / idle.latency.p99_us.max(0.001)
    }

    fn json(&self, idle: &HabitatStats) -> serde_json::Value {
        json!({
            "switches": self.switches,
            "designs": self.designs,
            "mean_design_ms": self.mean_design_ms(),
            "samples": self.stats.samples,
            "overruns": self.stats.overruns,
            "latency_us": percentiles(&self.stats.latency),
            "exec_us": percentiles(&self.stats.exec),
            "latency_p99_ratio_to_idle": self.ratio(idle),
        })
    }

    fn mean_design_ms(&self) -> f64 {
        self.design_ns as f64 / self.designs.max(1) as f64 / 1e6
    }

    fn print(&self, args: &Args, idle: &HabitatStats) -> anyhow::Result<()> {
        outln!(
            "switch under load: {} switches (one every {:?}, {} LQR designs of {} states in enable, {:.2} ms each), {} samples, {} overruns (without switches: {})",
            self.switches,
            args.switch_every,
            self.designs,
            args.design_states,
            self.mean_design_ms(),
            self.stats.samples,
            self.stats.overruns,
            idle.overruns
        )?;
        outln!(
            "  start latency: p99 {:.1} us, max {:.1} us; without switches p99 {:.1} us, max {:.1} us (p99 ratio {:.2})",
            self.stats.latency.p99_us,
            self.stats.latency.max_us,
            idle.latency.p99_us,
            idle.latency.max_us,
            self.ratio(idle)
        )?;
        Ok(())
    }
}

/// The timer habitat of [`jitter`] with a switch every `--switch-every` between a gain and
/// a [`Designer`].
fn switching(args: &Args) -> anyhow::Result<Switching> {
    let rt = Runtime::new("perf");
    let mut options = HabitatOptions::rate(args.rate);
    options.cpu = args.cpu;
    options.realtime_priority = args.fifo;
    rt.create_habitat("bench", options)?;
    install_gains(&rt, args.modules)?;
    let end = format!("c{}", args.modules);
    // Groups first: the two controllers write `u` and are never active together.
    rt.group("control", "plain", &["plain"])?;
    rt.group("control", "designed", &["designed"])?;
    rt.configuration("Plain", &[("control", "plain")])?;
    rt.configuration("Designed", &[("control", "designed")])?;
    rt.install("bench", "plain", |b| Gain::new(b, &end, "u", -1.0))?;
    let design_ns = Arc::new(AtomicU64::new(0));
    let (n, ns) = (args.design_states.max(1), Arc::clone(&design_ns));
    rt.install("bench", "designed", |b| {
        Ok(Designer {
            input: b.input(&end, (1, 1)),
            output: b.output("u", (1, 1)),
            n,
            gain: 0.0,
            design_ns: ns,
        })
    })?;
    let habitat = rt.habitat("bench");
    habitat.start().context("starting the timer habitat")?;
    let started = Instant::now();
    let mut switches = 0u64;
    while started.elapsed().as_secs_f64() < args.seconds {
        std::thread::sleep(args.switch_every);
        let next = if switches.is_multiple_of(2) {
            "Designed"
        } else {
            "Plain"
        };
        rt.switch(next)?;
        switches += 1;
    }
    habitat.stop();
    Ok(Switching {
        stats: habitat.stats_total(),
        switches,
        designs: switches.div_ceil(2),
        design_ns: design_ns.load(Ordering::Relaxed),
    })
}

fn busy(stop: &AtomicBool, cpu: Option<usize>) {
    if let Some(cpu) = cpu
        && let Err(err) = pin_to_cpu(cpu)
    {
        eprintln!("ndds: cannot pin a busy thread to CPU {cpu} ({err}); it runs unpinned");
    }
    let mut x = 0u64;
    while !stop.load(Ordering::Relaxed) {
        for _ in 0..10_000 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
    }
}

fn percentiles(p: &Percentiles) -> serde_json::Value {
    json!({ "count": p.count, "p50": p.p50_us, "p99": p.p99_us, "max": p.max_us })
}

fn print_jitter(args: &Args, stats: &HabitatStats) -> anyhow::Result<()> {
    let load = match (args.load, args.load_cpu) {
        (0, _) => "idle".to_owned(),
        (n, Some(cpu)) => format!("{n} busy thread(s) on CPU {cpu}"),
        (n, None) => format!("{n} busy thread(s)"),
    };
    outln!(
        "timer habitat, {} gains at {} Hz for {} s ({load}{}{}): {} samples (expected {:.0}), {} overruns",
        args.modules,
        args.rate,
        args.seconds,
        args.cpu
            .map(|c| format!(", habitat on CPU {c}"))
            .unwrap_or_default(),
        args.fifo
            .map(|p| format!(", SCHED_FIFO {p}"))
            .unwrap_or_default(),
        stats.samples,
        args.rate * args.seconds,
        stats.overruns
    )?;
    for (name, p) in [
        ("start latency", &stats.latency),
        ("period jitter", &stats.period_jitter),
        ("execution    ", &stats.exec),
    ] {
        outln!(
            "  {name}: p50 {:.1} us, p99 {:.1} us, max {:.1} us ({} samples)",
            p.p50_us,
            p.p99_us,
            p.max_us,
            p.count
        )?;
    }
    Ok(())
}

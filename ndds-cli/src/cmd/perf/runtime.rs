//! `ndds perf runtime`: what the ControlShell runtime costs, without any network.
//!
//! 1. **Overhead**: a manual habitat runs `--samples` samples of `--modules` modules, first
//!    modules that do nothing (the runtime's own cost: the list lock, two routine calls per
//!    module, the counters), then a chain of 1 × 1 gains (each locks its gain, its input and
//!    its output, one at a time, and copies the value in and out). Reported per sample and
//!    per module.
//! 2. **Jitter**: a timer habitat of `--modules` gains at `--rate` for `--seconds`: how late
//!    each sample started against its absolute deadline, how far each period was from the
//!    nominal one, and execution times. `--load N` runs N busy threads meanwhile (pinned to
//!    `--load-cpu`), `--cpu` pins the habitat, `--fifo` asks for `SCHED_FIFO`.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use hdrhistogram::Histogram;
use ndds_components::Gain;
use ndds_runtime::{
    Clock, CsMat, HabitatOptions, HabitatStats, Percentiles, Runtime, SampleModule, pin_to_cpu,
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
        outln!("{value}")?;
    } else {
        if let Some((nop, gain)) = &overhead {
            nop.print("modules that do nothing")?;
            gain.print("1x1 gains (three CSMat locks: gain, input, output; two copies)")?;
        }
        print_jitter(args, &jitter)?;
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

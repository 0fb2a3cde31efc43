//! `ndds run FILE`: load a system description (`ndds_runtime::system`), verify it, run it on
//! the local daemon (or an embedded one on loopback when none runs), print a compact live
//! status, and shut it down cleanly (disable and shutdown routines) on Ctrl-C.
//!
//! Several `ndds run` processes, on one host or several, form one distributed system: their
//! CSMats meet on the topics the files publish and subscribe.

use std::io::{IsTerminal as _, Write as _};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use ndds_client::{EmbeddedPolicy, Participant};
use ndds_runtime::system::{LoadOptions, Status, System, SystemError};
use ndds_runtime::{BEHIND_BELOW, CsMat, Freshness, InputStatus, Pace, Registry};

use crate::connect::DaemonArgs;
use crate::seconds;
use crate::status_term::screen;

/// `println!` that ignores a closed stdout (`ndds run ... | head`): the system keeps running
/// and stops as it would have.
macro_rules! say {
    ($($arg:tt)*) => {{
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

/// `print!` likewise.
macro_rules! say_raw {
    ($($arg:tt)*) => {{
        let mut out = std::io::stdout();
        let _ = write!(out, $($arg)*);
        let _ = out.flush();
    }};
}

/// Options of `ndds run`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The system description (TOML; see docs/description-files.md).
    file: PathBuf,
    /// Stop after this many seconds (default: run until Ctrl-C).
    #[arg(long, value_parser = seconds::parse)]
    seconds: Option<Duration>,
    /// Load and verify only: print what would run, start nothing, exit 0 if it verifies.
    #[arg(long)]
    check: bool,
    /// Seconds between status reports.
    #[arg(long, value_parser = seconds::parse_interval, default_value = "1")]
    interval: Duration,
    /// Never start an embedded daemon: fail if no daemon runs.
    #[arg(long)]
    no_embedded: bool,
    /// Append each status report instead of redrawing it in place.
    #[arg(long)]
    plain: bool,
    /// Run this many seconds of simulated time as fast as the machine allows (every habitat
    /// clocked by the simulation), print the final status and the speed, and stop. A topic
    /// the system both publishes and subscribes to is passed on in the process; samples from
    /// other programs still travel in real time.
    #[arg(long, value_parser = seconds::parse, conflicts_with_all = ["seconds", "check"])]
    simulate: Option<Duration>,
    /// Run the system under this name instead of the file's (a name runs once per domain).
    /// Its statistics and command port take the name; its topics and state machines keep the
    /// file's names, so a second copy of one system belongs in another domain (--domain).
    #[arg(long)]
    name: Option<String>,
    /// Record the system's topics (its bindings, its state machines' states and stimuli, its
    /// statistics and configuration topics) into FILE, an MCAP file as `ndds record` writes.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["check", "simulate"])]
    record: Option<PathBuf>,
}

/// `ndds run` in a program of your own: parses `program`'s command line as `ndds run`'s (the
/// description file, every `ndds run` flag and the daemon's), adds `extend`'s component types
/// to the built-in library, runs the system and returns the exit status (the error, if any,
/// said on stderr as `program: ...`). See the crate's doc for an example and
/// docs/components.md, "Your own components".
pub fn run_main(
    program: &'static str,
    extend: impl FnOnce(&mut Registry),
) -> std::process::ExitCode {
    use clap::{CommandFactory as _, FromArgMatches as _};

    /// `ndds run`'s command line, for a program of its own.
    #[derive(Debug, clap::Parser)]
    struct RunCli {
        #[command(flatten)]
        daemon: DaemonArgs,
        #[command(flatten)]
        run: Args,
    }

    let command = RunCli::command()
        .name(program)
        .bin_name(program)
        .about("Load a system description file, verify it and run it, with a live status.");
    let cli = match RunCli::from_arg_matches(&command.get_matches()) {
        Ok(cli) => cli,
        Err(err) => err.exit(),
    };
    crate::init_logging(false);
    let mut library = ndds_components::library();
    extend(&mut library);
    crate::exit_code(program, run(&cli.daemon, &cli.run, library))
}

/// Runs `ndds run` with the component types of `library`.
pub fn run(daemon: &DaemonArgs, args: &Args, library: Registry) -> anyhow::Result<()> {
    // First Ctrl-C (or SIGTERM): stop cleanly; a second one exits at once.
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register_conditional_shutdown(signal, 130, Arc::clone(&stop))
            .context("cannot catch signals")?;
        signal_hook::flag::register(signal, Arc::clone(&stop)).context("cannot catch signals")?;
    }
    if args.check || args.simulate.is_some() {
        let options = LoadOptions {
            simulated: args.simulate.is_some(),
            name: args.name.clone(),
            check: args.check,
            library: library.clone(),
            overlay: Default::default(),
        };
        // Network bindings are built against a daemon: connect only if the file has some.
        let mut participant = None;
        let loaded = match System::load_with(&args.file, None, options.clone()) {
            Err(SystemError::NeedsParticipant(_)) => {
                let p = participant.insert(connect(daemon, args.no_embedded, &args.file)?);
                System::load_with(&args.file, Some(p), options)
            }
            other => other,
        };
        let system = loaded.map_err(|e| describe_error(&args.file, e))?;
        return match args.simulate {
            Some(seconds) => simulate(&system, seconds, &stop),
            None => {
                print_plan(&system);
                Ok(())
            }
        };
    }
    let participant = connect(daemon, args.no_embedded, &args.file)?;
    let system = System::load_with(
        &args.file,
        Some(&participant),
        LoadOptions {
            name: args.name.clone(),
            ..LoadOptions::default().with_library(library)
        },
    )
    .map_err(|e| describe_error(&args.file, e))?;

    system.start().context("starting the system")?;
    say!(
        "ndds run: system `{}` running ({} habitat{}, {}); Ctrl-C stops it",
        system.name(),
        system.runtime().habitats().len(),
        if system.runtime().habitats().len() == 1 {
            ""
        } else {
            "s"
        },
        match system.runtime().current_configuration() {
            Some(c) => format!("configuration `{c}`"),
            None => "no configurations".to_owned(),
        }
    );
    let mut recorder = match &args.record {
        Some(path) => Some(start_recording(&participant, &system, path)?),
        None => None,
    };
    let mut next_discovery = Instant::now() + Duration::from_millis(500);
    let begun = Instant::now();
    let live = !args.plain && std::io::stdout().is_terminal();
    if live {
        screen().go_live(std::io::stderr().is_terminal());
    }
    let mut next = begun + args.interval;
    let mut watch = Watch::default();
    let _ = watch.changes(&system, Duration::ZERO);
    // The last report, for the rates achieved since.
    let mut last = (Instant::now(), system.status());
    let stopped_by_signal = loop {
        if stop.load(Ordering::Acquire) {
            break true;
        }
        if args.seconds.is_some_and(|s| begun.elapsed() >= s) {
            break false;
        }
        // Configuration switches and state changes, as they happen, above the status.
        let events = watch.changes(&system, begun.elapsed());
        if !events.is_empty() {
            screen().print(&events);
        }
        let now = Instant::now();
        if now >= next {
            let status = system.status();
            let at = Instant::now();
            let paces = paces(&last.1, &status, at - last.0);
            // Formatted before the screen is locked: a logging habitat never waits for it.
            let text = render(&status, &paces, begun.elapsed());
            screen().draw(&text);
            last = (at, status);
            next += args.interval;
            if next < now {
                next = now + args.interval;
            }
        }
        if let Some(recorder) = recorder.as_mut()
            && now >= next_discovery
        {
            next_discovery = now + Duration::from_millis(500);
            if let Err(err) = recorder.discover() {
                tracing::warn!(%err, "recording: the graph could not be read");
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    // The last report stays on screen; what follows goes below it.
    screen().release();
    if stopped_by_signal {
        say!("ndds run: interrupted");
    }
    system.stop();
    if let Some(recorder) = recorder {
        let summary = recorder.finish()?;
        let files: Vec<String> = summary
            .files
            .iter()
            .map(|f| f.display().to_string())
            .collect();
        say!(
            "ndds run: recorded {} messages of {} topics into {} ({} lost){}",
            summary.messages(),
            summary.topics.len(),
            files.join(", "),
            summary.lost(),
            summary
                .stopped
                .as_ref()
                .map(|why| format!("; stopped early: {why}"))
                .unwrap_or_default()
        );
    }
    let status = system.status();
    let errors = status.module_errors();
    say!(
        "ndds run: stopped `{}` after {:.1} s (shutdown routines ran; {} module error{})",
        system.name(),
        begun.elapsed().as_secs_f64(),
        errors,
        if errors == 1 { "" } else { "s" }
    );
    Ok(())
}

/// `--record FILE`: a recorder of the system's topics and its `cs/NAME/` topics, its first
/// consumers declared now (the rest as their producers appear).
fn start_recording(
    participant: &Participant,
    system: &System,
    path: &std::path::Path,
) -> anyhow::Result<ndds_bag::Recorder> {
    let mut names: Vec<String> = system
        .topics()
        .iter()
        .map(|t| format!("^{}$", regex::escape(t)))
        .collect();
    names.push(format!("^cs/{}/", regex::escape(system.name())));
    let selection = regex::Regex::new(&names.join("|")).context("the system's topics")?;
    let options = ndds_bag::RecordOptions {
        selection: ndds_bag::Selection::Regex(selection),
        ..ndds_bag::RecordOptions::default()
    };
    let mut recorder = ndds_bag::Recorder::start(participant, path, options)?;
    recorder.discover()?;
    say!(
        "ndds run: recording the system's topics into {}",
        path.display()
    );
    Ok(recorder)
}

/// `--simulate`: simulated time in steps of 10 ms, letting state machines act between steps.
fn simulate(system: &System, seconds: Duration, stop: &AtomicBool) -> anyhow::Result<()> {
    const STEP: f64 = 0.01;
    system.start().context("starting the system")?;
    let total = seconds.as_secs_f64().min(1e7);
    let begun = Instant::now();
    let mut watch = Watch::default();
    let _ = watch.changes(system, Duration::ZERO);
    let (mut t, mut samples) = (0.0, 0u64);
    while t < total {
        if stop.load(Ordering::Acquire) {
            say!("ndds run: interrupted");
            break;
        }
        let step = STEP.min(total - t);
        samples += system.simulate(step).context("simulating")?;
        t += step;
        std::thread::yield_now();
        say_raw!("{}", watch.changes(system, Duration::from_secs_f64(t)));
    }
    let wall = begun.elapsed().as_secs_f64();
    let status = system.status();
    let paces = vec![None; status.habitats.len()];
    say_raw!("{}", render(&status, &paces, Duration::from_secs_f64(t)));
    system.stop();
    say!(
        "ndds run: simulated {t:.1} s in {wall:.2} s ({:.0}x real time, {samples} samples, \
         {:.0} samples/s; {} module errors)",
        t / wall.max(1e-9),
        samples as f64 / wall.max(1e-9),
        system.status().module_errors()
    );
    Ok(())
}

fn connect(
    daemon: &DaemonArgs,
    no_embedded: bool,
    file: &std::path::Path,
) -> anyhow::Result<Participant> {
    let name = file.file_stem().map_or_else(
        || "ndds-run".to_owned(),
        |s| s.to_string_lossy().into_owned(),
    );
    let mut builder = Participant::builder().name(&name).embedded(if no_embedded {
        EmbeddedPolicy::Never
    } else {
        EmbeddedPolicy::Auto
    });
    if let Some(domain) = daemon.domain {
        builder = builder.domain(domain);
    }
    if let Some(socket) = &daemon.socket {
        builder = builder.socket(socket);
    }
    let participant = builder
        .connect()
        .context("cannot connect to a daemon or start an embedded one")?;
    crate::connect::check_domain(daemon, &participant)?;
    Ok(participant)
}

fn describe_error(file: &std::path::Path, err: SystemError) -> anyhow::Error {
    match err {
        SystemError::Invalid(d) => anyhow::anyhow!(
            "{} does not describe a system that can run ({} problem{}); nothing was started:\n{d}",
            file.display(),
            d.0.len(),
            if d.0.len() == 1 { "" } else { "s" }
        ),
        other => anyhow::Error::new(other).context(format!("loading {}", file.display())),
    }
}

fn print_plan(system: &System) {
    let rt = system.runtime();
    say!("system `{}`: verified, nothing started", system.name());
    if let Some(d) = system.description() {
        say!("  {d}");
    }
    for file in system.files() {
        say!("  file {}", file.display());
    }
    for h in rt.habitats() {
        say!(
            "  habitat {} at {:.6} Hz: {}",
            h.name(),
            1.0 / h.period().as_secs_f64(),
            h.order().join(" -> ")
        );
    }
    let groups = rt.active_groups();
    if !groups.is_empty() {
        let active: Vec<String> = groups.iter().map(|(c, g)| format!("{c}/{g}")).collect();
        say!(
            "  configuration {} (active groups {})",
            rt.current_configuration().unwrap_or_else(|| "-".into()),
            active.join(", ")
        );
    }
    for m in system.machine_names() {
        say!("  state machine {m}");
    }
}

/// What was seen last, to report changes.
#[derive(Default)]
struct Watch {
    configuration: Option<String>,
    states: std::collections::BTreeMap<String, String>,
}

impl Watch {
    /// One line per change since the last call.
    fn changes(&mut self, system: &System, elapsed: Duration) -> String {
        let mut out = String::new();
        let t = elapsed.as_secs_f64();
        let configuration = system.runtime().current_configuration();
        if configuration != self.configuration {
            if let (Some(old), Some(new)) = (&self.configuration, &configuration) {
                out.push_str(&format!("t={t:.1}s  configuration {old} -> {new}\n"));
            }
            self.configuration = configuration;
        }
        for name in system.machine_names() {
            let Some(machine) = system.machine(&name) else {
                continue;
            };
            let state = machine.snapshot().state;
            match self.states.insert(name.clone(), state.clone()) {
                Some(old) if old != state => {
                    out.push_str(&format!("t={t:.1}s  fsm {name}: {old} -> {state}\n"));
                }
                _ => {}
            }
        }
        out
    }
}

/// Each habitat's pace from `earlier` to `later` (in `later`'s order; `None` where there is
/// nothing to judge).
fn paces(earlier: &Status, later: &Status, elapsed: Duration) -> Vec<Option<Pace>> {
    later
        .habitats
        .iter()
        .map(|h| {
            let before = earlier.habitats.iter().find(|e| e.habitat == h.habitat)?;
            Pace::between(before, h, elapsed)
        })
        .collect()
}

/// The status block: one line per habitat (nominal and achieved rate, marked when behind),
/// the configuration, machines, subscribed inputs that are not fed, and displayed CSMats.
/// `paces[i]` is habitat `i`'s since the last report.
pub fn render(status: &Status, paces: &[Option<Pace>], elapsed: Duration) -> String {
    let mut out = format!(
        "{}  t={:.1}s  configuration {}\n",
        status.system,
        elapsed.as_secs_f64(),
        status.configuration.as_deref().unwrap_or("-")
    );
    out.push_str(&format!(
        "  {:<12} {:>9} {:>9} {:>9} {:>11} {:>9} {:>8} {:>6}\n",
        "habitat", "rate Hz", "achieved", "samples", "jitter p99", "exec p50", "overruns", "errors"
    ));
    for (i, h) in status.habitats.iter().enumerate() {
        let pace = paces.get(i).copied().flatten();
        out.push_str(&format!(
            "  {:<12} {:>9.1} {:>9} {:>9} {:>8.1} us {:>6.1} us {:>8} {:>6}{}\n",
            h.habitat,
            h.rate_hz,
            pace.map_or_else(|| "-".to_owned(), |p| format!("{:.1}", p.achieved_hz)),
            h.samples,
            h.period_jitter.p99_us,
            h.exec.p50_us,
            h.overruns,
            h.module_errors,
            if h.running {
                pace.map(behind).unwrap_or_default()
            } else {
                "  (stopped)".to_owned()
            }
        ));
    }
    for m in &status.machines {
        out.push_str(&format!(
            "  fsm {:<8} state {:<12} transitions {}{}\n",
            m.machine,
            m.state,
            m.transitions,
            if m.faults > 0 {
                format!("  faults {} ({})", m.faults, m.last_fault)
            } else {
                String::new()
            }
        ));
    }
    for input in status.inputs.iter().filter(|i| i.is_problem()) {
        out.push_str(&format!("  {}\n", input_problem(input)));
    }
    for (name, value) in &status.display {
        out.push_str(&format!("  {name} = {}\n", show(value)));
    }
    out
}

/// The marker after a habitat that falls behind (empty when it keeps up).
fn behind(pace: Pace) -> String {
    if !pace.is_behind() {
        return String::new();
    }
    let mut why = Vec::new();
    if pace.ratio() < BEHIND_BELOW {
        // Rounded down: 94.8 % is not shown as the 95 % it is below.
        why.push(format!(
            "{:.0} % of nominal",
            (pace.ratio() * 100.0).floor()
        ));
    }
    if pace.new_overruns > 0 {
        let s = if pace.new_overruns == 1 { "" } else { "s" };
        why.push(format!("+{} overrun{s}", pace.new_overruns));
    }
    format!("  BEHIND ({})", why.join(", "))
}

/// `input arm/angles -> angles: never received (waited 3.0 s)` or `... stale 2.3 s`.
fn input_problem(input: &InputStatus) -> String {
    let what = match (input.freshness, input.age) {
        (Freshness::Stale, Some(age)) => format!(
            "stale {:.1} s (last of {} samples)",
            age.as_secs_f64(),
            input.received
        ),
        _ => format!(
            "never received (waited {:.1} s)",
            input.sampled.as_secs_f64()
        ),
    };
    let refused = if input.refused > 0 {
        format!(
            "; {} sample{} refused (undecodable or of another shape)",
            input.refused,
            if input.refused == 1 { "" } else { "s" }
        )
    } else {
        String::new()
    };
    format!("input {} -> {}: {what}{refused}", input.topic, input.mat)
}

fn show(m: &CsMat) -> String {
    let unit = |i: usize| {
        m.row_fields()
            .get(i)
            .map(|f| f.unit.as_str())
            .filter(|u| !u.is_empty())
            .map(|u| format!(" {u}"))
            .unwrap_or_default()
    };
    let values: Vec<String> = (0..m.rows())
        .flat_map(|r| (0..m.cols()).map(move |c| (r, c)))
        .map(|(r, c)| format!("{:+.4}{}", m.matrix()[(r, c)], unit(r)))
        .collect();
    format!("[{}]", values.join(", "))
}

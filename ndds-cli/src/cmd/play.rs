//! `ndds play FILE...`: publishes recorded samples on their topics with their recorded types,
//! QoS and timing. On a terminal: a progress bar, and keys (space pauses and resumes, `s`
//! steps to the next message while paused, `+` and `-` double and halve the rate, `q`
//! stops).

use std::collections::HashMap;
use std::io::{IsTerminal as _, Read as _, Write as _};
use std::os::fd::AsFd as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use ndds_bag::play::{PlayControl, PlayOptions, Player, Progress};
use ndds_client::Reliability;
use regex::Regex;
use serde_json::json;

use crate::connect::{DaemonArgs, connect};
use crate::{outln, seconds};

/// Options of `ndds play`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Recordings (MCAP files, or directories of them); several are merged in time order.
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// Speed: 2 plays twice as fast, 0.5 at half speed.
    #[arg(long, default_value = "1")]
    rate: f64,
    /// Start again at the end, until Ctrl-C.
    #[arg(long = "loop")]
    repeat: bool,
    /// Skip this many seconds of the recording's start.
    #[arg(long, value_parser = seconds::parse, default_value = "0")]
    start: Duration,
    /// Play only this many seconds (after --start).
    #[arg(long, value_parser = seconds::parse)]
    duration: Option<Duration>,
    /// Play only these recorded topics.
    #[arg(long, num_args = 1..)]
    topics: Option<Vec<String>>,
    /// Never play recorded topics whose name matches this regular expression.
    #[arg(long, value_name = "REGEX")]
    exclude: Option<Regex>,
    /// Play recorded topic OLD on topic NEW (repeatable).
    #[arg(long, value_name = "OLD=NEW", value_parser = parse_remap)]
    remap: Vec<(String, String)>,
    /// Every producer's strength (default: as recorded).
    #[arg(long, allow_hyphen_values = true)]
    strength: Option<i32>,
    /// Every producer reliable (default: as recorded).
    #[arg(long, conflicts_with = "best_effort")]
    reliable: bool,
    /// Every producer best-effort (default: as recorded).
    #[arg(long)]
    best_effort: bool,
    /// Seconds to wait after declaring the producers, so consumers match before the first
    /// sample.
    #[arg(long, value_parser = seconds::parse, default_value = "0.5")]
    delay: Duration,
    /// Start paused (space resumes; needs a terminal).
    #[arg(long)]
    paused: bool,
    /// No progress bar (it is off anyway when standard error is not a terminal).
    #[arg(long, short)]
    quiet: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

/// Runs `ndds play`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let files = expand(&args.files)?;
    let interactive = std::io::stdin().is_terminal() && std::io::stderr().is_terminal();
    if args.paused && !interactive {
        anyhow::bail!("--paused needs a terminal (to resume with the space bar)");
    }
    let options = PlayOptions {
        rate: args.rate,
        repeat: args.repeat,
        start: args.start,
        duration: args.duration,
        topics: args.topics.clone(),
        exclude: args.exclude.clone(),
        remap: args.remap.iter().cloned().collect::<HashMap<_, _>>(),
        strength: args.strength,
        reliability: if args.reliable {
            Some(Reliability::Reliable { depth: 256 })
        } else if args.best_effort {
            Some(Reliability::BestEffort)
        } else {
            None
        },
        delay: args.delay,
    };
    let participant = connect(daemon)?;
    let mut player = Player::open(&participant, files, options)?;
    for warning in player.warnings() {
        eprintln!("ndds play: {warning}");
    }
    let control = Arc::new(PlayControl::new(args.rate, args.paused));
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register_conditional_shutdown(signal, 130, Arc::clone(&stop))
            .context("cannot catch signals")?;
        signal_hook::flag::register(signal, Arc::clone(&stop)).context("cannot catch signals")?;
    }
    {
        let control = Arc::clone(&control);
        let stop = Arc::clone(&stop);
        std::thread::Builder::new()
            .name("ndds-play-stop".into())
            .spawn(move || {
                while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(20));
                }
                control.stop();
            })?;
    }
    let _keys = interactive.then(|| Keys::start(Arc::clone(&control)));
    let live = !args.quiet && std::io::stderr().is_terminal();
    let total = player.messages();
    let started = Instant::now();
    let mut next_draw = Instant::now();
    let summary = player.run(&control, |progress| {
        if live && Instant::now() >= next_draw {
            draw(&progress, total, &control, interactive);
            next_draw = Instant::now() + Duration::from_millis(100);
        }
    })?;
    if live {
        eprint!("\r\x1b[K");
    }
    if args.json {
        outln!(
            "{}",
            json!({"published": summary.published, "failed": summary.failed,
                   "seconds": started.elapsed().as_secs_f64(), "topics": summary.topics})
        )?;
    } else {
        outln!(
            "published {} messages in {:.1} s ({} failed)",
            summary.published,
            started.elapsed().as_secs_f64(),
            summary.failed
        )?;
        for (topic, count) in &summary.topics {
            outln!("  {topic}: {count}")?;
        }
    }
    Ok(())
}

/// The files, with each directory replaced by its `.mcap` files in name order.
fn expand(paths: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for path in paths {
        if path.is_dir() {
            let mut inside: Vec<PathBuf> = std::fs::read_dir(path)
                .with_context(|| format!("reading {}", path.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
                .collect();
            inside.sort();
            if inside.is_empty() {
                anyhow::bail!("{} holds no .mcap files", path.display());
            }
            files.extend(inside);
        } else {
            files.push(path.clone());
        }
    }
    Ok(files)
}

fn draw(progress: &Progress, total: u64, control: &PlayControl, interactive: bool) {
    let fraction = if progress.total.is_zero() {
        1.0
    } else {
        (progress.position.as_secs_f64() / progress.total.as_secs_f64()).clamp(0.0, 1.0)
    };
    let width = 30;
    let filled = (fraction * width as f64).round() as usize;
    let bar: String = "#".repeat(filled) + &"-".repeat(width - filled);
    let state = if control.is_paused() {
        "paused"
    } else {
        "playing"
    };
    let keys = if interactive {
        "  [space pause, s step, +/- rate, q quit]"
    } else {
        ""
    };
    // One write: unbuffered standard error would otherwise write each piece of the format on
    // its own, and the terminal could show half a line.
    let line = format!(
        "\r\x1b[K{state} [{bar}] {:.1}/{:.1} s  x{:.2}  {}/{total} msgs{}{keys}",
        progress.position.as_secs_f64(),
        progress.total.as_secs_f64(),
        control.rate(),
        progress.published,
        if progress.passes > 0 {
            format!("  pass {}", progress.passes + 1)
        } else {
            String::new()
        }
    );
    let mut err = std::io::stderr().lock();
    let _ = err.write_all(line.as_bytes());
    let _ = err.flush();
}

/// The terminal in character mode (no echo, no line buffering) while playing, and a thread
/// that turns keys into controls; the terminal is restored on drop.
struct Keys {
    saved: Option<nix::sys::termios::Termios>,
}

impl Keys {
    fn start(control: Arc<PlayControl>) -> Self {
        use nix::sys::termios::{LocalFlags, SetArg, tcgetattr, tcsetattr};
        let stdin = std::io::stdin();
        let saved = tcgetattr(stdin.as_fd()).ok();
        if let Some(saved) = &saved {
            let mut raw = saved.clone();
            raw.local_flags
                .remove(LocalFlags::ICANON | LocalFlags::ECHO);
            let _ = tcsetattr(stdin.as_fd(), SetArg::TCSANOW, &raw);
        }
        let _ = std::thread::Builder::new()
            .name("ndds-play-keys".into())
            .spawn(move || {
                let mut byte = [0u8; 1];
                let mut stdin = std::io::stdin().lock();
                while stdin.read(&mut byte).is_ok_and(|n| n == 1) {
                    match byte[0] {
                        b' ' => control.toggle_pause(),
                        b's' | b'n' => control.step(),
                        b'+' | b'=' => control.set_rate(control.rate() * 2.0),
                        b'-' | b'_' => control.set_rate(control.rate() / 2.0),
                        b'q' => {
                            control.stop();
                            break;
                        }
                        _ => {}
                    }
                }
            });
        Keys { saved }
    }
}

impl Drop for Keys {
    fn drop(&mut self) {
        if let Some(saved) = &self.saved {
            let _ = nix::sys::termios::tcsetattr(
                std::io::stdin().as_fd(),
                nix::sys::termios::SetArg::TCSANOW,
                saved,
            );
        }
    }
}

fn parse_remap(text: &str) -> Result<(String, String), String> {
    match text.split_once('=') {
        Some((old, new)) if !old.is_empty() && !new.is_empty() => {
            Ok((old.to_owned(), new.to_owned()))
        }
        _ => Err(format!("{text:?}: a remapping is OLD=NEW")),
    }
}

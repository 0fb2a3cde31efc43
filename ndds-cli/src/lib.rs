//! The `ndds` command as a library: the binary's `main` ([`main`]), and [`run_main`], which
//! gives a program of your own the whole `ndds run` behaviour (loading and checking a
//! description file, `--check`, `--simulate`, the live status, Ctrl-C) with component types
//! of its own added to the built-in library:
//!
//! ```no_run
//! use ndds_runtime::{Component, Mat, RoutineResult, SampleContext, SampleModule};
//!
//! /// Doubles its input.
//! #[derive(Component)]
//! #[component(name = "double")]
//! struct Double {
//!     /// u
//!     #[input]
//!     input: Mat,
//!     /// 2·u, the shape of u
//!     #[output(same_as = input)]
//!     output: Mat,
//! }
//!
//! impl SampleModule for Double {
//!     fn execute(&mut self, _: &SampleContext) -> RoutineResult {
//!         let u = self.input.read().matrix().clone();
//!         self.output.write().matrix_mut().copy_from(&(u * 2.0));
//!         Ok(())
//!     }
//! }
//!
//! fn main() -> std::process::ExitCode {
//!     // `my-system FILE [--check] [--simulate 10] [--seconds 5] ...`: every `ndds run` flag.
//!     ndds_cli::run_main("my-system", |library| {
//!         library.add::<Double>();
//!     })
//! }
//! ```
//!
//! Every subcommand talks to the local daemon of the domain (`--domain`, `--socket`,
//! `NDDS_DOMAIN`, `NDDS_SOCKET`) as a tool; none starts an embedded daemon, so "no daemon
//! running" is reported instead of silently showing an empty domain (`ndds run` and
//! [`run_main`] start an embedded one when none runs, unless `--no-embedded`).

mod builtin;
mod cmd;
mod connect;
mod out;
mod render;
mod seconds;
mod status_term;
mod systems;

use clap::Parser;

pub use cmd::run::run_main;

/// The `ndds` command: parses the command line, runs the subcommand, and says what went
/// wrong on stderr.
pub fn main() -> std::process::ExitCode {
    let cli = cmd::Cli::parse();
    init_logging(cli.explains_mismatches());
    exit_code("ndds", cmd::run(cli))
}

/// The exit status of a command's outcome, its error (if any) said on stderr.
pub(crate) fn exit_code(program: &str, outcome: anyhow::Result<()>) -> std::process::ExitCode {
    match outcome {
        Ok(()) => std::process::ExitCode::SUCCESS,
        // `ndds topics | head -1`: the reader has all it wanted.
        Err(err) if out::is_closed(&err) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("{program}: {}", describe(&err));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The error and its causes, each once: library errors often say their cause in their own
/// message already (`habitat `h`: CSMat `u` has two writers ...`), and anyhow's `{:#}` would
/// repeat it.
fn describe(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}

/// Library warnings (incompatible types, undecodable samples, a lost daemon) go to stderr;
/// `RUST_LOG` chooses another level. They pass through the status screen, so `ndds run`'s
/// live status is erased and redrawn below each of them instead of hiding it. A command that
/// explains a mismatched endpoint in its own words (`quiet_mismatches`) does not also get the
/// library's warning about it.
pub(crate) fn init_logging(quiet_mismatches: bool) {
    let default = if quiet_mismatches {
        "warn,ndds_client::peers=error"
    } else {
        "warn"
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(status_term::LogWriter::default)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        // A closed stderr (a parent that went away) must not turn a log line into a panic.
        .log_internal_errors(false)
        .without_time()
        .try_init();
}

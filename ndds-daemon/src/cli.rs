//! The command line of `ndds-daemon`.

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Parser;
use tokio_util::sync::CancellationToken;

use crate::config::ConfigFile;
use crate::daemon::Daemon;

/// The ndds discovery daemon: run one per host and domain.
///
/// Clients on this host connect to it through its Unix socket; it finds the daemons of other
/// hosts over UDP multicast on the chosen interface, and by unicast through `--peers` where
/// multicast does not reach (`--no-multicast` turns multicast off). By default it uses the
/// loopback interface only: pass `--interface` (an address or a name such as eth0) to reach
/// other hosts.
#[derive(Debug, Parser)]
#[command(name = "ndds-daemon", version)]
pub struct Args {
    /// TOML config file with the settings below; flags and environment override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The settings, each also a key of the config file.
    #[command(flatten)]
    pub settings: ConfigFile,
}

/// Parses the command line, runs the daemon until SIGINT or SIGTERM, and returns how the
/// process should exit. An error is printed once, as one line on stderr (`ndds-daemon: ...`,
/// with its causes), never as a `Debug` dump or a backtrace, whatever `RUST_BACKTRACE` says.
pub fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            use std::io::Write as _;
            // A closed stderr must not turn the report into a panic.
            let _ = writeln!(std::io::stderr(), "ndds-daemon: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// [`main`] without the reporting.
pub fn run() -> anyhow::Result<()> {
    let args = Args::parse();
    init_logging();
    let file = match &args.config {
        Some(path) => ConfigFile::load(path)?,
        None => ConfigFile::default(),
    };
    let config = args.settings.or(file).resolve()?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the tokio runtime")?;
    runtime.block_on(async move {
        // Signals are caught from before the sockets exist: a SIGTERM during start-up still
        // ends in a clean shutdown (goodbye sent, socket file removed).
        let shutdown = CancellationToken::new();
        stop_on_signal(shutdown.clone())?;
        let daemon = Daemon::bind(config).await?;
        if daemon.config().interface.is_loopback() {
            tracing::info!(
                "discovery on loopback: this host only (--interface with a shared network's address or name reaches other hosts)"
            );
        }
        daemon.run(shutdown).await?;
        Ok(())
    })
}

/// Logs to stderr through tracing; `RUST_LOG` chooses the level (default `info`).
pub fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        // A closed stderr (a parent that went away) must not turn a log line into a panic.
        .log_internal_errors(false)
        .try_init();
}

/// Cancels `shutdown` on the first SIGINT or SIGTERM. The handlers are installed before this
/// returns, so a signal arriving at any later moment is caught.
fn stop_on_signal(shutdown: CancellationToken) -> anyhow::Result<()> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut int = signal(SignalKind::interrupt()).context("cannot catch SIGINT")?;
    let mut term = signal(SignalKind::terminate()).context("cannot catch SIGTERM")?;
    tokio::spawn(async move {
        let name = tokio::select! {
            _ = int.recv() => "SIGINT",
            _ = term.recv() => "SIGTERM",
        };
        // Cancel before logging: nothing may stand between a signal and the shutdown.
        shutdown.cancel();
        tracing::info!("{name}: shutting down");
    });
    Ok(())
}

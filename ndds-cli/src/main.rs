//! `ndds`: inspect and drive live ndds systems from the command line.
//!
//! Every subcommand talks to the local daemon of the domain (`--domain`, `--socket`,
//! `NDDS_DOMAIN`, `NDDS_SOCKET`) as a tool; none starts an embedded daemon, so "no daemon
//! running" is reported instead of silently showing an empty domain.

mod builtin;
mod cmd;
mod connect;
mod render;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = cmd::Cli::parse();
    match cmd::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("ndds: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

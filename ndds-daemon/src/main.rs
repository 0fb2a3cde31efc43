//! `ndds-daemon`: see [`ndds_daemon::cli`].

fn main() -> std::process::ExitCode {
    ndds_daemon::cli::main()
}

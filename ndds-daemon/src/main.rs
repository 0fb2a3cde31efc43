//! `ndds-daemon`: see [`ndds_daemon::cli`].

fn main() -> anyhow::Result<()> {
    ndds_daemon::cli::main()
}

//! `ndds`: inspect and drive live ndds systems from the command line (the library's
//! [`ndds_cli::main`]).

fn main() -> std::process::ExitCode {
    ndds_cli::main()
}

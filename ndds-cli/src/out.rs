//! Printing to standard output for every command, where a closed pipe is a normal end.
//!
//! `ndds topics | head -1` closes the pipe while `ndds` is still writing. `println!` panics
//! then ("failed printing to stdout: Broken pipe"); [`outln!`](crate::outln) and
//! [`out!`](crate::out!) return an [`Error`] instead, and `main` ends the command quietly with
//! exit status 0 when the error is [`Error::Closed`] (see [`is_closed`]). Any other write error
//! (a full disk behind `> file`) stays an error with a message.
//!
//! Use them as `println!`/`print!`, with `?`, in a function returning `anyhow::Result`:
//!
//! ```text
//! use crate::outln;
//!
//! fn print_state(state: &State) -> anyhow::Result<()> {
//!     outln!("state       {}", state.name)?;
//!     Ok(())
//! }
//! ```
//!
//! Each call writes to a locked stdout and flushes, so nothing is left in a buffer to fail
//! later at exit. Only stdout is covered: a BrokenPipe from anywhere else (the daemon's socket)
//! is not [`Error::Closed`] and is reported as usual.

use std::fmt;
use std::io::{self, Write as _};

/// Why a write to stdout failed.
#[derive(Debug)]
pub enum Error {
    /// Stdout's reader went away (`| head`): the command should end quietly, successfully.
    Closed,
    /// Any other write error on stdout.
    Write(io::Error),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Closed => f.write_str("standard output closed"),
            Error::Write(err) => write!(f, "writing to standard output: {err}"),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Closed => None,
            Error::Write(err) => Some(err),
        }
    }
}

/// Writes `args` to stdout and flushes; what [`out!`](crate::out!) and
/// [`outln!`](crate::outln) expand to.
pub fn write(args: fmt::Arguments<'_>) -> Result<(), Error> {
    let mut stdout = io::stdout().lock();
    stdout
        .write_fmt(args)
        .and_then(|()| stdout.flush())
        .map_err(|err| match err.kind() {
            io::ErrorKind::BrokenPipe => Error::Closed,
            _ => Error::Write(err),
        })
}

/// Whether `err` (or an error in its chain, under any context) is [`Error::Closed`].
pub fn is_closed(err: &anyhow::Error) -> bool {
    err.chain()
        .any(|cause| matches!(cause.downcast_ref::<Error>(), Some(Error::Closed)))
}

/// `print!` to stdout returning `Result<(), out::Error>` instead of panicking on a closed pipe.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::out::write(format_args!($($arg)*))
    };
}

/// `println!` to stdout returning `Result<(), out::Error>` instead of panicking on a closed
/// pipe: `outln!("{name}  ({count} producers)")?;`.
#[macro_export]
macro_rules! outln {
    () => {
        $crate::out::write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::out::write(format_args!("{}\n", format_args!($($arg)*)))
    };
}

#[cfg(test)]
mod tests {
    use anyhow::Context as _;

    use super::*;

    #[test]
    fn a_closed_stdout_is_recognised_under_context_and_nothing_else_is() {
        let closed = anyhow::Error::from(Error::Closed).context("printing topics");
        assert!(is_closed(&closed));
        let failed: anyhow::Result<()> =
            Err(Error::Write(io::Error::from(io::ErrorKind::StorageFull))).context("printing");
        assert!(!is_closed(&failed.unwrap_err()));
        // A broken pipe elsewhere (the daemon's socket) is not a closed stdout.
        let socket = anyhow::Error::from(io::Error::from(io::ErrorKind::BrokenPipe));
        assert!(!is_closed(&socket));
    }
}

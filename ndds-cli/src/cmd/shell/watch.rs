//! `watch MAT [SECONDS]`: a CSMat's table, again and again. On a terminal (standard input
//! and output both) the table is redrawn in place about 5 times a second (through the
//! process's status screen, so log lines stay above it) until Enter, `q` or Ctrl-C, or until
//! SECONDS have passed; otherwise a snapshot is printed every second for SECONDS
//! ([`SNAPSHOT_SECONDS`] by default).

use std::io::{IsTerminal as _, Read as _};
use std::os::fd::AsFd as _;
use std::time::{Duration, Instant};

use nix::sys::termios::{self, LocalFlags, SetArg, SpecialCharacterIndices, Termios};

use super::session::Session;
use super::table;
use crate::out;
use crate::status_term::screen;

/// Between two redraws on a terminal.
const REDRAW: Duration = Duration::from_millis(200);

/// How long `watch` prints snapshots when not on a terminal and no SECONDS are given.
pub const SNAPSHOT_SECONDS: f64 = 3.0;

/// Runs `watch`.
pub fn run(session: &Session, mat: &str, seconds: Option<f64>) -> anyhow::Result<()> {
    let description = session.check(|v| v.mat(mat).cloned())?;
    let draw = |elapsed: Duration, footer: &str| -> anyhow::Result<String> {
        let values = session.read_mat(mat)?;
        let table = table::mat_table(mat, Some(&description), &values);
        Ok(format!(
            "{table}t = {:.1} s{footer}\n",
            elapsed.as_secs_f64()
        ))
    };
    let limit = seconds.map(Duration::from_secs_f64);
    if std::io::stdin().is_terminal() && std::io::stdout().is_terminal() {
        in_place(limit, draw)
    } else {
        let limit = limit.unwrap_or(Duration::from_secs_f64(SNAPSHOT_SECONDS));
        snapshots(limit, draw)
    }
}

/// Redraws until a key or the limit.
fn in_place(
    limit: Option<Duration>,
    draw: impl Fn(Duration, &str) -> anyhow::Result<String>,
) -> anyhow::Result<()> {
    let keys = Keys::catch();
    let started = Instant::now();
    screen().go_live(std::io::stderr().is_terminal());
    let outcome = loop {
        let elapsed = started.elapsed();
        let block = match draw(elapsed, "; Enter, q or Ctrl-C stops") {
            Ok(block) => block,
            Err(err) => break Err(err),
        };
        screen().draw(&block);
        let left = limit.map(|l| l.saturating_sub(started.elapsed()));
        if left.is_some_and(|l| l.is_zero()) {
            break Ok(());
        }
        if keys.stop_within(left.map_or(REDRAW, |l| l.min(REDRAW))) {
            break Ok(());
        }
    };
    screen().release();
    outcome
}

/// A snapshot now and then every second while less than `limit` has passed.
fn snapshots(
    limit: Duration,
    draw: impl Fn(Duration, &str) -> anyhow::Result<String>,
) -> anyhow::Result<()> {
    let started = Instant::now();
    let mut next = Duration::ZERO;
    while next < limit || next.is_zero() {
        if let Some(wait) = next.checked_sub(started.elapsed()) {
            std::thread::sleep(wait);
        }
        out!("{}\n", draw(started.elapsed(), "")?)?;
        next += Duration::from_secs(1);
    }
    Ok(())
}

/// The terminal taking keys one by one, unechoed, with Ctrl-C a key rather than a signal,
/// and a read that gives up after a tenth of a second; restored on drop.
struct Keys {
    saved: Option<Termios>,
}

impl Keys {
    fn catch() -> Self {
        let stdin = std::io::stdin();
        let saved = termios::tcgetattr(stdin.as_fd()).ok();
        if let Some(saved) = &saved {
            let mut keys = saved.clone();
            keys.local_flags
                .remove(LocalFlags::ICANON | LocalFlags::ECHO | LocalFlags::ISIG);
            keys.control_chars[SpecialCharacterIndices::VMIN as usize] = 0;
            keys.control_chars[SpecialCharacterIndices::VTIME as usize] = 1;
            let _ = termios::tcsetattr(stdin.as_fd(), SetArg::TCSANOW, &keys);
        }
        Keys { saved }
    }

    /// Whether Enter, `q`, Ctrl-C or Ctrl-D comes within about `wait`.
    fn stop_within(&self, wait: Duration) -> bool {
        if self.saved.is_none() {
            // Not a terminal after all: nothing stops it but the limit.
            std::thread::sleep(wait);
            return false;
        }
        let until = Instant::now() + wait;
        let mut stdin = std::io::stdin().lock();
        let mut bytes = [0u8; 64];
        loop {
            // Returns after a tenth of a second without a key (VTIME), with 0 bytes.
            let read = stdin.read(&mut bytes).unwrap_or(0);
            let keys = &bytes[..read];
            if keys
                .iter()
                .any(|k| matches!(k, b'\r' | b'\n' | b'q' | 0x03 | 0x04))
            {
                return true;
            }
            if Instant::now() >= until {
                return false;
            }
        }
    }
}

impl Drop for Keys {
    fn drop(&mut self) {
        if let Some(saved) = &self.saved {
            let _ = termios::tcsetattr(std::io::stdin().as_fd(), SetArg::TCSANOW, saved);
        }
    }
}

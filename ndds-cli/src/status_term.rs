//! The terminal under `ndds run`'s live status: a block redrawn in place that never hides a
//! message.
//!
//! One [`Screen`] per process owns stdout's status block and every line written around it:
//! status reports, the events `ndds run` prints (configuration switches, state changes), and
//! log lines (tracing's writer is [`LogWriter`]). While a block is live on a terminal, each
//! line is written *above* it: erase the block (`ESC[nA ESC[J`), write the line, redraw the
//! block, all under the screen's lock so no two writers interleave. Lines scroll up and stay;
//! only the block is ever erased.
//!
//! The block is drawn with auto-wrap off (`ESC[?7l` … `ESC[?7h`), so a line wider than the
//! terminal is cut instead of wrapped and the block takes exactly as many rows as it has
//! lines: erasing it never leaves stray rows. (A block taller than the terminal still cannot
//! be erased completely.)
//!
//! Log lines are formatted by tracing before the lock is taken; the critical section is a few
//! writes of at most a screenful. A habitat thread that logs waits at most for one redraw.
//!
//! Without a live block (`--plain`, stdout not a terminal, any other command) everything is
//! appended as written: reports to stdout, logs to stderr.

use std::io::{self, Write};
use std::sync::{LazyLock, Mutex, MutexGuard, PoisonError};

/// Auto-wrap off and on (DECAWM), around the block.
const WRAP_OFF: &[u8] = b"\x1b[?7l";
const WRAP_ON: &[u8] = b"\x1b[?7h";

/// A status block on `out` with the lines written around it (`err` takes log lines).
pub struct Screen<O, E> {
    out: O,
    err: E,
    /// The block as last drawn (kept to redraw it under a new line).
    block: String,
    /// Rows of the block on screen now (0: none, or not redrawing in place).
    drawn: usize,
    /// Whether the block is redrawn in place (a terminal, not `--plain`).
    in_place: bool,
    /// Whether `err` shows on the same terminal (else a log line needs no erasing).
    err_on_screen: bool,
}

impl<O: Write, E: Write> Screen<O, E> {
    /// A screen appending everything (nothing live yet).
    pub fn new(out: O, err: E) -> Self {
        Self {
            out,
            err,
            block: String::new(),
            drawn: 0,
            in_place: false,
            err_on_screen: false,
        }
    }

    /// From now on, [`draw`](Self::draw) redraws in place; `err_on_screen` says whether log
    /// lines land on the same terminal.
    pub fn go_live(&mut self, err_on_screen: bool) {
        self.in_place = true;
        self.err_on_screen = err_on_screen;
    }

    /// Stops redrawing: the last block stays on screen, later lines go below it.
    pub fn release(&mut self) {
        if self.in_place && self.drawn > 0 {
            // Whatever the terminal echoed below the block (`^C`) goes.
            let _ = self.out.write_all(b"\r\x1b[J");
            let _ = self.out.flush();
        }
        self.in_place = false;
        self.drawn = 0;
        self.block.clear();
    }

    /// Shows a new status block: in place of the last one when live, else appended.
    pub fn draw(&mut self, block: &str) {
        if !self.in_place {
            let _ = self.out.write_all(block.as_bytes());
            let _ = self.out.flush();
            return;
        }
        self.erase();
        self.block.clear();
        self.block.push_str(block);
        self.redraw();
    }

    /// Writes lines of `ndds run`'s own (events) to `out`, above the block.
    pub fn print(&mut self, text: &str) {
        let live = self.in_place && self.drawn > 0;
        if live {
            self.erase();
        }
        let _ = self.out.write_all(text.as_bytes());
        let _ = self.out.flush();
        if live {
            self.redraw();
        }
    }

    /// Writes a log line to `err`, above the block if both share the terminal.
    pub fn log(&mut self, line: &[u8]) -> io::Result<()> {
        let live = self.in_place && self.drawn > 0 && self.err_on_screen;
        if live {
            self.erase();
        }
        let written = self.err.write_all(line).and_then(|()| self.err.flush());
        if live {
            self.redraw();
        }
        written
    }

    fn erase(&mut self) {
        if self.drawn > 0 {
            let _ = write!(self.out, "\x1b[{}A\x1b[J", self.drawn);
            self.drawn = 0;
        }
        let _ = self.out.flush();
    }

    fn redraw(&mut self) {
        let _ = self.out.write_all(WRAP_OFF);
        let _ = self.out.write_all(self.block.as_bytes());
        let _ = self.out.write_all(WRAP_ON);
        let _ = self.out.flush();
        self.drawn = self.block.lines().count();
    }
}

/// The process's screen: stdout and stderr.
static SCREEN: LazyLock<Mutex<Screen<io::Stdout, io::Stderr>>> =
    LazyLock::new(|| Mutex::new(Screen::new(io::stdout(), io::stderr())));

/// The process's screen, locked (hold it only to write).
pub fn screen() -> MutexGuard<'static, Screen<io::Stdout, io::Stderr>> {
    SCREEN.lock().unwrap_or_else(PoisonError::into_inner)
}

/// tracing's writer: each event (tracing formats it first, then writes it whole) goes through
/// [`Screen::log`]. Use as `.with_writer(LogWriter::default)`.
#[derive(Default)]
pub struct LogWriter;

impl Write for LogWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        screen().log(buf)?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::cell::RefCell;
    use std::rc::Rc;

    use super::*;

    /// One terminal: stdout and stderr into the same bytes, in order.
    #[derive(Clone, Default)]
    struct Terminal(Rc<RefCell<Vec<u8>>>);

    impl Write for Terminal {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            self.0.borrow_mut().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Terminal {
        fn take(&self) -> String {
            String::from_utf8(std::mem::take(&mut *self.0.borrow_mut())).unwrap()
        }
    }

    fn live() -> (Screen<Terminal, Terminal>, Terminal) {
        let terminal = Terminal::default();
        let mut screen = Screen::new(terminal.clone(), terminal.clone());
        screen.go_live(true);
        (screen, terminal)
    }

    const BLOCK: &str = "arm  t=1.0s\n  habitat ...\n  servo ...\n";

    #[test]
    fn a_log_line_goes_above_the_block_which_is_redrawn() {
        let (mut screen, terminal) = live();
        screen.draw(BLOCK);
        assert_eq!(terminal.take(), format!("\x1b[?7l{BLOCK}\x1b[?7h"));
        screen.log(b"WARN something happened\n").unwrap();
        assert_eq!(
            terminal.take(),
            format!("\x1b[3A\x1b[JWARN something happened\n\x1b[?7l{BLOCK}\x1b[?7h"),
            "erase the 3-line block, write the line, redraw the block"
        );
    }

    #[test]
    fn a_new_block_replaces_the_last_one_and_events_stay_above_it() {
        let (mut screen, terminal) = live();
        screen.draw(BLOCK);
        screen.print("t=1.2s  fsm arm: Idle -> Coarse\n");
        let shorter = "arm  t=2.0s\n";
        terminal.take();
        screen.draw(shorter);
        assert_eq!(
            terminal.take(),
            format!("\x1b[3A\x1b[J\x1b[?7l{shorter}\x1b[?7h"),
            "only the block is erased (the event was written before the block was redrawn)"
        );
        screen.log(b"WARN late\n").unwrap();
        assert!(terminal.take().starts_with("\x1b[1A\x1b[JWARN late\n"));
    }

    #[test]
    fn before_the_first_block_and_when_plain_nothing_is_erased() {
        let (mut screen, terminal) = live();
        screen.log(b"WARN early\n").unwrap();
        assert_eq!(terminal.take(), "WARN early\n");
        let terminal = Terminal::default();
        let mut plain = Screen::new(terminal.clone(), terminal.clone());
        plain.draw(BLOCK);
        plain.log(b"WARN x\n").unwrap();
        plain.draw(BLOCK);
        assert_eq!(terminal.take(), format!("{BLOCK}WARN x\n{BLOCK}"));
    }

    #[test]
    fn logs_to_another_place_than_the_terminal_leave_the_block_alone() {
        let out = Terminal::default();
        let err = Terminal::default();
        let mut screen = Screen::new(out.clone(), err.clone());
        screen.go_live(false);
        screen.draw(BLOCK);
        out.take();
        screen.log(b"WARN to a file\n").unwrap();
        assert_eq!(
            (out.take(), err.take()),
            (String::new(), "WARN to a file\n".into())
        );
    }

    #[test]
    fn released_the_block_stays_and_lines_append_below() {
        let (mut screen, terminal) = live();
        screen.draw(BLOCK);
        terminal.take();
        screen.release();
        assert_eq!(
            terminal.take(),
            "\r\x1b[J",
            "only what was echoed below the block"
        );
        screen.print("ndds run: stopped\n");
        screen.log(b"WARN after\n").unwrap();
        assert_eq!(terminal.take(), "ndds run: stopped\nWARN after\n");
    }
}

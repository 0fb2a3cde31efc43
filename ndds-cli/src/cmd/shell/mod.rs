//! `ndds shell`: the operator's console on a running system (ControlShell's menu system).
//! `ls`, `show`, `watch`, `stats`, `set`, `switch`, `habitat`, `reset`, `send`, `query`,
//! `help`, `quit`; interactively with line editing, history and TAB completion of the live
//! system's names, or from `-c 'CMD; CMD'`, `--script FILE` or a pipe.
//!
//! Layout:
//! - [`commands`]: `parse` (a line to a [`ShellCommand`](commands::ShellCommand)) and
//!   `split` (a script into commands), pure;
//! - [`help`]: the command table, what `help` prints;
//! - [`view`]: the system's description and ports, and lookups that say what exists, pure;
//! - [`complete`]: TAB completion candidates from a view, pure;
//! - [`table`]: the text of `show`, `stats` and `ls`, pure;
//! - [`session`]: the requests to the system and the printing of the answers;
//! - [`watch`]: `watch`, redrawn in place on a terminal;
//! - [`interactive`]: the line editor loop.

mod commands;
mod complete;
mod help;
mod interactive;
mod session;
mod table;
mod view;
mod watch;

use std::io::{IsTerminal as _, Read as _};
use std::path::PathBuf;
use std::rc::Rc;
use std::time::Duration;

use anyhow::Context as _;

use self::commands::ScriptLine;
use self::session::{Flow, Session};
use crate::connect::{DaemonArgs, connect};
use crate::{seconds, systems};

/// Options of `ndds shell`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The system to work on (default: the one running).
    #[arg(long)]
    system: Option<String>,
    /// Run these commands (separated by `;` or newlines) and exit.
    #[arg(
        short = 'c',
        long = "command",
        value_name = "COMMANDS",
        conflicts_with = "script"
    )]
    commands: Option<String>,
    /// Run the commands of FILE (one a line, `#` starts a comment) and exit.
    #[arg(long, value_name = "FILE")]
    script: Option<PathBuf>,
    /// With -c, --script or a pipe: go on after a failing command (the exit status is still 1).
    #[arg(long)]
    keep_going: bool,
    /// Seconds to wait for the system's answers.
    #[arg(long, value_parser = seconds::parse, default_value = "5")]
    wait: Duration,
}

/// Runs `ndds shell`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    // A missing script is said before anything connects.
    let script = match (&args.commands, &args.script) {
        (Some(text), _) => Some((None, text.clone())),
        (None, Some(file)) => {
            let text = std::fs::read_to_string(file)
                .with_context(|| format!("cannot read script {}", file.display()))?;
            Some((Some(file.display().to_string()), text))
        }
        (None, None) => None,
    };
    let participant = connect(daemon)?;
    let link = systems::choose(&participant, args.system.as_deref(), None, args.wait)?;
    let session = Rc::new(Session::open(participant, link, args.wait)?);
    match script {
        Some((origin, text)) => run_script(&session, origin.as_deref(), &text, args.keep_going),
        None if std::io::stdin().is_terminal() => interactive::run(session),
        None => {
            let mut text = String::new();
            std::io::stdin()
                .read_to_string(&mut text)
                .context("cannot read commands from standard input")?;
            run_script(&session, Some("<stdin>"), &text, args.keep_going)
        }
    }
}

/// Runs the commands of `text` in order; the first that fails ends it with its error
/// (prefixed with `origin:LINE: ` when the text came from a file), unless `keep_going`: then
/// each error is said and the others run, and the outcome is an error if any failed.
fn run_script(
    session: &Session,
    origin: Option<&str>,
    text: &str,
    keep_going: bool,
) -> anyhow::Result<()> {
    let commands = commands::split(text);
    let mut failed = 0;
    for ScriptLine { line, text } in &commands {
        let outcome = commands::parse(text)
            .map_err(anyhow::Error::msg)
            .and_then(|command| session.execute(&command));
        let err = match outcome {
            Ok(Flow::Quit) => break,
            Ok(Flow::Continue) => continue,
            Err(err) => match origin {
                Some(origin) => err.context(format!("{origin}:{line}")),
                None => err,
            },
        };
        if !keep_going || crate::out::is_closed(&err) {
            return Err(err);
        }
        failed += 1;
        report(err);
    }
    if failed > 0 {
        anyhow::bail!("{failed} of {} commands failed", commands.len());
    }
    Ok(())
}

/// Says `err` on stderr the way `ndds` says a command's error (`ndds: ...`), and goes on.
fn report(err: anyhow::Error) {
    let _ = crate::exit_code("ndds", Err(err));
}

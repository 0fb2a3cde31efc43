//! The interactive shell: a line editor (rustyline) with history kept in a file and TAB
//! completion of the live system's names; each line's commands run in turn, and an error is
//! said and the shell goes on. Ctrl-C clears the line; Ctrl-D (or `quit`) leaves.

use std::path::PathBuf;
use std::rc::Rc;

use rustyline::completion::{Completer, Pair};
use rustyline::error::ReadlineError;
use rustyline::highlight::Highlighter;
use rustyline::hint::Hinter;
use rustyline::history::FileHistory;
use rustyline::validate::Validator;
use rustyline::{CompletionType, Config, Context, Editor, Helper};

use super::session::{Flow, Session};
use super::{commands, complete, report};
use crate::outln;

/// Lines of history kept.
const HISTORY_LINES: usize = 1000;

/// Runs the shell on the terminal until `quit` or Ctrl-D.
pub fn run(session: Rc<Session>) -> anyhow::Result<()> {
    let config = Config::builder()
        .max_history_size(HISTORY_LINES)?
        .history_ignore_dups(true)?
        .history_ignore_space(true)
        .completion_type(CompletionType::List)
        .auto_add_history(false)
        .build();
    let mut editor: Editor<ShellHelper, FileHistory> = Editor::with_config(config)?;
    editor.set_helper(Some(ShellHelper {
        session: Rc::clone(&session),
    }));
    let history = history_path();
    if let Some(path) = &history {
        // None yet (the first session), or unreadable: start without.
        let _ = editor.load_history(path);
    }
    let view = session.completion_view();
    outln!(
        "ndds shell on system `{}` (habitats: {}); `help` lists the commands, TAB completes, \
         Ctrl-D leaves",
        session.name(),
        super::view::listed(&view.habitats())
    )?;
    let prompt = format!("{}> ", session.name());
    loop {
        let line = match editor.readline(&prompt) {
            Ok(line) => line,
            Err(ReadlineError::Interrupted) => continue,
            Err(ReadlineError::Eof) => {
                outln!()?;
                return Ok(());
            }
            Err(err) => return Err(err.into()),
        };
        if line.trim().is_empty() {
            continue;
        }
        let _ = editor.add_history_entry(line.trim());
        if let Some(path) = &history {
            remember(&mut editor, path);
        }
        for command in commands::split(&line) {
            let outcome = commands::parse(&command.text)
                .map_err(anyhow::Error::msg)
                .and_then(|parsed| session.execute(&parsed));
            match outcome {
                Ok(Flow::Quit) => return Ok(()),
                Ok(Flow::Continue) => {}
                Err(err) if crate::out::is_closed(&err) => return Err(err),
                Err(err) => report(err),
            }
        }
    }
}

/// `$XDG_STATE_HOME/ndds/shell_history`, else `~/.local/state/ndds/shell_history`.
fn history_path() -> Option<PathBuf> {
    let absolute = |v: std::ffi::OsString| Some(PathBuf::from(v)).filter(|p| p.is_absolute());
    let state = std::env::var_os("XDG_STATE_HOME")
        .and_then(absolute)
        .or_else(|| {
            std::env::var_os("HOME")
                .and_then(absolute)
                .map(|h| h.join(".local/state"))
        })?;
    Some(state.join("ndds").join("shell_history"))
}

/// Adds the new history lines to the file; a file that cannot be written is no reason to
/// stop (the history of this session is still there).
fn remember(editor: &mut Editor<ShellHelper, FileHistory>, path: &std::path::Path) {
    if let Some(dir) = path.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let _ = editor.append_history(path);
}

/// The line editor's view of the shell: completion from the live system.
struct ShellHelper {
    session: Rc<Session>,
}

impl Completer for ShellHelper {
    type Candidate = Pair;

    fn complete(
        &self,
        line: &str,
        pos: usize,
        _: &Context<'_>,
    ) -> rustyline::Result<(usize, Vec<Pair>)> {
        let view = self.session.completion_view();
        let (start, words) = complete::candidates(&view, line, pos);
        let pairs = words.into_iter().map(|word| Pair {
            // A whole word is followed by a space; a condition's `Name=` by its value.
            replacement: if word.ends_with('=') {
                word.clone()
            } else {
                format!("{word} ")
            },
            display: word,
        });
        Ok((start, pairs.collect()))
    }
}

impl Hinter for ShellHelper {
    type Hint = String;
}

impl Highlighter for ShellHelper {}

impl Validator for ShellHelper {}

impl Helper for ShellHelper {}

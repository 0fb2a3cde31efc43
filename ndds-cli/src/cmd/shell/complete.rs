//! TAB completion: which words fit where the cursor is, from the command being typed and the
//! live system's names ([`SystemView`]). Pure: the line editor's glue (`interactive`) asks
//! [`candidates`] and inserts what it answers.
//!
//! | after            | completes                                     |
//! |------------------|-----------------------------------------------|
//! | nothing, `;`     | command names                                 |
//! | `ls`             | habitats, modules, mats, ...                  |
//! | `show`, `watch`  | CSMats                                        |
//! | `module`         | modules                                       |
//! | `set`            | CSMats no module writes                       |
//! | `switch`         | configurations                                |
//! | `habitat`, `reset` | habitats; after `habitat NAME`: the actions |
//! | `send`           | machines; then that machine's stimuli (`Name=` for a condition) |
//! | `query`          | ports declared in description files           |
//! | `help`           | command names                                 |

use ndds_runtime::fsm::StimulusKind;

use super::commands::Listing;
use super::help::command_names;
use super::view::SystemView;

/// Where the word being completed starts in `line` (a byte offset) and the words that may
/// replace it, sorted: those starting with it (in its case if any do, else in any case).
pub fn candidates(view: &SystemView, line: &str, pos: usize) -> (usize, Vec<String>) {
    let pos = floor_char_boundary(line, pos.min(line.len()));
    let before = &line[..pos];
    let segment_start = before.rfind(';').map_or(0, |at| at + 1);
    let segment = &before[segment_start..];
    let word_start = segment
        .char_indices()
        .rev()
        .find(|(_, c)| c.is_whitespace())
        .map_or(0, |(at, c)| at + c.len_utf8());
    let word = &segment[word_start..];
    let args: Vec<&str> = segment[..word_start].split_whitespace().collect();
    let pool: Vec<String> = match args.split_first() {
        None => owned(command_names()),
        Some((command, rest)) => arguments(view, command, rest),
    };
    (segment_start + word_start, matching(pool, word))
}

/// The words that fit as the next argument of `command` after `rest`.
fn arguments(view: &SystemView, command: &str, rest: &[&str]) -> Vec<String> {
    match (command, rest) {
        ("ls", []) => owned(Listing::ALL.map(Listing::word)),
        ("show" | "watch", []) => owned(view.mats()),
        ("module", []) => owned(view.modules()),
        ("set", []) => owned(view.settable_mats()),
        ("switch", []) => owned(view.configurations()),
        ("habitat" | "reset", []) => owned(view.habitats()),
        ("habitat", [_]) => owned(["rate", "reset", "start", "stop"]),
        ("send", []) => owned(view.machines()),
        ("send", [machine, ..]) => stimuli(view, machine),
        ("query", []) => owned(view.declared_ports()),
        ("help", []) => owned(command_names()),
        _ => Vec::new(),
    }
}

/// A machine's stimuli; a condition as `Name=`, for its value to follow.
fn stimuli(view: &SystemView, machine: &str) -> Vec<String> {
    let Ok(machine) = view.machine(machine) else {
        return Vec::new();
    };
    (machine.stimuli.iter())
        .map(|(name, kind)| match kind {
            StimulusKind::Condition => format!("{name}="),
            _ => name.clone(),
        })
        .collect()
}

fn owned<'a>(words: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    words.into_iter().map(str::to_owned).collect()
}

/// The words of `pool` that start with `word`, sorted and each once.
fn matching(pool: Vec<String>, word: &str) -> Vec<String> {
    let mut exact: Vec<String> = pool
        .iter()
        .filter(|w| w.starts_with(word))
        .cloned()
        .collect();
    if exact.is_empty() {
        let lower = word.to_lowercase();
        exact = pool
            .into_iter()
            .filter(|w| w.to_lowercase().starts_with(&lower))
            .collect();
    }
    exact.sort();
    exact.dedup();
    exact
}

/// The largest char boundary of `text` at or before `at`.
fn floor_char_boundary(text: &str, mut at: usize) -> usize {
    while !text.is_char_boundary(at) {
        at -= 1;
    }
    at
}

#[cfg(test)]
mod tests {
    use super::super::view::tests::arm;
    use super::*;

    fn complete(line: &str) -> (usize, Vec<String>) {
        candidates(&arm(), line, line.len())
    }

    #[test]
    fn the_first_word_is_a_command() {
        assert_eq!(complete(""), (0, owned(sorted(command_names()))));
        assert_eq!(
            complete("s"),
            (0, owned(["send", "set", "show", "stats", "switch"]))
        );
        assert_eq!(complete("m"), (0, owned(["module"])));
        assert_eq!(complete("  he"), (2, owned(["help"])));
        // After a `;`, a new command.
        assert_eq!(complete("ls; sw"), (4, owned(["switch"])));
        assert_eq!(complete("stats;qui"), (6, owned(["quit"])));
    }

    #[test]
    fn arguments_come_from_the_live_system() {
        assert_eq!(
            complete("show joint_"),
            (5, owned(["joint_error", "joint_goal"]))
        );
        assert_eq!(complete("watch e"), (6, owned(["endpoint_goal"])));
        assert_eq!(
            complete("module joint"),
            (7, owned(["joint_error", "joint_pd"]))
        );
        // `set` offers only what can be set.
        assert_eq!(
            complete("set "),
            (4, owned(["endpoint_goal", "joint_goal"]))
        );
        assert_eq!(complete("switch e"), (7, owned(["endptLQG"])));
        assert_eq!(complete("habitat "), (8, owned(["control", "plant"])));
        assert_eq!(
            complete("habitat control r"),
            (16, owned(["rate", "reset"]))
        );
        assert_eq!(complete("reset p"), (6, owned(["plant"])));
        assert_eq!(complete("ls c"), (3, owned(["configurations"])));
        assert_eq!(complete("send "), (5, owned(["arm"])));
        assert_eq!(complete("send arm P"), (9, owned(["Precise"])));
        // A condition is completed up to its `=`; stimuli go on after the first.
        assert_eq!(complete("send arm Coarse O"), (16, owned(["Object="])));
        assert_eq!(complete("query "), (6, owned(["arm-configure"])));
        assert_eq!(complete("help wa"), (5, owned(["watch"])));
    }

    #[test]
    fn case_is_ignored_only_when_nothing_matches_in_case() {
        assert_eq!(complete("switch j"), (7, owned(["JointPD"])));
        assert_eq!(complete("switch ENDPT"), (7, owned(["endptLQG"])));
    }

    #[test]
    fn nothing_fits_where_no_argument_goes() {
        assert_eq!(complete("stats "), (6, Vec::new()));
        assert_eq!(complete("show joint_goal "), (16, Vec::new()));
        assert_eq!(complete("send nobody P"), (12, Vec::new()));
        assert_eq!(complete("frob "), (5, Vec::new()));
    }

    #[test]
    fn the_cursor_may_be_inside_the_line() {
        let line = "show jo; stats";
        assert_eq!(
            candidates(&arm(), line, 7),
            (5, owned(["joint_error", "joint_goal", "joints"]))
        );
        // A position inside a multi-byte character counts from the character's start.
        assert_eq!(candidates(&arm(), "show é", 6).0, 5);
    }

    fn sorted(mut words: Vec<&'static str>) -> Vec<&'static str> {
        words.sort();
        words
    }
}

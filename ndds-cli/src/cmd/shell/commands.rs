//! The shell's commands parsed: [`parse`] turns a line into a [`ShellCommand`] or says what
//! is wrong with it, without the system (names are checked against the system when the
//! command runs); [`split`] cuts `-c` text and scripts into commands.

use ndds_runtime::HabitatAction;

use super::help::{help_of, unknown};

/// The longest `watch MAT SECONDS` (a day).
const MAX_WATCH_SECONDS: f64 = 86_400.0;

/// One command, parsed.
#[derive(Clone, Debug, PartialEq)]
pub enum ShellCommand {
    /// `ls [WHAT]`: everything, or one kind.
    Ls(Option<Listing>),
    /// `show MAT`.
    Show(String),
    /// `module NAME`.
    Module(String),
    /// `watch MAT [SECONDS]`.
    Watch {
        /// The CSMat.
        mat: String,
        /// How long (until a key, without).
        seconds: Option<f64>,
    },
    /// `stats`.
    Stats,
    /// `set MAT V1 V2 ...`.
    Set {
        /// The CSMat.
        mat: String,
        /// Its values, row-major.
        values: Vec<f64>,
    },
    /// `switch CONFIG`.
    Switch(String),
    /// `habitat NAME rate HZ | reset | start | stop`, and `reset NAME`.
    Habitat {
        /// The habitat.
        habitat: String,
        /// What to do.
        action: HabitatAction,
    },
    /// `send MACHINE STIMULUS[=VALUE]...`.
    Send {
        /// The machine.
        machine: String,
        /// The stimuli as typed.
        stimuli: Vec<String>,
    },
    /// `query PORT TEXT...`.
    Query {
        /// The port.
        port: String,
        /// The request: the rest of the line.
        text: String,
    },
    /// `help [COMMAND]`.
    Help(Option<String>),
    /// `quit`, `exit`.
    Quit,
}

impl ShellCommand {
    /// Whether it may change the system (then what the shell knows of it is fetched again).
    pub fn changes_the_system(&self) -> bool {
        matches!(
            self,
            ShellCommand::Set { .. }
                | ShellCommand::Switch(_)
                | ShellCommand::Habitat { .. }
                | ShellCommand::Send { .. }
                | ShellCommand::Query { .. }
        )
    }
}

/// What `ls` lists.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Listing {
    /// Habitats with rate, clock and execution order.
    Habitats,
    /// Modules with habitat, component and groups.
    Modules,
    /// CSMats with shape and fields.
    Mats,
    /// Configurations with their groups.
    Configurations,
    /// State machines with their stimuli.
    Machines,
    /// The ports of the system's process.
    Ports,
}

impl Listing {
    /// Every listing, in the order `ls` prints them.
    pub const ALL: [Listing; 6] = [
        Listing::Habitats,
        Listing::Modules,
        Listing::Mats,
        Listing::Configurations,
        Listing::Machines,
        Listing::Ports,
    ];

    /// Its word (`ls mats`).
    pub fn word(self) -> &'static str {
        match self {
            Listing::Habitats => "habitats",
            Listing::Modules => "modules",
            Listing::Mats => "mats",
            Listing::Configurations => "configurations",
            Listing::Machines => "machines",
            Listing::Ports => "ports",
        }
    }

    /// The listing a word names (plural or singular).
    fn parse(word: &str) -> Result<Listing, String> {
        let found = Listing::ALL
            .into_iter()
            .find(|l| word == l.word() || Some(word) == l.word().strip_suffix('s'));
        found.ok_or_else(|| {
            let words = Listing::ALL.map(Listing::word);
            format!(
                "`ls` cannot list `{word}`{}; it lists {}",
                super::view::hint(word, &words),
                words.join(", ")
            )
        })
    }
}

/// Parses one command (a line without its `;` or newline; not blank).
pub fn parse(line: &str) -> Result<ShellCommand, String> {
    let line = line.trim();
    let (name, rest) = match line.split_once(char::is_whitespace) {
        Some((name, rest)) => (name, rest.trim()),
        None => (line, ""),
    };
    let args: Vec<&str> = rest.split_whitespace().collect();
    let usage = |problem: &str| {
        let usage = help_of(name).map_or("", |h| h.usage);
        Err(format!("{problem}; usage: {usage}"))
    };
    match (name, args.as_slice()) {
        ("", _) => Err("empty command".to_owned()),
        ("ls", []) => Ok(ShellCommand::Ls(None)),
        ("ls", [what]) => Listing::parse(what).map(|l| ShellCommand::Ls(Some(l))),
        ("ls", _) => usage("`ls` takes at most one argument"),
        ("show", [mat]) => Ok(ShellCommand::Show((*mat).to_owned())),
        ("show", _) => usage("`show` takes one CSMat"),
        ("module", [module]) => Ok(ShellCommand::Module((*module).to_owned())),
        ("module", _) => usage("`module` takes one module"),
        ("watch", [mat]) => Ok(ShellCommand::Watch {
            mat: (*mat).to_owned(),
            seconds: None,
        }),
        ("watch", [mat, seconds]) => match seconds.parse::<f64>() {
            Ok(s) if s.is_finite() && s > 0.0 && s <= MAX_WATCH_SECONDS => {
                Ok(ShellCommand::Watch {
                    mat: (*mat).to_owned(),
                    seconds: Some(s),
                })
            }
            _ => usage(&format!(
                "`{seconds}` is not a positive number of seconds up to {MAX_WATCH_SECONDS} (a \
                 day; without a number, `watch` runs until a key is pressed)"
            )),
        },
        ("watch", _) => usage("`watch` takes a CSMat and, if you like, how many seconds"),
        ("stats", []) => Ok(ShellCommand::Stats),
        ("stats", _) => usage("`stats` takes no argument"),
        ("set", [mat, values @ ..]) if !values.is_empty() => {
            let values: Result<Vec<f64>, String> = (values.iter())
                .map(|v| match v.parse::<f64>() {
                    Ok(x) if x.is_finite() => Ok(x),
                    _ => Err(format!("`{v}` is not a finite number")),
                })
                .collect();
            match values {
                Ok(values) => Ok(ShellCommand::Set {
                    mat: (*mat).to_owned(),
                    values,
                }),
                Err(problem) => usage(&problem),
            }
        }
        ("set", _) => usage("`set` takes a CSMat and its values"),
        ("switch", [config]) => Ok(ShellCommand::Switch((*config).to_owned())),
        ("switch", _) => usage("`switch` takes one configuration"),
        ("habitat", [habitat, action @ ..]) => match habitat_action(action) {
            Ok(action) => Ok(ShellCommand::Habitat {
                habitat: (*habitat).to_owned(),
                action,
            }),
            Err(problem) => usage(&problem),
        },
        ("habitat", []) => usage("`habitat` takes a habitat and what to do"),
        ("reset", [habitat]) => Ok(ShellCommand::Habitat {
            habitat: (*habitat).to_owned(),
            action: HabitatAction::Reset,
        }),
        ("reset", _) => usage("`reset` takes one habitat"),
        ("send", [machine, stimuli @ ..]) if !stimuli.is_empty() => {
            if let Some(bad) = stimuli.iter().find(|s| s.starts_with('=')) {
                return usage(&format!("`{bad}` has no stimulus name"));
            }
            Ok(ShellCommand::Send {
                machine: (*machine).to_owned(),
                stimuli: stimuli.iter().map(|s| (*s).to_owned()).collect(),
            })
        }
        ("send", _) => usage("`send` takes a state machine and at least one stimulus"),
        ("query", [port, _, ..]) => {
            let text = rest[port.len()..].trim();
            Ok(ShellCommand::Query {
                port: (*port).to_owned(),
                text: text.to_owned(),
            })
        }
        ("query", _) => usage("`query` takes a port and the text to send"),
        ("help", []) => Ok(ShellCommand::Help(None)),
        ("help", [command]) => Ok(ShellCommand::Help(Some((*command).to_owned()))),
        ("help", _) => usage("`help` takes at most one command"),
        ("quit" | "exit", []) => Ok(ShellCommand::Quit),
        ("quit" | "exit", _) => usage(&format!("`{name}` takes no argument")),
        (other, _) => Err(unknown(other)),
    }
}

/// `rate HZ`, `reset`, `start` or `stop`.
fn habitat_action(words: &[&str]) -> Result<HabitatAction, String> {
    const ACTIONS: [&str; 4] = ["rate", "reset", "start", "stop"];
    match words {
        ["rate", hz] => match hz.parse::<f64>() {
            Ok(hz) if hz.is_finite() && hz > 0.0 => Ok(HabitatAction::Rate(hz)),
            _ => Err(format!("`{hz}` is not a positive rate in Hz")),
        },
        ["rate"] | ["rate", ..] => Err("`rate` takes one rate in Hz".to_owned()),
        ["reset"] => Ok(HabitatAction::Reset),
        ["start"] => Ok(HabitatAction::Start),
        ["stop"] => Ok(HabitatAction::Stop),
        [] => Err(format!("say what to do: {}", ACTIONS.join(", "))),
        [word, ..] if !ACTIONS.contains(word) => Err(format!(
            "a habitat has no action `{word}`{}; actions: rate HZ, reset, start, stop",
            super::view::hint(word, &ACTIONS)
        )),
        [word, ..] => Err(format!("`{word}` takes no argument")),
    }
}

/// A command of a script or of `-c`, with the line it is on (1-based).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ScriptLine {
    /// The line.
    pub line: usize,
    /// The command's text.
    pub text: String,
}

/// Cuts `text` into commands: one a line, several on a line separated by `;`, `#` starting a
/// comment (at the start of a line or after a blank); blank commands are dropped. A `;` or
/// `#` cannot be part of a command (of a `query`'s text, say).
pub fn split(text: &str) -> Vec<ScriptLine> {
    let mut commands = Vec::new();
    for (index, line) in text.lines().enumerate() {
        let code = match comment_start(line) {
            Some(at) => &line[..at],
            None => line,
        };
        for command in code.split(';').map(str::trim).filter(|c| !c.is_empty()) {
            commands.push(ScriptLine {
                line: index + 1,
                text: command.to_owned(),
            });
        }
    }
    commands
}

/// Where a comment starts in `line`: a `#` first on the line or after whitespace.
fn comment_start(line: &str) -> Option<usize> {
    let mut previous: Option<char> = None;
    for (at, c) in line.char_indices() {
        if c == '#' && previous.is_none_or(char::is_whitespace) {
            return Some(at);
        }
        previous = Some(c);
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(line: &str) -> ShellCommand {
        parse(line).unwrap_or_else(|e| panic!("{line:?}: {e}"))
    }

    fn err(line: &str) -> String {
        parse(line).expect_err(line)
    }

    #[test]
    fn every_command_parses() {
        assert_eq!(ok("ls"), ShellCommand::Ls(None));
        assert_eq!(ok("ls mats"), ShellCommand::Ls(Some(Listing::Mats)));
        assert_eq!(ok("ls  machine"), ShellCommand::Ls(Some(Listing::Machines)));
        assert_eq!(
            ok("show joint_goal"),
            ShellCommand::Show("joint_goal".into())
        );
        assert_eq!(
            ok("module joint_pd"),
            ShellCommand::Module("joint_pd".into())
        );
        assert_eq!(
            ok("watch tip 2.5"),
            ShellCommand::Watch {
                mat: "tip".into(),
                seconds: Some(2.5)
            }
        );
        assert_eq!(ok(" stats "), ShellCommand::Stats);
        assert_eq!(
            ok("set joint_goal 0.5 -1e-1"),
            ShellCommand::Set {
                mat: "joint_goal".into(),
                values: vec![0.5, -0.1]
            }
        );
        assert_eq!(
            ok("switch endptLQG"),
            ShellCommand::Switch("endptLQG".into())
        );
        assert_eq!(
            ok("habitat control rate 100"),
            ShellCommand::Habitat {
                habitat: "control".into(),
                action: HabitatAction::Rate(100.0)
            }
        );
        for (word, action) in [
            ("reset", HabitatAction::Reset),
            ("start", HabitatAction::Start),
            ("stop", HabitatAction::Stop),
        ] {
            assert_eq!(
                ok(&format!("habitat plant {word}")),
                ShellCommand::Habitat {
                    habitat: "plant".into(),
                    action
                }
            );
        }
        assert_eq!(ok("reset plant"), ok("habitat plant reset"));
        assert_eq!(
            ok("send arm Precise Object=Visible"),
            ShellCommand::Send {
                machine: "arm".into(),
                stimuli: vec!["Precise".into(), "Object=Visible".into()]
            }
        );
        assert_eq!(
            ok("query arm-configure  endptLQG  now"),
            ShellCommand::Query {
                port: "arm-configure".into(),
                text: "endptLQG  now".into()
            }
        );
        assert_eq!(ok("help"), ShellCommand::Help(None));
        assert_eq!(ok("help set"), ShellCommand::Help(Some("set".into())));
        assert_eq!(ok("quit"), ShellCommand::Quit);
        assert_eq!(ok("exit"), ShellCommand::Quit);
    }

    #[test]
    fn a_malformed_command_says_how_it_is_written() {
        assert_eq!(err("show"), "`show` takes one CSMat; usage: show MAT");
        assert_eq!(
            err("set joint_goal one 2"),
            "`one` is not a finite number; usage: set MAT V1 V2 ..."
        );
        assert!(err("set joint_goal NaN").contains("`NaN` is not a finite number"));
        assert!(err("habitat control rate -3").contains("`-3` is not a positive rate in Hz"));
        assert!(err("habitat control").contains("say what to do: rate, reset, start, stop"));
        let action = err("habitat control rest");
        assert!(action.contains("did you mean `reset`?"), "{action}");
        assert!(err("watch tip soon").contains("`soon` is not a positive number"));
        assert!(err("watch tip 1e20").contains("`1e20` is not a positive number"));
        assert!(err("send arm").contains("usage: send MACHINE STIMULUS[=VALUE]..."));
        assert!(err("query arm-configure").contains("usage: query PORT TEXT..."));
        let listing = err("ls matz");
        assert!(listing.contains("did you mean `mats`?"), "{listing}");
        assert!(listing.contains("habitats, modules, mats, configurations, machines, ports"));
    }

    #[test]
    fn an_unknown_command_lists_the_commands_with_a_suggestion() {
        let unknown = err("shw joint_goal");
        assert!(
            unknown.starts_with("unknown command `shw` (did you mean `show` or `set`?)"),
            "{unknown}"
        );
        assert!(unknown.ends_with(
            "commands: ls, show, module, watch, stats, set, switch, habitat, reset, send, query, help, \
             quit, exit"
        ));
        assert!(err("swtich x").contains("did you mean `switch`?"));
        assert!(!err("frobnicate").contains("did you mean"));
    }

    #[test]
    fn scripts_split_on_lines_and_semicolons_without_comments() {
        let script =
            "# set up\nls mats; show joint_goal\n\n  switch JointPD # back\n;;\nsend arm x#y\n";
        let commands = split(script);
        let lines: Vec<(usize, &str)> =
            commands.iter().map(|c| (c.line, c.text.as_str())).collect();
        assert_eq!(
            lines,
            [
                (2, "ls mats"),
                (2, "show joint_goal"),
                (4, "switch JointPD"),
                (6, "send arm x#y"),
            ]
        );
        assert!(split("  \n# only a comment\n").is_empty());
    }
}

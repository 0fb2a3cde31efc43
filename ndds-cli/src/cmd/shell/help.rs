//! The shell's commands in words: the table `help` prints (name, usage, summary, details),
//! and the error for a word that is no command.

/// A command's help.
#[derive(Debug)]
pub struct CommandHelp {
    /// Its name.
    pub name: &'static str,
    /// How it is written.
    pub usage: &'static str,
    /// One line.
    pub summary: &'static str,
    /// More, for `help NAME`.
    pub details: &'static str,
}

/// Every command, in the order `help` lists them.
pub const COMMANDS: &[CommandHelp] = &[
    CommandHelp {
        name: "ls",
        usage: "ls [habitats|modules|mats|configurations|machines|ports]",
        summary: "list what the system has (everything without an argument)",
        details: "Habitats with their rate, clock and execution order; modules with their \
                  habitat and component; CSMats with their shape and fields (`settable` when no \
                  module writes them); configurations (the active one marked); state machines \
                  with their stimuli; the ports of the system's process.",
    },
    CommandHelp {
        name: "show",
        usage: "show MAT",
        summary: "print a CSMat now, as a table with its fields and units",
        details: "Rows and columns are labelled with the CSMat's field names and units.",
    },
    CommandHelp {
        name: "module",
        usage: "module NAME",
        summary: "a module: its habitat, component, groups, what it reads and writes",
        details: "Whether it is in its habitat's active set now, and each CSMat it reads (as \
                  input, state or parameter) or writes.",
    },
    CommandHelp {
        name: "watch",
        usage: "watch MAT [SECONDS]",
        summary: "redraw a CSMat's table about 5 times a second",
        details: "On a terminal the table is redrawn in place until Enter, q or Ctrl-C (or \
                  until SECONDS have passed); otherwise a snapshot is printed every second for \
                  SECONDS (3 by default).",
    },
    CommandHelp {
        name: "stats",
        usage: "stats",
        summary: "each habitat's rate, achieved rate, samples, overruns and module errors",
        details: "The achieved rate is measured over half a second; the timing columns are the \
                  99th percentiles of the habitat's last statistics interval.",
    },
    CommandHelp {
        name: "set",
        usage: "set MAT V1 V2 ...",
        summary: "set a parameter or reference input (a CSMat no module writes)",
        details: "Values are row-major, as many as the CSMat has elements; its habitats take \
                  them at their next sample boundary.",
    },
    CommandHelp {
        name: "switch",
        usage: "switch CONFIG",
        summary: "switch to a configuration",
        details: "The switch happens at the next sample boundary of the habitats concerned.",
    },
    CommandHelp {
        name: "habitat",
        usage: "habitat NAME rate HZ | reset | start | stop",
        summary: "change a habitat's rate, reset its modules, start or stop it",
        details: "`rate HZ` samples at HZ from the next sample boundary; `reset` calls every \
                  module's reset there; `start` verifies the system and begins sampling; `stop` \
                  runs the disable and shutdown routines.",
    },
    CommandHelp {
        name: "reset",
        usage: "reset HABITAT",
        summary: "reset a habitat's modules (as `habitat NAME reset`)",
        details: "Every module's reset routine runs at the habitat's next sample boundary.",
    },
    CommandHelp {
        name: "send",
        usage: "send MACHINE STIMULUS[=VALUE]...",
        summary: "send stimuli to a state machine and print what they did",
        details: "`NAME` for a transient or latched stimulus, `NAME=VALUE` for a condition. The \
                  machine takes them all or refuses them all, with its reason.",
    },
    CommandHelp {
        name: "query",
        usage: "query PORT TEXT...",
        summary: "send text to a port declared in a description file and print its reply",
        details: "The rest of the line is the request (a configuration name, or stimuli, for \
                  the ports of description files).",
    },
    CommandHelp {
        name: "help",
        usage: "help [COMMAND]",
        summary: "list the commands, or explain one",
        details: "",
    },
    CommandHelp {
        name: "quit",
        usage: "quit | exit",
        summary: "leave the shell (Ctrl-D too)",
        details: "",
    },
];

/// Every word that starts a command (`exit` as well as `quit`).
pub fn command_names() -> Vec<&'static str> {
    let mut names: Vec<&'static str> = COMMANDS.iter().map(|c| c.name).collect();
    names.push("exit");
    names
}

/// The help of command `name` (`exit` is `quit`'s).
pub fn help_of(name: &str) -> Option<&'static CommandHelp> {
    let name = if name == "exit" { "quit" } else { name };
    COMMANDS.iter().find(|c| c.name == name)
}

/// `help`: every command with its usage and summary.
pub fn help_text() -> String {
    let width = COMMANDS.iter().map(|c| c.usage.len()).max().unwrap_or(0);
    let mut text = String::from("commands:\n");
    for command in COMMANDS {
        text.push_str(&format!(
            "  {:width$}  {}\n",
            command.usage, command.summary
        ));
    }
    text.push_str("`help COMMAND` explains one; TAB completes names of the live system\n");
    text
}

/// `help NAME`: its usage, summary and details.
pub fn command_help_text(name: &str) -> Result<String, String> {
    let help = help_of(name).ok_or_else(|| unknown(name))?;
    let mut text = format!("usage: {}\n{}\n", help.usage, help.summary);
    if !help.details.is_empty() {
        text.push_str(&wrap(help.details, 92));
    }
    Ok(text)
}

/// `text` wrapped at `width` columns, each line ending in a newline.
fn wrap(text: &str, width: usize) -> String {
    let mut out = String::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.len() + 1 + word.len() > width {
            out.push_str(&line);
            out.push('\n');
            line.clear();
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        out.push_str(&line);
        out.push('\n');
    }
    out
}

/// The error for a word that is no command: the close ones, and every one.
pub fn unknown(word: &str) -> String {
    let names = command_names();
    format!(
        "unknown command `{word}`{}; commands: {}",
        super::view::hint(word, &names),
        names.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_command_has_help_and_the_parser_knows_it() {
        for name in command_names() {
            let parsed = super::super::commands::parse(name);
            assert!(
                !parsed
                    .as_ref()
                    .is_err_and(|e| e.starts_with("unknown command")),
                "{name}: {parsed:?}"
            );
        }
        for command in COMMANDS {
            let text = command_help_text(command.name).unwrap();
            assert!(
                text.starts_with(&format!("usage: {}", command.usage)),
                "{text}"
            );
            assert!(help_text().contains(command.usage));
        }
        assert_eq!(command_help_text("exit"), command_help_text("quit"));
        let unknown = command_help_text("sett").unwrap_err();
        assert!(unknown.contains("did you mean `set`"), "{unknown}");
    }
}

//! docs/cli.md carries the help of every `ndds` command, generated from the binary itself:
//! a new option or command that is not in the reference fails here.
//! `NDDS_BLESS=1 cargo test -p ndds-cli --test cli_reference` rewrites the generated part.

use std::path::Path;
use std::process::Command;

const BEGIN: &str = "<!-- generated from `ndds help`: do not edit by hand -->";
const END: &str = "<!-- end of generated help -->";

fn help(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ndds"))
        .args(args)
        .arg("--help")
        .env("COLUMNS", "100")
        .output()
        .expect("ndds runs");
    assert!(out.status.success(), "ndds {args:?} --help failed");
    String::from_utf8(out.stdout).expect("help is UTF-8")
}

/// The subcommands a help text lists under `Commands:` (without `help`).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| l.trim() != "Commands:")
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_owned)
        .collect()
}

fn section(out: &mut String, path: &[String]) {
    let args: Vec<&str> = path.iter().map(String::as_str).collect();
    let text = help(&args);
    let title = if path.is_empty() {
        "ndds".to_owned()
    } else {
        format!("ndds {}", path.join(" "))
    };
    out.push_str(&format!(
        "{} `{title}`\n\n```text\n{}\n```\n\n",
        "#".repeat(3 + path.len().min(1)),
        text.trim_end()
    ));
    for sub in subcommands(&text) {
        let mut next = path.to_vec();
        next.push(sub);
        section(out, &next);
    }
}

#[test]
fn the_reference_has_every_commands_help() {
    let mut wanted = String::from("\n\n");
    section(&mut wanted, &[]);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/cli.md");
    let text = std::fs::read_to_string(&path).expect("docs/cli.md");
    let (Some(begin), Some(end)) = (text.find(BEGIN), text.find(END)) else {
        panic!("docs/cli.md lacks the generated-help markers");
    };
    if text[begin + BEGIN.len()..end] != wanted {
        if std::env::var_os("NDDS_BLESS").is_some() {
            let new = format!("{}{BEGIN}{wanted}{}", &text[..begin], &text[end..]);
            std::fs::write(&path, new).expect("rewrite docs/cli.md");
        } else {
            panic!(
                "docs/cli.md does not have the help `ndds` prints; regenerate it with \
                 NDDS_BLESS=1 cargo test -p ndds-cli --test cli_reference"
            );
        }
    }
    // Every top-level command also has a hand-written entry above the generated part.
    for command in subcommands(&help(&[])) {
        assert!(
            text[..begin].contains(&format!("## `ndds {command}")),
            "docs/cli.md has no section `## \\`ndds {command}...\\`` for {command}"
        );
    }
}

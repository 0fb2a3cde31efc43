//! `docs/fsm.md` against the code: its example program is the example file, loads and
//! verifies with the runtime's actions; its code excerpts are verbatim; its tables list the
//! stimulus kinds and the published state's fields exactly.

use ndds_docs::excerpts::{self, source};
use ndds_docs::markdown::Doc;
use ndds_runtime::Runtime;
use ndds_runtime::fsm::{ActionSet, MachineState, Program, verify};

fn doc() -> Doc {
    Doc::load("fsm.md")
}

#[test]
fn the_example_program_is_the_file_and_verifies() {
    let doc = doc();
    let block = doc
        .blocks()
        .into_iter()
        .find(|b| b.info == "toml" && b.text().starts_with("# from "))
        .expect("the example program");
    let text = block.text();
    let (first, body) = text.split_once('\n').unwrap();
    let file = first.trim_start_matches("# from ").trim();
    let original = source(file);
    // The file starts with its own comment lines; the rest must be the same.
    let original_body: String = original
        .lines()
        .skip_while(|l| l.starts_with('#'))
        .collect::<Vec<_>>()
        .join("\n");
    assert_eq!(
        body.trim(),
        original_body.trim(),
        "docs/fsm.md line {}",
        block.line
    );
    let program = Program::from_toml(&original).unwrap();
    let actions = ActionSet::runtime(&Runtime::new("docs"));
    let problems = verify(&program, &|name| actions.codes(name));
    assert!(problems.is_empty(), "{problems:?}");
}

#[test]
fn rust_excerpts_are_verbatim() {
    let (count, wrong) = excerpts::check(&doc(), "rust");
    assert!(count >= 1, "the guide quotes the example");
    assert!(
        wrong.is_empty(),
        "docs/fsm.md: not verbatim (line, file): {wrong:?}"
    );
}

#[test]
fn tables_list_the_kinds_and_the_state_fields() {
    let doc = doc();
    let kinds: Vec<String> = doc
        .table(&["kind", "value", "lifetime"])
        .expect("the table")
        .rows
        .iter()
        .map(|r| r.plain(0))
        .collect();
    assert_eq!(kinds, ["transient", "latched", "condition"]);
    for kind in &kinds {
        let text = format!("main = \"m\"\n[stimuli]\nx = \"{kind}\"\n");
        assert!(
            Program::from_toml(&text).is_ok(),
            "{kind} is a kind the loader accepts"
        );
    }
    let value = serde_json::to_value(MachineState::default()).unwrap();
    let fields: Vec<String> = value.as_object().unwrap().keys().cloned().collect();
    let listed: Vec<String> = doc
        .table(&["field", "meaning"])
        .expect("the table")
        .rows
        .iter()
        .map(|r| r.plain(0))
        .collect();
    assert_eq!(listed, fields);
}

//! `docs/ports.md` against the code: its code excerpts are verbatim parts of the examples, and
//! its tables name what the code has (the restriction fields).

use std::path::Path;

use ndds_client::ports::Restrictions;
use ndds_docs::markdown::Doc;

fn source(relative: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(relative);
    std::fs::read_to_string(&path).unwrap_or_else(|err| panic!("{}: {err}", path.display()))
}

#[test]
fn rust_excerpts_are_verbatim() {
    let doc = Doc::load("ports.md");
    let mut excerpts = 0;
    for block in doc.blocks().into_iter().filter(|b| b.info == "rust") {
        let lines: Vec<&str> = block.lines.iter().map(|(_, l)| l.as_str()).collect();
        let Some(file) = lines.first().and_then(|l| l.strip_prefix("// from ")) else {
            continue;
        };
        excerpts += 1;
        let text = source(file.trim());
        let all: Vec<&str> = text.lines().collect();
        let body = &lines[1..];
        assert!(
            all.windows(body.len().max(1)).any(|w| w == body),
            "docs/ports.md line {}: not a verbatim part of {file}",
            block.line
        );
    }
    assert!(excerpts >= 3);
}

#[test]
fn the_restriction_table_names_every_field() {
    let doc = Doc::load("ports.md");
    let table = doc
        .tables()
        .into_iter()
        .find(|t| t.starts_with(&["restriction", "field", "checked"]))
        .expect("the restrictions table");
    let listed: Vec<String> = table
        .rows
        .iter()
        .map(|r| r.plain(1))
        .filter(|f| !f.starts_with('('))
        .collect();
    let value = serde_json::to_value(Restrictions::default()).unwrap();
    let fields: Vec<String> = value.as_object().unwrap().keys().cloned().collect();
    assert_eq!(listed, fields);
}

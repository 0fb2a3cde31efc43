//! `docs/ports.md` against the code: its code excerpts are verbatim parts of the examples, and
//! its tables name what the code has (the restriction fields).

use ndds_client::ports::Restrictions;
use ndds_docs::excerpts;
use ndds_docs::markdown::Doc;

#[test]
fn rust_excerpts_are_verbatim() {
    let (count, wrong) = excerpts::check(&Doc::load("ports.md"), "rust");
    assert!(count >= 3, "the guide quotes the examples");
    assert!(
        wrong.is_empty(),
        "docs/ports.md: not verbatim (line, file): {wrong:?}"
    );
}

#[test]
fn the_restriction_table_names_every_field() {
    let doc = Doc::load("ports.md");
    let table = doc
        .table(&["restriction", "field", "checked"])
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

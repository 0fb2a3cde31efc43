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

#[test]
fn the_module_file_example_reads_and_its_key_table_is_what_the_reader_takes() {
    use ndds_client::ports::ModuleFile;

    let doc = Doc::load("ports.md");
    let block = doc
        .block("toml")
        .expect("one toml block: the module file example");
    let text: String = block.lines.iter().map(|(_, l)| format!("{l}\n")).collect();
    let file = ModuleFile::parse("ports.md", &text)
        .unwrap_or_else(|err| panic!("docs/ports.md:{}: {err}", block.line));
    assert_eq!(file.names(), ["CHIP_IT"]);
    // Every key the table lists is taken, and a key it does not list is refused.
    let table = doc
        .table(&["key", "value"])
        .expect("the module file's key table");
    let mut keys = Vec::new();
    for row in &table.rows {
        for cell in row.cells[0].split(['/', ',']) {
            let key = cell.trim().trim_matches('`');
            if !key.starts_with("[[") {
                keys.push(key.to_owned());
            }
        }
    }
    assert!(keys.len() >= 9, "the table lists the module keys: {keys:?}");
    for key in &keys {
        let value = match key.as_str() {
            "name" => "\"M\"",
            "order" => "\"ORDER(M)\"",
            "schedule" => "\"\"",
            "schedule_file" => continue, // read from disk: the reader's own tests cover it
            _ => "[]",
        };
        let text = format!("[[module]]\nname = \"M\"\n{key} = {value}\n")
            .replace("name = \"M\"\nname = \"M\"\n", "name = \"M\"\n");
        if let Err(err) = ModuleFile::parse("k.toml", &text) {
            assert!(
                !err.to_string().contains("unknown field"),
                "docs/ports.md lists `{key}`, which the reader refuses: {err}"
            );
        }
    }
    let err = ModuleFile::parse("k.toml", "[[module]]\nname = \"M\"\nunlisted = 1\n").unwrap_err();
    assert!(err.to_string().contains("unknown field"), "{err}");
}

//! `docs/runtime.md` against the code: its code excerpts are verbatim parts of the files they
//! name, and its tables of entry routines, verification problems and
//! statistics fields list exactly what the code has.

use ndds_docs::excerpts::{self, source};
use ndds_docs::markdown::Doc;
use ndds_docs::report::Problems;
use ndds_runtime::HabitatStats;

fn doc() -> Doc {
    Doc::load("runtime.md")
}

/// Compares the table's first column with `expected`, in order.
fn first_column(doc: &Doc, problems: &mut Problems, columns: &[&str], expected: &[String]) {
    let table = doc.table(columns).expect("one table with these columns");
    let listed: Vec<String> = table.rows.iter().map(|r| r.plain(0)).collect();
    if listed != expected {
        problems.at(
            doc,
            table.line,
            format!("the table lists {listed:?}; the code has {expected:?}"),
        );
    }
}

/// Names declared in `source` as `fn NAME(` inside the block that starts with `opening`.
fn names_in_block(source: &str, opening: &str, pattern: fn(&str) -> Option<String>) -> Vec<String> {
    let start = source.find(opening).expect("the block exists");
    let mut depth = 0i32;
    let mut names = Vec::new();
    for line in source[start..].lines() {
        if depth == 1
            && let Some(name) = pattern(line.trim())
        {
            names.push(name);
        }
        depth += line.matches('{').count() as i32 - line.matches('}').count() as i32;
        if depth == 0 && line.contains('}') {
            break;
        }
    }
    names
}

#[test]
fn code_excerpts_are_verbatim() {
    let (count, wrong) = excerpts::check(&doc(), "rust");
    assert!(count >= 2, "the guide quotes the example program");
    assert!(
        wrong.is_empty(),
        "docs/runtime.md: not verbatim (line, file): {wrong:?}"
    );
}

#[test]
fn entry_routines_are_the_traits() {
    let doc = doc();
    let mut problems = Problems::new();
    let trait_source = source("ndds-runtime/src/module.rs");
    let routines = names_in_block(&trait_source, "pub trait SampleModule", |line| {
        let rest = line.strip_prefix("fn ")?;
        Some(rest[..rest.find('(')?].to_owned())
    });
    assert_eq!(routines.len(), 9, "the paper's nine routines: {routines:?}");
    first_column(
        &doc,
        &mut problems,
        &["routine", "when it is called"],
        &routines,
    );
    problems.finish("docs/runtime.md entry routines");
}

#[test]
fn verification_problems_are_the_enums() {
    let doc = doc();
    let mut problems = Problems::new();
    let verify = source("ndds-runtime/src/verify.rs");
    let variants = names_in_block(&verify, "pub enum Problem", |line| {
        let name: String = line.chars().take_while(|c| c.is_alphanumeric()).collect();
        (line.ends_with('{') && name.chars().next().is_some_and(char::is_uppercase)).then_some(name)
    });
    first_column(&doc, &mut problems, &["problem", "meaning"], &variants);
    problems.finish("docs/runtime.md verification problems");
}

#[test]
fn statistics_fields_are_the_sample_type() {
    let doc = doc();
    let mut problems = Problems::new();
    let value = serde_json::to_value(HabitatStats::default()).unwrap();
    let fields: Vec<String> = value.as_object().unwrap().keys().cloned().collect();
    first_column(&doc, &mut problems, &["field", "meaning"], &fields);
    problems.finish("docs/runtime.md statistics fields");
}

//! Code excerpts in the guides: each fenced block whose first line is `// from PATH` must be a
//! verbatim run of lines of that file (PATH relative to the repository root).

use std::path::Path;

use crate::markdown::Doc;

/// The text of `relative` (a path from the repository root).
///
/// # Panics
/// If the file cannot be read: the tests cannot run without it.
pub fn source(relative: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(relative);
    std::fs::read_to_string(&path).unwrap_or_else(|err| panic!("{}: {err}", path.display()))
}

/// Checks every `info` block of `doc` that starts with `// from PATH`: returns how many there
/// are and, for each that is not a verbatim part of its file, its line and the file.
pub fn check(doc: &Doc, info: &str) -> (usize, Vec<(usize, String)>) {
    let mut count = 0;
    let mut wrong = Vec::new();
    for block in doc.blocks().into_iter().filter(|b| b.info == info) {
        let lines: Vec<&str> = block.lines.iter().map(|(_, l)| l.as_str()).collect();
        let Some(file) = lines.first().and_then(|l| l.strip_prefix("// from ")) else {
            continue;
        };
        count += 1;
        let text = source(file.trim());
        let all: Vec<&str> = text.lines().collect();
        let body = &lines[1..];
        if !all.windows(body.len().max(1)).any(|w| w == body) {
            wrong.push((block.line, file.trim().to_owned()));
        }
    }
    (count, wrong)
}

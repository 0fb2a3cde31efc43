//! Reading description files: TOML parsed into owned values that remember where each one was
//! written (file, line, column), with includes resolved.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use toml::de::{DeTable, DeValue};

/// Largest description file read (bytes).
pub const MAX_FILE_BYTES: u64 = 1 << 20;
/// Deepest include chain.
pub const MAX_INCLUDE_DEPTH: usize = 16;
/// Most files one system may consist of.
pub const MAX_FILES: usize = 256;

/// Where something was written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    /// The file (as named, or `<text>` for a string).
    pub file: Arc<PathBuf>,
    /// Line, from 1.
    pub line: usize,
    /// Column (characters), from 1.
    pub column: usize,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.file.display(), self.line, self.column)
    }
}

/// One thing wrong with a description, where it was written, and what was expected there.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Diagnostic {
    /// Where.
    pub location: Location,
    /// What is wrong.
    pub message: String,
    /// What would have been right (`None` when the message says it).
    pub expected: Option<String>,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.location, self.message)?;
        if let Some(expected) = &self.expected {
            write!(f, "; expected {expected}")?;
        }
        Ok(())
    }
}

/// Every problem found in a description, in file order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Diagnostics(pub Vec<Diagnostic>);

impl fmt::Display for Diagnostics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, d) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{d}")?;
        }
        Ok(())
    }
}

/// Problems reported at most; the rest are counted in a last one.
pub const MAX_DIAGNOSTICS: usize = 100;

impl Diagnostics {
    /// Keeps the first [`MAX_DIAGNOSTICS`] problems (in file order) and says how many more
    /// there were.
    pub(crate) fn truncate(&mut self) {
        if self.0.len() > MAX_DIAGNOSTICS {
            let more = self.0.len() - MAX_DIAGNOSTICS;
            self.0.truncate(MAX_DIAGNOSTICS);
            let at = self.0[MAX_DIAGNOSTICS - 1].location.clone();
            self.push(&at, format!("... and {more} more problems"));
        }
    }

    pub(crate) fn push(&mut self, at: &Location, message: impl Into<String>) {
        self.0.push(Diagnostic {
            location: at.clone(),
            message: message.into(),
            expected: None,
        });
    }

    pub(crate) fn expected(
        &mut self,
        at: &Location,
        message: impl Into<String>,
        expected: impl Into<String>,
    ) {
        self.0.push(Diagnostic {
            location: at.clone(),
            message: message.into(),
            expected: Some(expected.into()),
        });
    }

    /// Whether nothing is wrong.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// A TOML value with where it was written.
#[derive(Clone, Debug)]
pub(crate) struct Raw {
    pub at: Location,
    pub value: RawValue,
}

#[derive(Clone, Debug)]
pub(crate) enum RawValue {
    Integer(i64),
    Float(f64),
    Text(String),
    Bool(bool),
    Datetime,
    Array(Vec<Raw>),
    Table(RawTable),
}

/// A table's entries in the order written, each key with its location.
#[derive(Clone, Debug, Default)]
pub(crate) struct RawTable {
    pub entries: Vec<(String, Location, Raw)>,
}

impl RawTable {
    pub fn get(&self, key: &str) -> Option<&Raw> {
        self.entries
            .iter()
            .find(|(k, _, _)| k == key)
            .map(|(_, _, v)| v)
    }
}

impl RawValue {
    pub fn kind(&self) -> &'static str {
        match self {
            RawValue::Integer(_) => "an integer",
            RawValue::Float(_) => "a number",
            RawValue::Text(_) => "a string",
            RawValue::Bool(_) => "a boolean",
            RawValue::Datetime => "a date-time",
            RawValue::Array(_) => "an array",
            RawValue::Table(_) => "a table",
        }
    }
}

/// One file of a system, parsed.
#[derive(Debug)]
pub(crate) struct SourceFile {
    pub path: Arc<PathBuf>,
    /// The canonical path (each file is read once, however often it is included).
    pub canonical: Option<PathBuf>,
    pub top: RawTable,
    /// Where the file starts (for problems about the file as a whole).
    pub start: Location,
}

struct Lines {
    file: Arc<PathBuf>,
    starts: Vec<usize>,
    text: String,
}

impl Lines {
    fn new(file: Arc<PathBuf>, text: &str) -> Self {
        let mut starts = vec![0];
        starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        Self {
            file,
            starts,
            text: text.to_owned(),
        }
    }

    fn at(&self, offset: usize) -> Location {
        let offset = offset.min(self.text.len());
        let line = self.starts.partition_point(|&s| s <= offset).max(1);
        let start = self.starts[line - 1];
        let column = self
            .text
            .get(start..offset)
            .map_or(offset - start, |s| s.chars().count())
            + 1;
        Location {
            file: Arc::clone(&self.file),
            line,
            column,
        }
    }
}

fn convert(lines: &Lines, value: &DeValue<'_>, at: Location) -> Raw {
    let value = match value {
        DeValue::String(s) => RawValue::Text(s.to_string()),
        DeValue::Integer(i) => {
            let digits = i.as_str().replace('_', "");
            match i64::from_str_radix(&digits, i.radix()) {
                Ok(n) => RawValue::Integer(n),
                // Beyond i64: kept as the (large) number it is, so range checks can say so.
                Err(_) => RawValue::Float(digits.parse().unwrap_or(f64::INFINITY)),
            }
        }
        DeValue::Float(x) => {
            RawValue::Float(x.as_str().replace('_', "").parse().unwrap_or(f64::NAN))
        }
        DeValue::Boolean(b) => RawValue::Bool(*b),
        DeValue::Datetime(_) => RawValue::Datetime,
        DeValue::Array(items) => RawValue::Array(
            items
                .iter()
                .map(|item| convert(lines, item.get_ref(), lines.at(item.span().start)))
                .collect(),
        ),
        DeValue::Table(table) => RawValue::Table(convert_table(lines, table)),
    };
    Raw { at, value }
}

fn convert_table(lines: &Lines, table: &DeTable<'_>) -> RawTable {
    let mut entries: Vec<(String, Location, Raw)> = table
        .iter()
        .map(|(key, value)| {
            let key_at = lines.at(key.span().start);
            let raw = convert(lines, value.get_ref(), lines.at(value.span().start));
            (key.get_ref().to_string(), key_at, raw)
        })
        .collect();
    // In the order written, whatever order the map keeps.
    entries.sort_by_key(|(_, at, _)| (at.line, at.column));
    RawTable { entries }
}

/// Parses one file's text.
pub(crate) fn parse(path: Arc<PathBuf>, text: &str) -> Result<SourceFile, Diagnostic> {
    let lines = Lines::new(Arc::clone(&path), text);
    match DeTable::parse(text) {
        Ok(table) => Ok(SourceFile {
            canonical: None,
            start: lines.at(0),
            top: convert_table(&lines, table.get_ref()),
            path,
        }),
        Err(err) => Err(Diagnostic {
            location: lines.at(err.span().map_or(0, |s| s.start)),
            message: format!("not valid TOML: {}", err.message().trim_end()),
            expected: None,
        }),
    }
}

/// Texts that stand in for files: an editor's unsaved files, by absolute path (see
/// [`overlay_key`]). A file named here is read from here, whether or not it exists on disk.
pub type Overlay = std::collections::BTreeMap<PathBuf, String>;

/// The key of `path` in an [`Overlay`]: absolute (against the current directory), with `.`
/// and `..` resolved by name (symbolic links are not followed).
pub fn overlay_key(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_owned());
    let mut key = PathBuf::new();
    for part in absolute.components() {
        match part {
            std::path::Component::CurDir => {}
            std::path::Component::ParentDir => {
                key.pop();
            }
            other => key.push(other),
        }
    }
    key
}

/// The text of `path` from `overlay`, if it stands in for it.
pub(crate) fn from_overlay<'a>(overlay: &'a Overlay, path: &Path) -> Option<&'a String> {
    if overlay.is_empty() {
        return None;
    }
    overlay.get(&overlay_key(path))
}

/// Reads `path` and every file it includes (depth first, each file once, included files
/// before the file that includes them), taking the files `overlay` holds from there.
pub(crate) fn read_all(path: &Path, overlay: &Overlay) -> Result<Vec<SourceFile>, Diagnostics> {
    let mut files = Vec::new();
    let mut problems = Diagnostics::default();
    let mut stack = Vec::new();
    let whole = Location {
        file: Arc::new(path.to_owned()),
        line: 1,
        column: 1,
    };
    read_into(path, &whole, overlay, &mut stack, &mut files, &mut problems);
    if problems.is_empty() {
        Ok(files)
    } else {
        Err(problems)
    }
}

/// Parses `text` (named `name` in messages) and the files it includes (relative to `dir`).
pub(crate) fn read_text(
    name: &str,
    text: &str,
    dir: &Path,
) -> Result<Vec<SourceFile>, Diagnostics> {
    let mut problems = Diagnostics::default();
    let file = match parse(Arc::new(PathBuf::from(name)), text) {
        Ok(file) => file,
        Err(d) => return Err(Diagnostics(vec![d])),
    };
    let mut files = Vec::new();
    let mut stack = vec![PathBuf::from(name)];
    for (include, at) in includes(&file, &mut problems) {
        let at_path = dir.join(&include);
        read_into(
            &at_path,
            &at,
            &Overlay::new(),
            &mut stack,
            &mut files,
            &mut problems,
        );
    }
    files.push(file);
    if problems.is_empty() {
        Ok(files)
    } else {
        Err(problems)
    }
}

fn read_into(
    path: &Path,
    at: &Location,
    overlay: &Overlay,
    stack: &mut Vec<PathBuf>,
    files: &mut Vec<SourceFile>,
    problems: &mut Diagnostics,
) {
    let standing_in = from_overlay(overlay, path);
    let canonical = match standing_in {
        Some(_) => overlay_key(path),
        None => match path.canonicalize() {
            Ok(p) => p,
            Err(err) => {
                problems.push(at, format!("cannot read `{}`: {err}", path.display()));
                return;
            }
        },
    };
    if stack.contains(&canonical) {
        let chain: Vec<String> = stack
            .iter()
            .chain(std::iter::once(&canonical))
            .map(|p| p.display().to_string())
            .collect();
        problems.push(at, format!("include cycle: {}", chain.join(" includes ")));
        return;
    }
    if files
        .iter()
        .any(|f: &SourceFile| f.canonical.as_ref() == Some(&canonical))
    {
        return; // included twice (a diamond): once is enough
    }
    if stack.len() >= MAX_INCLUDE_DEPTH {
        problems.push(
            at,
            format!("includes nested more than {MAX_INCLUDE_DEPTH} deep"),
        );
        return;
    }
    if files.len() >= MAX_FILES {
        problems.push(at, format!("a system may have at most {MAX_FILES} files"));
        return;
    }
    let text = match file_text(path, &canonical, standing_in) {
        Ok(text) => text,
        Err(problem) => {
            problems.push(at, problem);
            return;
        }
    };
    // Messages name the file as the user would (relative paths stay relative).
    let file = match parse(Arc::new(display_path(path)), &text) {
        Ok(file) => file,
        Err(d) => {
            problems.0.push(d);
            return;
        }
    };
    // Includes are named relative to this file as the user named it, so messages keep
    // relative paths relative.
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    stack.push(canonical.clone());
    for (include, at) in includes(&file, problems) {
        read_into(&dir.join(include), &at, overlay, stack, files, problems);
    }
    stack.pop();
    let mut file = file;
    file.canonical = Some(canonical);
    files.push(file);
}

/// The text of a file of a system: `standing_in` (from an [`Overlay`]) if given, else the
/// regular file at `real` on disk, of at most [`MAX_FILE_BYTES`] either way; else what is
/// wrong, naming the file as `path`.
pub(crate) fn file_text(
    path: &Path,
    real: &Path,
    standing_in: Option<&String>,
) -> Result<String, String> {
    let shown = path.display();
    let too_large = |len: u64| {
        format!("`{shown}` is {len} bytes; description files are at most {MAX_FILE_BYTES}")
    };
    if let Some(text) = standing_in {
        return match text.len() as u64 {
            len if len > MAX_FILE_BYTES => Err(too_large(len)),
            _ => Ok(text.clone()),
        };
    }
    match std::fs::metadata(real) {
        Ok(meta) if !meta.is_file() => Err(format!("`{shown}` is not a regular file")),
        Ok(meta) if meta.len() > MAX_FILE_BYTES => Err(too_large(meta.len())),
        Ok(_) => read_bounded(real).map_err(|err| format!("cannot read `{shown}`: {err}")),
        Err(err) => Err(format!("cannot read `{shown}`: {err}")),
    }
}

/// Reads a file of at most [`MAX_FILE_BYTES`] (it may have grown since its size was checked).
pub(crate) fn read_bounded(path: &Path) -> std::io::Result<String> {
    use std::io::Read as _;
    let mut text = String::new();
    std::fs::File::open(path)?
        .take(MAX_FILE_BYTES + 1)
        .read_to_string(&mut text)?;
    if text.len() as u64 > MAX_FILE_BYTES {
        return Err(std::io::Error::other(format!(
            "larger than {MAX_FILE_BYTES} bytes"
        )));
    }
    Ok(text)
}

fn display_path(path: &Path) -> PathBuf {
    let normal: PathBuf = path.components().collect();
    normal
}

/// The `include = [...]` entries of a file.
fn includes(file: &SourceFile, problems: &mut Diagnostics) -> Vec<(String, Location)> {
    let Some(raw) = file.top.get("include") else {
        return Vec::new();
    };
    let items: Vec<&Raw> = match &raw.value {
        RawValue::Text(_) => vec![raw],
        RawValue::Array(items) => items.iter().collect(),
        other => {
            problems.expected(
                &raw.at,
                format!("`include` is {}", other.kind()),
                "a file name or a list of file names",
            );
            return Vec::new();
        }
    };
    let mut out = Vec::new();
    for item in items {
        match &item.value {
            RawValue::Text(name) if !name.is_empty() => out.push((name.clone(), item.at.clone())),
            other => problems.expected(
                &item.at,
                format!("an include entry is {}", other.kind()),
                "a file name (relative to this file)",
            ),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_are_lines_and_character_columns() {
        let text = "a = 1\n# ünïcode\nb = \"x\"\n  [t]\n  c = [1, 2]\n";
        let file = parse(Arc::new("f.toml".into()), text).unwrap();
        let b = file.top.get("b").unwrap();
        assert_eq!((b.at.line, b.at.column), (3, 5));
        let RawValue::Table(t) = &file.top.get("t").unwrap().value else {
            panic!("t is a table")
        };
        let RawValue::Array(items) = &t.get("c").unwrap().value else {
            panic!("c is an array")
        };
        assert_eq!((items[1].at.line, items[1].at.column), (5, 11));
        assert_eq!(b.at.to_string(), "f.toml:3:5");
    }

    #[test]
    fn syntax_errors_say_where() {
        let err = parse(Arc::new("f.toml".into()), "a = 1\nb = [1, 2\n").unwrap_err();
        assert_eq!(err.location.line, 2, "{err}");
        assert!(err.message.starts_with("not valid TOML"), "{err}");
    }

    #[test]
    fn keys_keep_the_order_written() {
        let file = parse(Arc::new("f".into()), "z = 1\na = 2\nm = 3\n").unwrap();
        let keys: Vec<&str> = file
            .top
            .entries
            .iter()
            .map(|(k, _, _)| k.as_str())
            .collect();
        assert_eq!(keys, ["z", "a", "m"]);
    }
}

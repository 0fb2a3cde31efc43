//! Just enough Markdown for the doc tests: ATX headings, pipe tables and fenced code blocks,
//! each with its 1-based line number so a failing test can name the line to update.
//!
//! Lines inside fenced blocks are never read as headings or tables.

use std::fmt::Write as _;
use std::path::Path;

/// A Markdown document split into lines.
#[derive(Clone, Debug)]
pub struct Doc {
    name: String,
    lines: Vec<String>,
}

/// An ATX heading (`## Title`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Heading {
    /// 1-based line number.
    pub line: usize,
    /// Number of `#`.
    pub level: usize,
    /// The text after the `#`s, trimmed.
    pub text: String,
}

/// A pipe table: a header row, a `|---|` separator row and body rows.
#[derive(Clone, Debug)]
pub struct Table {
    /// Line of the header row.
    pub line: usize,
    /// The nearest heading above the table, if any.
    pub heading: Option<Heading>,
    /// Header cells, as written.
    pub header: Vec<String>,
    /// Body rows.
    pub rows: Vec<Row>,
}

/// One body row of a [`Table`].
#[derive(Clone, Debug)]
pub struct Row {
    /// 1-based line number.
    pub line: usize,
    /// Cells, trimmed, as written (backticks kept).
    pub cells: Vec<String>,
}

/// A fenced code block.
#[derive(Clone, Debug)]
pub struct Block {
    /// Line of the opening fence.
    pub line: usize,
    /// The info string after the opening fence (` ```hex example:bye ` gives `hex example:bye`).
    pub info: String,
    /// Content lines with their line numbers.
    pub lines: Vec<(usize, String)>,
}

/// One byte of a hex block, with the line it was written on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HexByte {
    /// The byte.
    pub value: u8,
    /// 1-based line number.
    pub line: usize,
}

impl Doc {
    /// Reads `relative` (a path inside the `docs/` directory).
    ///
    /// # Panics
    /// If the file cannot be read: the tests cannot run without it.
    pub fn load(relative: &str) -> Doc {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(relative);
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|err| panic!("cannot read {}: {err}", path.display()));
        Doc::parse(&format!("docs/{relative}"), &text)
    }

    /// A document named `name` (as failure messages print it) with the content `text`.
    pub fn parse(name: &str, text: &str) -> Doc {
        Doc {
            name: name.to_owned(),
            lines: text.lines().map(str::to_owned).collect(),
        }
    }

    /// `name:line`, the way failure messages point at a line.
    pub fn at(&self, line: usize) -> String {
        format!("{}:{line}", self.name)
    }

    /// The text of a 1-based line (empty past the end).
    pub fn line(&self, line: usize) -> &str {
        line.checked_sub(1)
            .and_then(|i| self.lines.get(i))
            .map_or("", String::as_str)
    }

    /// Number of lines.
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    /// True for an empty document.
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }

    /// Lines outside fenced blocks, with their numbers.
    fn prose(&self) -> Vec<(usize, &str)> {
        let mut out = Vec::new();
        let mut fenced = false;
        for (i, line) in self.lines.iter().enumerate() {
            if line.trim_start().starts_with("```") {
                fenced = !fenced;
                continue;
            }
            if !fenced {
                out.push((i + 1, line.as_str()));
            }
        }
        out
    }

    /// Every heading, in order.
    pub fn headings(&self) -> Vec<Heading> {
        self.prose()
            .into_iter()
            .filter_map(|(line, text)| heading(line, text))
            .collect()
    }

    /// Every pipe table, in order.
    pub fn tables(&self) -> Vec<Table> {
        let prose = self.prose();
        let mut tables = Vec::new();
        let mut current_heading = None;
        let mut i = 0;
        while i < prose.len() {
            let (line, text) = prose[i];
            if let Some(h) = heading(line, text) {
                current_heading = Some(h);
            }
            let is_table = is_row(text)
                && prose
                    .get(i + 1)
                    .is_some_and(|(next, sep)| *next == line + 1 && is_separator(sep));
            if !is_table {
                i += 1;
                continue;
            }
            let mut table = Table {
                line,
                heading: current_heading.clone(),
                header: cells(text),
                rows: Vec::new(),
            };
            i += 2;
            while let Some((row_line, row)) = prose.get(i) {
                if !is_row(row) || *row_line != table.line + 2 + table.rows.len() {
                    break;
                }
                table.rows.push(Row {
                    line: *row_line,
                    cells: cells(row),
                });
                i += 1;
            }
            tables.push(table);
        }
        tables
    }

    /// The one table whose header starts with `columns`; `None` when there is none or more
    /// than one.
    pub fn table(&self, columns: &[&str]) -> Option<Table> {
        let mut found = self.tables().into_iter().filter(|t| t.starts_with(columns));
        let first = found.next()?;
        found.next().is_none().then_some(first)
    }

    /// Every fenced block, in order.
    pub fn blocks(&self) -> Vec<Block> {
        let mut blocks = Vec::new();
        let mut open: Option<Block> = None;
        for (i, line) in self.lines.iter().enumerate() {
            let trimmed = line.trim_start();
            match (&mut open, trimmed.strip_prefix("```")) {
                (None, Some(info)) => {
                    open = Some(Block {
                        line: i + 1,
                        info: info.trim().to_owned(),
                        lines: Vec::new(),
                    });
                }
                (Some(_), Some(_)) => blocks.extend(open.take()),
                (Some(block), None) => block.lines.push((i + 1, line.clone())),
                (None, None) => {}
            }
        }
        blocks
    }

    /// The fenced block whose info string is `info`, if exactly one has it.
    pub fn block(&self, info: &str) -> Option<Block> {
        let mut found = self.blocks().into_iter().filter(|b| b.info == info);
        let first = found.next()?;
        found.next().is_none().then_some(first)
    }
}

impl Table {
    /// The header cells as plain text (see [`plain`]), lower-cased.
    pub fn columns(&self) -> Vec<String> {
        self.header
            .iter()
            .map(|c| plain(c).to_lowercase())
            .collect()
    }

    /// True when the header's first cells are `names` (plain, case-insensitive).
    pub fn starts_with(&self, names: &[&str]) -> bool {
        let columns = self.columns();
        names.len() <= columns.len() && names.iter().zip(&columns).all(|(a, b)| *a == b)
    }
}

impl Row {
    /// Cell `index` as plain text (see [`plain`]); empty when the row is short.
    pub fn plain(&self, index: usize) -> String {
        self.cells.get(index).map_or_else(String::new, |c| plain(c))
    }
}

impl Block {
    /// The content as one string, lines joined with `\n`.
    pub fn text(&self) -> String {
        let mut out = String::new();
        for (i, (_, line)) in self.lines.iter().enumerate() {
            if i > 0 {
                out.push('\n');
            }
            out.push_str(line);
        }
        out
    }

    /// The bytes of a hex block: on each line, whitespace-separated pairs of hex digits up to
    /// an optional `#` comment. Errors name the line of the first bad token.
    pub fn hex_bytes(&self) -> Result<Vec<HexByte>, (usize, String)> {
        let mut bytes = Vec::new();
        for (line, text) in &self.lines {
            let data = text.split('#').next().unwrap_or("");
            for token in data.split_whitespace() {
                let value = (token.len() == 2)
                    .then(|| u8::from_str_radix(token, 16).ok())
                    .flatten()
                    .ok_or_else(|| (*line, format!("`{token}` is not a hex byte")))?;
                bytes.push(HexByte { value, line: *line });
            }
        }
        Ok(bytes)
    }
}

/// A cell or heading without backticks and surrounding whitespace; `\|` becomes `|`.
pub fn plain(text: &str) -> String {
    text.replace('`', "").replace("\\|", "|").trim().to_owned()
}

/// Bytes as lowercase hex pairs, `per_line` to a line.
pub fn hex_lines(bytes: &[u8], per_line: usize) -> String {
    let mut out = String::new();
    for (i, chunk) in bytes.chunks(per_line.max(1)).enumerate() {
        if i > 0 {
            out.push('\n');
        }
        for (j, byte) in chunk.iter().enumerate() {
            if j > 0 {
                out.push(' ');
            }
            let _ = write!(out, "{byte:02x}");
        }
    }
    out
}

fn heading(line: usize, text: &str) -> Option<Heading> {
    let level = text.chars().take_while(|c| *c == '#').count();
    let rest = &text[level..];
    (level > 0 && level <= 6 && rest.starts_with(' ')).then(|| Heading {
        line,
        level,
        text: rest.trim().to_owned(),
    })
}

fn is_row(text: &str) -> bool {
    text.trim_start().starts_with('|')
}

fn is_separator(text: &str) -> bool {
    is_row(text)
        && text
            .trim()
            .chars()
            .all(|c| matches!(c, '|' | '-' | ':' | ' '))
}

/// Splits a row on `|` that are not escaped as `\|`, dropping the outer empty cells.
fn cells(row: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cell = String::new();
    let mut chars = row.trim().chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '\\' if chars.peek() == Some(&'|') => {
                cell.push_str("\\|");
                chars.next();
            }
            '|' => out.push(std::mem::take(&mut cell)),
            other => cell.push(other),
        }
    }
    out.push(cell);
    if out.first().is_some_and(|c| c.trim().is_empty()) {
        out.remove(0);
    }
    if out.last().is_some_and(|c| c.trim().is_empty()) {
        out.pop();
    }
    out.into_iter().map(|c| c.trim().to_owned()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "\
# Title

## Kinds

| kind | name |
|---|---|
| 1 | `Solicit` |
| 2 | a \\| b |

```hex example:x
4e 44   # magic
01
```

```text
## not a heading
| not | a table |
|---|---|
```
";

    #[test]
    fn reads_headings_tables_and_blocks() {
        let doc = Doc::parse("sample.md", SAMPLE);
        let headings = doc.headings();
        assert_eq!(headings.len(), 2);
        assert_eq!(headings[1].text, "Kinds");
        assert_eq!(headings[1].line, 3);

        let tables = doc.tables();
        assert_eq!(tables.len(), 1);
        let table = &tables[0];
        assert!(table.starts_with(&["kind", "name"]));
        assert_eq!(table.heading.as_ref().map(|h| h.level), Some(2));
        assert_eq!(table.rows.len(), 2);
        assert_eq!(table.rows[0].line, 7);
        assert_eq!(table.rows[0].plain(1), "Solicit");
        assert_eq!(table.rows[1].plain(1), "a | b");

        let block = doc.block("hex example:x").unwrap();
        assert_eq!(block.line, 10);
        let bytes = block.hex_bytes().unwrap();
        assert_eq!(
            bytes.iter().map(|b| (b.value, b.line)).collect::<Vec<_>>(),
            vec![(0x4e, 11), (0x44, 11), (0x01, 12)]
        );
        assert_eq!(doc.blocks().len(), 2);
        assert_eq!(doc.at(3), "sample.md:3");
    }

    #[test]
    fn bad_hex_names_its_line() {
        let doc = Doc::parse("x.md", "```hex\n00 0g\n```\n");
        let err = doc.blocks()[0].hex_bytes().unwrap_err();
        assert_eq!(err.0, 2);
    }

    #[test]
    fn hex_lines_groups_bytes() {
        assert_eq!(hex_lines(&[0, 1, 0xab], 2), "00 01\nab");
    }
}

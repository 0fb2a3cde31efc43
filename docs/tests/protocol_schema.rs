//! Every structure of the wire and local protocols, as `docs/protocol.md` tabulates it, against
//! the serde layout of the Rust types: field names, order and types; enum variant indices,
//! names and contents.
//!
//! serde-reflection traces the types the same way postcard walks them, so a field added,
//! removed, reordered or retyped in the code shows up here with the table row to change.

use std::collections::BTreeMap;

use ndds_core::ipc::{ClientMessage, DaemonMessage, Role};
use ndds_core::types::{ContainerShape, Format, VariantShape};
use ndds_core::wire::data::{Addressing, Fragment, Gap, Heartbeat, Sample};
use ndds_core::wire::feedback::{AckNack, NackFrag};
use ndds_core::wire::{
    Announce, Bye, ConsumerMode, EndpointQos, Probe, ProbeReply, Reliability, Solicit, Withdraw,
};
use ndds_docs::markdown::{Doc, Heading, Table, plain};
use ndds_docs::report::Problems;
use serde_reflection::{
    ContainerFormat, Format as F, Named, Registry, Samples, Tracer, TracerConfig, VariantFormat,
};

/// Every structure reachable from the datagram bodies, the `Data` and `Feedback` addressing
/// and submessages, and the two frame enums.
fn registry() -> Registry {
    let mut samples = Samples::new();
    let mut tracer = Tracer::new(TracerConfig::default());
    // `Addressing` is only ever encoded (the parser reads it field by field), so it is traced
    // from a value.
    let addressing = Addressing {
        reader_participant: 1,
        writer: 2,
        token: 4,
        readers: &[3],
    };
    // Enums first: one that sits behind a `Vec` or `Option` is seen completely only when
    // traced on its own.
    let traced = tracer
        .trace_simple_type::<Format>()
        .and_then(|_| tracer.trace_simple_type::<ContainerShape>())
        .and_then(|_| tracer.trace_simple_type::<VariantShape>())
        .and_then(|_| tracer.trace_simple_type::<Reliability>())
        .and_then(|_| tracer.trace_simple_type::<ConsumerMode>())
        .and_then(|_| tracer.trace_simple_type::<EndpointQos>())
        .and_then(|_| tracer.trace_simple_type::<Role>())
        // `DaemonMessage::Declared::result`.
        .and_then(|_| tracer.trace_simple_type::<Result<(), String>>())
        .and_then(|_| tracer.trace_simple_type::<ClientMessage>())
        .and_then(|_| tracer.trace_simple_type::<DaemonMessage>())
        .and_then(|_| tracer.trace_simple_type::<Solicit>())
        .and_then(|_| tracer.trace_simple_type::<Announce>())
        .and_then(|_| tracer.trace_simple_type::<Withdraw>())
        .and_then(|_| tracer.trace_simple_type::<Bye>())
        .and_then(|_| tracer.trace_simple_type::<Probe>())
        .and_then(|_| tracer.trace_simple_type::<ProbeReply>())
        .and_then(|_| tracer.trace_value(&mut samples, &addressing).map(|_| ()))
        .and_then(|_| tracer.trace_type::<Sample<'_>>(&samples))
        .and_then(|_| tracer.trace_type::<Fragment<'_>>(&samples))
        .and_then(|_| tracer.trace_simple_type::<Heartbeat>())
        .and_then(|_| tracer.trace_simple_type::<Gap>())
        .and_then(|_| tracer.trace_type::<AckNack<'_>>(&samples))
        .and_then(|_| tracer.trace_type::<NackFrag<'_>>(&samples));
    if let Err(err) = traced {
        panic!(
            "serde-reflection cannot trace the protocol types ({err}); if a new enum sits behind \
             a Vec or Option, trace it on its own in registry() in docs/tests/protocol_schema.rs"
        );
    }
    tracer
        .registry()
        .unwrap_or_else(|err| panic!("incomplete trace of the protocol types: {err}"))
}

/// A format in the document's type notation (section 2).
fn notation(format: &F) -> String {
    let list = |items: &[F]| items.iter().map(notation).collect::<Vec<_>>().join(",");
    match format {
        F::Variable(_) => "?".to_owned(),
        F::TypeName(name) => name.clone(),
        F::Unit => "unit".to_owned(),
        F::Bool => "bool".to_owned(),
        F::I8 => "i8".to_owned(),
        F::I16 => "i16".to_owned(),
        F::I32 => "i32".to_owned(),
        F::I64 => "i64".to_owned(),
        F::I128 => "i128".to_owned(),
        F::U8 => "u8".to_owned(),
        F::U16 => "u16".to_owned(),
        F::U32 => "u32".to_owned(),
        F::U64 => "u64".to_owned(),
        F::U128 => "u128".to_owned(),
        F::F32 => "f32".to_owned(),
        F::F64 => "f64".to_owned(),
        F::Char => "char".to_owned(),
        F::Str => "str".to_owned(),
        F::Bytes => "bytes".to_owned(),
        F::Option(inner) => format!("option<{}>", notation(inner)),
        F::Seq(inner) => format!("seq<{}>", notation(inner)),
        F::Map { key, value } => format!("map<{},{}>", notation(key), notation(value)),
        F::Tuple(items) => format!("tuple<{}>", list(items)),
        F::TupleArray { content, size } => format!("array<{};{size}>", notation(content)),
    }
}

/// The short postcard encoding the `encoding` column gives for a format.
fn encoding(format: &F) -> String {
    match format {
        F::Variable(_) => "?",
        F::TypeName(name) => return format!("see {name}"),
        F::Unit => "nothing",
        F::Bool => "1 byte: 0 or 1",
        F::U8 => "1 byte",
        F::I8 => "1 byte, two's complement",
        F::U16 | F::U32 | F::U64 | F::U128 => "varint",
        F::I16 | F::I32 | F::I64 | F::I128 => "zigzag varint",
        F::F32 => "4 bytes, little-endian",
        F::F64 => "8 bytes, little-endian",
        F::Char | F::Str => "varint length + UTF-8",
        F::Bytes => "varint length + bytes",
        F::Option(_) => "0, or 1 + value",
        F::Seq(_) => "varint count + items",
        F::Map { .. } => "varint count + key, value pairs",
        F::Tuple(_) => "items in order, no prefix",
        F::TupleArray { size, .. } => return format!("{size} items, no prefix"),
    }
    .to_owned()
}

/// A variant's content in the document's notation.
fn content(variant: &VariantFormat) -> String {
    let fields = |fields: &[Named<F>]| {
        fields
            .iter()
            .map(|f| format!("{}:{}", f.name, notation(&f.value)))
            .collect::<Vec<_>>()
            .join(",")
    };
    match variant {
        VariantFormat::Variable(_) => "?".to_owned(),
        VariantFormat::Unit => "unit".to_owned(),
        VariantFormat::NewType(inner) => format!("newtype({})", notation(inner)),
        VariantFormat::Tuple(items) => format!(
            "tuple({})",
            items.iter().map(notation).collect::<Vec<_>>().join(",")
        ),
        VariantFormat::Struct(list) => format!("struct{{{}}}", fields(list)),
    }
}

/// What the document must say about one container: its kind word and its table rows
/// (cells compared, the `meaning` column excluded).
fn expected(container: &ContainerFormat) -> (&'static str, Vec<Vec<String>>) {
    let field_rows = |fields: Vec<(String, &F)>| {
        fields
            .into_iter()
            .enumerate()
            .map(|(i, (name, format))| {
                vec![
                    (i + 1).to_string(),
                    name,
                    notation(format),
                    encoding(format),
                ]
            })
            .collect()
    };
    match container {
        ContainerFormat::UnitStruct => ("unit struct", Vec::new()),
        ContainerFormat::NewTypeStruct(inner) => (
            "newtype struct",
            field_rows(vec![("0".to_owned(), &**inner)]),
        ),
        ContainerFormat::TupleStruct(items) => (
            "tuple struct",
            field_rows(
                items
                    .iter()
                    .enumerate()
                    .map(|(i, f)| (i.to_string(), f))
                    .collect(),
            ),
        ),
        ContainerFormat::Struct(fields) => (
            "struct",
            field_rows(fields.iter().map(|f| (f.name.clone(), &f.value)).collect()),
        ),
        ContainerFormat::Enum(variants) => (
            "enum",
            variants
                .iter()
                .map(|(index, v)| vec![index.to_string(), v.name.clone(), content(&v.value)])
                .collect(),
        ),
    }
}

fn columns_for(kind: &str) -> &'static [&'static str] {
    if kind == "enum" {
        &["index", "variant", "content"]
    } else {
        &["#", "field", "type", "encoding"]
    }
}

/// A row as the document should write it, with `…` for the meaning.
fn markdown_row(cells: &[String], kind: &str) -> String {
    let quoted: Vec<String> = cells
        .iter()
        .enumerate()
        .map(|(i, c)| match (kind, i) {
            (_, 0) => c.clone(),
            ("enum", _) | (_, 1 | 2) => format!("`{c}`"),
            _ => c.clone(),
        })
        .collect();
    format!("| {} | … |", quoted.join(" | "))
}

/// Cells compare without backticks; types and contents also without spaces.
fn same_cell(column: usize, written: &str, expected: &str) -> bool {
    let written = plain(written);
    if column >= 2 {
        let squeeze = |s: &str| s.split_whitespace().collect::<String>();
        squeeze(&written) == squeeze(expected)
    } else {
        written == expected
    }
}

/// `#### `Name` (kind)` headings: name, kind word, heading.
fn schema_headings(doc: &Doc) -> Vec<(String, String, Heading)> {
    doc.headings()
        .into_iter()
        .filter(|h| h.text.starts_with('`'))
        .filter_map(|h| {
            let text = plain(&h.text);
            let (name, rest) = text.split_once(" (")?;
            let kind = rest.strip_suffix(')')?;
            Some((name.to_owned(), kind.to_owned(), h))
        })
        .collect()
}

fn check_table(
    doc: &Doc,
    problems: &mut Problems,
    name: &str,
    kind: &str,
    table: &Table,
    rows: &[Vec<String>],
) {
    let columns = columns_for(kind);
    if !table.starts_with(columns) {
        problems.at(
            doc,
            table.line,
            format!(
                "the table of `{name}` must start with the columns `| {} |`",
                columns.join(" | ")
            ),
        );
        return;
    }
    for (i, want) in rows.iter().enumerate() {
        match table.rows.get(i) {
            Some(row) => {
                let same = want.iter().enumerate().all(|(c, cell)| {
                    same_cell(c, row.cells.get(c).map_or("", String::as_str), cell)
                });
                if !same {
                    problems.at(
                        doc,
                        row.line,
                        format!(
                            "`{name}` row {} does not match the code; it should read\n    {}",
                            i + 1,
                            markdown_row(want, kind)
                        ),
                    );
                }
            }
            None => problems.at(
                doc,
                table.rows.last().map_or(table.line, |r| r.line),
                format!(
                    "`{name}` has more {} in the code; add after this line\n    {}",
                    if kind == "enum" { "variants" } else { "fields" },
                    markdown_row(want, kind)
                ),
            ),
        }
    }
    for row in table.rows.iter().skip(rows.len()) {
        problems.at(
            doc,
            row.line,
            format!(
                "`{name}` has no such {} in the code; remove this row",
                if kind == "enum" { "variant" } else { "field" }
            ),
        );
    }
}

#[test]
fn every_structure_is_tabulated_as_the_code_encodes_it() {
    let doc = Doc::load("protocol.md");
    let registry = registry();
    let tables = doc.tables();
    let mut problems = Problems::new();
    let headings = schema_headings(&doc);
    let mut documented: BTreeMap<String, usize> = BTreeMap::new();
    for (name, kind, heading) in &headings {
        let Some(container) = registry.get(name) else {
            problems.at(
                &doc,
                heading.line,
                format!(
                    "`{name}` is not a structure of the wire or local protocol (renamed or removed?); \
                     update or remove this section"
                ),
            );
            continue;
        };
        if let Some(first) = documented.insert(name.clone(), heading.line) {
            problems.at(
                &doc,
                heading.line,
                format!("`{name}` is already described at line {first}; keep one section"),
            );
            continue;
        }
        let (want_kind, rows) = expected(container);
        if kind != want_kind {
            problems.at(
                &doc,
                heading.line,
                format!("`{name}` is a {want_kind} in the code: the heading should read `#### `{name}` ({want_kind})`"),
            );
            continue;
        }
        let table = tables
            .iter()
            .find(|t| t.heading.as_ref().is_some_and(|h| h.line == heading.line));
        match (table, rows.is_empty()) {
            (Some(table), _) => {
                check_table(&doc, &mut problems, name, kind, table, &rows);
            }
            (None, true) => {}
            (None, false) => problems.at(
                &doc,
                heading.line,
                format!(
                    "`{name}` needs its table right under this heading:\n    | {} | meaning |\n{}",
                    columns_for(kind).join(" | "),
                    rows.iter()
                        .map(|r| format!("    {}", markdown_row(r, kind)))
                        .collect::<Vec<_>>()
                        .join("\n")
                ),
            ),
        }
    }
    let anchor = headings.last().map_or(1, |(_, _, h)| h.line);
    for (name, container) in &registry {
        if documented.contains_key(name) {
            continue;
        }
        let (kind, rows) = expected(container);
        let mut text =
            format!("`{name}` is not described; add a section\n    #### `{name}` ({kind})\n");
        if !rows.is_empty() {
            text.push_str(&format!(
                "    | {} | meaning |\n",
                columns_for(kind).join(" | ")
            ));
            for row in &rows {
                text.push_str(&format!("    {}\n", markdown_row(row, kind)));
            }
        }
        problems.at(&doc, anchor, text.trim_end());
    }
    problems.finish("message structures");
}

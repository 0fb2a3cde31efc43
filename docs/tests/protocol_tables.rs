//! `docs/protocol.md` against the code: the message kind table and the message headings, the
//! submessage kinds of `Data` and `Feedback`, the drop reasons, the header layout, the domain
//! mapping, and every timer, limit and default.

#[path = "support/values.rs"]
mod values;

use std::collections::BTreeMap;

use ndds_core::domain;
use ndds_core::wire::data::{Addressing, DataSubKind, Fragment, Gap, Heartbeat, Sample};
use ndds_core::wire::feedback::{AckNack, FeedbackSubKind, NackFrag, encode_feedback};
use ndds_core::wire::{
    DataSub, DataWriter, DropReason, FeedbackSub, HEADER_LEN, Header, MAGIC, MAX_DATAGRAM,
    MessageKind, PROTOCOL_VERSION, SampleMeta,
};
use ndds_docs::markdown::{Doc, Table, plain};
use ndds_docs::report::Problems;

fn doc() -> Doc {
    Doc::load("protocol.md")
}

/// The one table whose header starts with `columns`; a problem if there is not exactly one.
fn single_table(doc: &Doc, problems: &mut Problems, columns: &[&str]) -> Option<Table> {
    let mut found: Vec<Table> = doc
        .tables()
        .into_iter()
        .filter(|t| t.starts_with(columns))
        .collect();
    match found.len() {
        1 => found.pop(),
        0 => {
            problems.at(
                doc,
                1,
                format!("no table with the columns `| {} |`", columns.join(" | ")),
            );
            None
        }
        _ => {
            for table in &found[1..] {
                problems.at(
                    doc,
                    table.line,
                    format!(
                        "a second table with the columns `| {} |`; keep one",
                        columns.join(" | ")
                    ),
                );
            }
            found.into_iter().next()
        }
    }
}

#[test]
fn message_kind_table_lists_every_kind_with_its_number() {
    let doc = doc();
    let mut problems = Problems::new();
    if let Some(table) = single_table(&doc, &mut problems, &["kind", "name"]) {
        for kind in MessageKind::ALL {
            let number = (kind as u8).to_string();
            match table.rows.iter().find(|r| r.plain(1) == kind.name()) {
                Some(row) if row.plain(0) == number => {}
                Some(row) => problems.at(
                    &doc,
                    row.line,
                    format!(
                        "`{}` is kind {number} in the code, not {}",
                        kind.name(),
                        row.plain(0)
                    ),
                ),
                None => problems.at(
                    &doc,
                    table.rows.last().map_or(table.line, |r| r.line),
                    format!(
                        "the message table lacks kind {number}: add the row `| {number} | `{}` | … |`",
                        kind.name()
                    ),
                ),
            }
        }
        for row in &table.rows {
            if MessageKind::ALL.iter().all(|k| k.name() != row.plain(1)) {
                problems.at(
                    &doc,
                    row.line,
                    format!(
                        "`{}` is not a message kind of the code (MessageKind::ALL); remove or rename the row",
                        row.plain(1)
                    ),
                );
            }
        }
    }
    check_kind_headings(&doc, &mut problems);
    problems.finish("message kinds");
}

/// Every `### Name (kind N)` heading names a kind with its number, once per kind.
fn check_kind_headings(doc: &Doc, problems: &mut Problems) {
    let mut seen = BTreeMap::new();
    for heading in doc.headings() {
        let Some((name, number)) = heading
            .text
            .strip_suffix(')')
            .and_then(|t| t.split_once(" (kind "))
        else {
            continue;
        };
        match MessageKind::ALL.iter().find(|k| k.name() == name) {
            Some(kind) if (*kind as u8).to_string() == number => {
                seen.insert(kind.name(), heading.line);
            }
            Some(kind) => {
                seen.insert(kind.name(), heading.line);
                problems.at(
                    doc,
                    heading.line,
                    format!("the heading should read `{name} (kind {})`", *kind as u8),
                );
            }
            None => problems.at(
                doc,
                heading.line,
                format!("`{name}` is not a message kind of the code; remove or rename the section"),
            ),
        }
    }
    for kind in MessageKind::ALL {
        if !seen.contains_key(kind.name()) {
            problems.at(
                doc,
                1,
                format!(
                    "no section `### {} (kind {})` describes this message",
                    kind.name(),
                    kind as u8
                ),
            );
        }
    }
}

/// The name of every `Data` submessage kind and the byte `DataWriter` writes for it.
fn data_sub_kinds() -> Vec<(&'static str, u8)> {
    let subs = [
        DataSub::Sample(Sample {
            meta: SampleMeta::default(),
            payload: &[],
        }),
        DataSub::Fragment(Fragment {
            meta: SampleMeta::default(),
            total_len: 0,
            frag_size: 0,
            index: 0,
            chunk: &[],
        }),
        DataSub::Heartbeat(Heartbeat { first: 0, last: 0 }),
        DataSub::Gap(Gap { from: 0, to: 0 }),
    ];
    let to = Addressing {
        reader_participant: 0,
        writer: 0,
        token: 0,
        readers: &[],
    };
    subs.iter()
        .map(|sub| {
            // Exhaustive: a new submessage kind fails to compile here until it is added to the
            // list above (and so to the document).
            let (name, kind) = match sub {
                DataSub::Sample(_) => ("Sample", DataSubKind::Sample),
                DataSub::Fragment(_) => ("Fragment", DataSubKind::Fragment),
                DataSub::Heartbeat(_) => ("Heartbeat", DataSubKind::Heartbeat),
                DataSub::Gap(_) => ("Gap", DataSubKind::Gap),
            };
            let mut writer = DataWriter::new();
            writer.begin(0, 0, &to);
            let start = writer.bytes().len();
            assert!(writer.push(sub, MAX_DATAGRAM));
            assert_eq!(writer.bytes()[start], kind as u8, "DataSubKind::{name}");
            (name, writer.bytes()[start])
        })
        .collect()
}

/// The name of every `Feedback` submessage kind and the byte `encode_feedback` writes for it.
fn feedback_sub_kinds() -> Vec<(&'static str, u8)> {
    let subs = [
        FeedbackSub::AckNack(AckNack {
            reader: 0,
            writer: 0,
            acked: 0,
            missing: &[],
        }),
        FeedbackSub::NackFrag(NackFrag {
            reader: 0,
            writer: 0,
            seq: 0,
            base: 0,
            missing: &[],
        }),
    ];
    subs.iter()
        .map(|sub| {
            let (name, kind) = match sub {
                FeedbackSub::AckNack(_) => ("AckNack", FeedbackSubKind::AckNack),
                FeedbackSub::NackFrag(_) => ("NackFrag", FeedbackSubKind::NackFrag),
            };
            let mut out = Vec::new();
            encode_feedback(0, 0, 0, 0, std::slice::from_ref(sub), &mut out).expect("encodes");
            // Header, a one-byte participant varint, the 8-byte token, then the kind byte.
            let byte = out[HEADER_LEN + 9];
            assert_eq!(byte, kind as u8, "FeedbackSubKind::{name}");
            (name, byte)
        })
        .collect()
}

/// The `| sub_kind | name |` table under the heading that names `datagram`.
fn check_sub_kind_table(doc: &Doc, problems: &mut Problems, datagram: &str, kinds: &[(&str, u8)]) {
    let tables: Vec<Table> = doc
        .tables()
        .into_iter()
        .filter(|t| t.starts_with(&["sub_kind", "name"]))
        .filter(|t| {
            t.heading
                .as_ref()
                .is_some_and(|h| plain(&h.text).starts_with(&format!("{datagram} ")))
        })
        .collect();
    let [table] = &tables[..] else {
        problems.at(
            doc,
            tables.get(1).map_or(1, |t| t.line),
            format!(
                "there must be one `| sub_kind | name | meaning |` table under a heading                  `#### {datagram} submessages`; found {}",
                tables.len()
            ),
        );
        return;
    };
    for (name, byte) in kinds {
        match table.rows.iter().find(|r| r.plain(1) == *name) {
            Some(row) if row.plain(0) == byte.to_string() => {}
            Some(row) => problems.at(
                doc,
                row.line,
                format!("`{name}` is sub_kind {byte} of `{datagram}` in the code"),
            ),
            None => problems.at(
                doc,
                table.rows.last().map_or(table.line, |r| r.line),
                format!("add the row `| {byte} | `{name}` | … |` for `{datagram}`"),
            ),
        }
    }
    for row in &table.rows {
        if kinds.iter().all(|(name, _)| *name != row.plain(1)) {
            problems.at(
                doc,
                row.line,
                format!(
                    "`{}` is not a submessage of `{datagram}` in the code; remove the row",
                    row.plain(1)
                ),
            );
        }
    }
}

#[test]
fn submessage_kind_tables_list_every_kind_with_its_byte() {
    let doc = doc();
    let mut problems = Problems::new();
    check_sub_kind_table(&doc, &mut problems, "Data", &data_sub_kinds());
    check_sub_kind_table(&doc, &mut problems, "Feedback", &feedback_sub_kinds());
    problems.finish("submessage kinds");
}

#[test]
fn drop_reason_table_lists_every_reason_in_counter_order() {
    let doc = doc();
    let mut problems = Problems::new();
    if let Some(table) = single_table(&doc, &mut problems, &["drop reason"]) {
        let documented: Vec<String> = table.rows.iter().map(|r| r.plain(0)).collect();
        let code: Vec<&str> = DropReason::ALL.iter().map(|r| r.name()).collect();
        for (i, reason) in code.iter().enumerate() {
            match documented.iter().position(|d| d == reason) {
                Some(at) if at == i => {}
                Some(at) => problems.at(
                    &doc,
                    table.rows[at].line,
                    format!(
                        "`{reason}` is reason {} in DropReason::ALL (the counter order); move this row to position {}",
                        i + 1,
                        i + 1
                    ),
                ),
                None => problems.at(
                    &doc,
                    table.line,
                    format!("the drop reason table lacks `{reason}`: add a row for it"),
                ),
            }
        }
        for row in &table.rows {
            if !code.contains(&row.plain(0).as_str()) {
                problems.at(
                    &doc,
                    row.line,
                    format!(
                        "`{}` is not a DropReason name; remove or rename the row",
                        row.plain(0)
                    ),
                );
            }
        }
    }
    problems.finish("drop reasons");
}

#[test]
fn header_table_matches_the_emitted_header() {
    let doc = doc();
    let mut problems = Problems::new();
    let header = Header {
        kind: MessageKind::Data,
        domain: 0x0102,
        sender: 0x1122_3344_5566_7788,
    };
    let mut bytes = Vec::new();
    header.emit(&mut bytes);
    let fields: [(&str, Vec<u8>); 5] = [
        ("magic", MAGIC.to_vec()),
        ("version", vec![PROTOCOL_VERSION]),
        ("kind", vec![MessageKind::Data as u8]),
        ("domain", header.domain.to_le_bytes().to_vec()),
        ("sender", header.sender.to_le_bytes().to_vec()),
    ];
    if let Some(table) = single_table(&doc, &mut problems, &["offset", "size", "field"]) {
        let mut next_offset = 0;
        for row in &table.rows {
            let (Ok(offset), Ok(size)) =
                (row.plain(0).parse::<usize>(), row.plain(1).parse::<usize>())
            else {
                problems.at(&doc, row.line, "offset and size must be numbers");
                continue;
            };
            if offset != next_offset {
                problems.at(
                    &doc,
                    row.line,
                    format!("this field should start at offset {next_offset}"),
                );
            }
            next_offset = offset + size;
            let name = row.plain(2);
            match fields.iter().find(|(field, _)| *field == name) {
                Some((_, expected)) if bytes.get(offset..offset + size) == Some(expected) => {}
                Some((_, expected)) => problems.at(
                    &doc,
                    row.line,
                    format!(
                        "`{name}` is not at bytes {offset}..{}: Header::emit writes {expected:02x?} and the header is {bytes:02x?}",
                        offset + size
                    ),
                ),
                None => problems.at(
                    &doc,
                    row.line,
                    format!("`{name}` is not a header field (magic, version, kind, domain, sender)"),
                ),
            }
        }
        if next_offset != HEADER_LEN {
            problems.at(
                &doc,
                table.line,
                format!("the fields cover {next_offset} bytes; the header has {HEADER_LEN}"),
            );
        }
        for (field, _) in &fields {
            if table.rows.iter().all(|r| r.plain(2) != *field) {
                problems.at(
                    &doc,
                    table.line,
                    format!("the header table lacks `{field}`"),
                );
            }
        }
    }
    problems.finish("header layout");
}

#[test]
fn domain_table_matches_the_mapping() {
    let doc = doc();
    let mut problems = Problems::new();
    let columns = [
        "domain",
        "multicast group",
        "discovery port",
        "unicast port",
        "socket name",
    ];
    if let Some(table) = single_table(&doc, &mut problems, &columns) {
        for row in &table.rows {
            let Ok(id) = row.plain(0).parse::<u32>() else {
                problems.at(&doc, row.line, "the domain must be a number");
                continue;
            };
            let Ok(id) = domain::check(id) else {
                problems.at(&doc, row.line, format!("domain {id} is out of range"));
                continue;
            };
            let expected = [
                id.to_string(),
                domain::multicast_group(id).to_string(),
                domain::discovery_port(id).to_string(),
                domain::unicast_port(id).to_string(),
                domain::socket_name(id),
            ];
            let written: Vec<String> = (0..expected.len()).map(|i| row.plain(i)).collect();
            if written != expected {
                problems.at(
                    &doc,
                    row.line,
                    format!("the row should read `| {} |`", expected.join(" | ")),
                );
            }
        }
        for id in [0, domain::MAX_DOMAIN] {
            if table.rows.iter().all(|r| r.plain(0) != id.to_string()) {
                problems.at(
                    &doc,
                    table.line,
                    format!("the domain table should show domain {id}"),
                );
            }
        }
    }
    problems.finish("domain mapping");
}

#[test]
fn every_timer_limit_and_default_has_its_current_value() {
    let doc = doc();
    let mut problems = Problems::new();
    let expected = values::expected();
    let mut seen: BTreeMap<&str, usize> = BTreeMap::new();
    let tables: Vec<Table> = doc
        .tables()
        .into_iter()
        .filter(|t| t.starts_with(&["name", "value"]))
        .collect();
    for row in tables.iter().flat_map(|t| &t.rows) {
        let name = row.plain(0);
        let Some((known, value)) = expected.iter().find(|(n, _)| *n == name) else {
            problems.at(
                &doc,
                row.line,
                format!(
                    "`{name}` is not checked against the code: add it to `expected()` in \
                     docs/tests/support/values.rs, or remove the row"
                ),
            );
            continue;
        };
        if let Some(first) = seen.insert(known, row.line) {
            problems.at(
                &doc,
                row.line,
                format!("`{name}` is already documented at line {first}; keep one row"),
            );
        }
        if plain(&row.cells.get(1).cloned().unwrap_or_default()) != *value {
            problems.at(
                &doc,
                row.line,
                format!(
                    "`{name}` is {value} in the code; the row should read `| `{name}` | {value} | … |`"
                ),
            );
        }
    }
    let anchor = tables.first().map_or(1, |t| t.line);
    for (name, value) in &expected {
        if !seen.contains_key(name) {
            problems.at(
                &doc,
                anchor,
                format!(
                    "`{name}` ({value}) is missing from the `| name | value | meaning |` tables of section 13"
                ),
            );
        }
    }
    problems.finish("timers, limits and defaults");
}

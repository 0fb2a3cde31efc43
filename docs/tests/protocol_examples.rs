//! The worked examples of `docs/protocol.md` against what the code encodes today: every
//! ```` ```hex example:NAME ```` block byte for byte, every ```` ```text canonical:NAME ````
//! block, and the fingerprint table (also recomputed from the documented algorithm). The
//! `Data` and `Feedback` examples are also parsed back into the submessages they show.

use std::net::Ipv4Addr;

use ndds_core::ipc::{self, ClientMessage, DaemonMessage, Hello, Role};
use ndds_core::types::{TypeDescription, fingerprint_hex};
use ndds_core::wire::data::{Addressing, FLAG_RELIABLE, Fragment, Gap, Heartbeat, Sample};
use ndds_core::wire::feedback::{AckNack, NackFrag, encode_feedback};
use ndds_core::wire::{
    self, Announce, Bye, DataDatagram, DataSub, DataWriter, EndpointInfo, EndpointQos,
    FeedbackDatagram, FeedbackSub, Guid, Locator, MAX_DATAGRAM, Message, NodeInfo, ProducerQosWire,
    Reliability, SampleMeta, Withdraw,
};
use ndds_docs::markdown::{Doc, HexByte, hex_lines};
use ndds_docs::report::Problems;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// The types of the canonical-text example (section 8), exactly as the document shows them.
#[derive(Serialize, Deserialize)]
enum Mode {
    Idle,
    Move { speed: f32 },
    Hold(u8, u8),
}

#[derive(Serialize, Deserialize)]
struct Pose {
    x: f64,
    y: f64,
    label: Option<String>,
    mode: Mode,
}

const NODE: u64 = 0x0a0b_0c0d_0e0f_1011;
const PARTICIPANT: u64 = 0x1122_3344_5566_7788;
/// The consuming participant of the data-plane examples.
const CONSUMER: u64 = 0x8877_6655_4433_2211;
const DOMAIN: u16 = 7;
/// The producing participant's address token for the consumer's data socket.
const TOKEN: u64 = 0x0123_4567_89ab_cdef;

/// From producer entity 1 of `PARTICIPANT` to consumers 2 and 5 of `CONSUMER`.
const TO_CONSUMERS: Addressing<'static> = Addressing {
    reader_participant: CONSUMER,
    writer: 1,
    token: TOKEN,
    readers: &[2, 5],
};

fn localhost(port: u16) -> Locator {
    Locator {
        addr: Ipv4Addr::LOCALHOST.octets(),
        port,
    }
}

fn datagram(domain: u16, sender: u64, message: &Message) -> Vec<u8> {
    let mut out = Vec::new();
    wire::encode(domain, sender, message, &mut out).expect("example encodes");
    out
}

fn announced_producer() -> EndpointInfo {
    let type_desc = TypeDescription::try_of::<f64>().expect("f64 is traceable");
    EndpointInfo {
        guid: Guid {
            participant: PARTICIPANT,
            entity: 1,
        },
        topic: "demo/value".to_owned(),
        fingerprint: type_desc.fingerprint(),
        type_desc,
        qos: EndpointQos::Producer(ProducerQosWire {
            strength: 0,
            persistence_us: 0,
            reliability: Reliability::BestEffort,
        }),
        locator: localhost(40001),
        pid: 4243,
        process: "demo".to_owned(),
    }
}

/// `Pose` under the explicit name the document shows (its derived name would be `Pose`).
fn pose_description() -> TypeDescription {
    let desc = TypeDescription::named::<Pose>("demo::Pose");
    assert!(desc.layout.is_some(), "Pose is traceable");
    desc
}

/// The metadata of sample `seq` of the data-plane examples' reliable producer.
fn meta(seq: u64, timestamp_ns: u64) -> SampleMeta {
    SampleMeta {
        seq,
        timestamp_ns,
        strength: -3,
        persistence_us: 300_000,
        flags: FLAG_RELIABLE,
    }
}

/// Sample 1 (the `f64` value 1.5) and a heartbeat behind it.
fn data_example(payload: &[u8]) -> Vec<DataSub<'_>> {
    vec![
        DataSub::Sample(Sample {
            meta: meta(1, 1_700_000_000_123_456_789),
            payload,
        }),
        DataSub::Heartbeat(Heartbeat { first: 1, last: 1 }),
    ]
}

/// A gap, then the last piece of a 10-byte sample cut into 4-byte pieces.
fn fragment_example() -> Vec<DataSub<'static>> {
    vec![
        DataSub::Gap(Gap { from: 2, to: 4 }),
        DataSub::Fragment(Fragment {
            meta: meta(4, 1_700_000_000_200_000_000),
            total_len: 10,
            frag_size: 4,
            index: 2,
            chunk: &[0xaa, 0xbb],
        }),
    ]
}

/// Everything before 5 arrived, 5 and 7 are missing; and pieces 1 and 2 of sample 9 are.
fn feedback_example() -> Vec<FeedbackSub<'static>> {
    vec![
        FeedbackSub::AckNack(AckNack {
            reader: 2,
            writer: 1,
            acked: 5,
            missing: &[0b0000_0101],
        }),
        FeedbackSub::NackFrag(NackFrag {
            reader: 2,
            writer: 1,
            seq: 9,
            base: 0,
            missing: &[0b0000_0110],
        }),
    ]
}

fn data_datagram(subs: &[DataSub<'_>]) -> Vec<u8> {
    let mut writer = DataWriter::new();
    writer.begin(DOMAIN, PARTICIPANT, &TO_CONSUMERS);
    for sub in subs {
        assert!(writer.push(sub, MAX_DATAGRAM), "example fits a datagram");
    }
    writer.bytes().to_vec()
}

fn feedback_datagram(subs: &[FeedbackSub<'_>]) -> Vec<u8> {
    let mut out = Vec::new();
    encode_feedback(DOMAIN, CONSUMER, PARTICIPANT, TOKEN, subs, &mut out).expect("example encodes");
    out
}

/// Every hex example the document must show, encoded by the code.
fn hex_examples() -> Vec<(&'static str, Vec<u8>)> {
    let payload = postcard::to_allocvec(&1.5_f64).expect("f64 encodes");
    let node = NodeInfo {
        hostname: "h1".to_owned(),
        pid: 4242,
        unicast: localhost(40000),
        lease_ms: 5000,
        announce_period_ms: 1000,
        version: "0.1.0".to_owned(),
    };
    let announce = Announce {
        node,
        endpoints: vec![announced_producer()],
        withdrawn: Vec::new(),
    };
    let withdraw = Withdraw {
        endpoints: vec![announced_producer().guid],
    };
    let hello = ClientMessage::Hello(Hello {
        ipc_version: ipc::IPC_VERSION,
        participant: PARTICIPANT,
        pid: 4243,
        name: "demo".to_owned(),
        role: Role::Client,
    });
    let declared = DaemonMessage::Declared {
        entity: 1,
        result: Ok(()),
    };
    vec![
        (
            "bye",
            datagram(7, 0x0123_4567_89ab_cdef, &Message::Bye(Bye)),
        ),
        ("data", data_datagram(&data_example(&payload))),
        ("data-fragment", data_datagram(&fragment_example())),
        ("feedback", feedback_datagram(&feedback_example())),
        ("announce", datagram(0, NODE, &Message::Announce(announce))),
        ("withdraw", datagram(0, NODE, &Message::Withdraw(withdraw))),
        (
            "hello-frame",
            ipc::encode_frame(&hello).expect("frame encodes"),
        ),
        (
            "declared-frame",
            ipc::encode_frame(&declared).expect("frame encodes"),
        ),
        (
            "pose-description",
            postcard::to_allocvec(&pose_description()).expect("description encodes"),
        ),
    ]
}

/// Every canonical-text example, with its description.
fn canonical_examples() -> Vec<(&'static str, TypeDescription)> {
    vec![
        ("pose", pose_description()),
        (
            "f64",
            TypeDescription::try_of::<f64>().expect("f64 is traceable"),
        ),
        ("blob", TypeDescription::opaque("demo::Blob")),
    ]
}

/// Names of the blocks whose info string is `"{language} {prefix}:NAME"`, with the blocks.
fn named_blocks(
    doc: &Doc,
    language: &str,
    prefix: &str,
) -> Vec<(String, ndds_docs::markdown::Block)> {
    let head = format!("{language} {prefix}:");
    doc.blocks()
        .into_iter()
        .filter_map(|b| Some((b.info.strip_prefix(&head)?.to_owned(), b)))
        .collect()
}

fn compare_bytes(doc: &Doc, problems: &mut Problems, name: &str, written: &[HexByte], code: &[u8]) {
    let code_hex = hex_lines(code, 16);
    let first_difference = written.iter().zip(code).position(|(w, c)| w.value != *c);
    match first_difference {
        Some(i) => problems.at(
            doc,
            written[i].line,
            format!(
                "example `{name}`: byte {i} is {:02x} here but the code encodes {:02x}; the code's \
                 bytes ({} in all) are\n{code_hex}",
                written[i].value,
                code[i],
                code.len()
            ),
        ),
        None if written.len() > code.len() => problems.at(
            doc,
            written[code.len()].line,
            format!(
                "example `{name}`: the code's encoding ends before this byte ({} bytes); they are\n{code_hex}",
                code.len()
            ),
        ),
        None if written.len() < code.len() => problems.at(
            doc,
            written.last().map_or(1, |b| b.line),
            format!(
                "example `{name}`: the code encodes {} more byte(s) after this line: {}",
                code.len() - written.len(),
                hex_lines(&code[written.len()..], 16)
            ),
        ),
        None => {}
    }
}

#[test]
fn hex_examples_are_what_the_code_encodes() {
    let doc = Doc::load("protocol.md");
    let mut problems = Problems::new();
    let examples = hex_examples();
    let blocks = named_blocks(&doc, "hex", "example");
    for (name, block) in &blocks {
        let Some((_, code)) = examples.iter().find(|(n, _)| n == name) else {
            problems.at(
                &doc,
                block.line,
                format!(
                    "no example `{name}` in docs/tests/protocol_examples.rs: add it to hex_examples() \
                     or remove this block"
                ),
            );
            continue;
        };
        match block.hex_bytes() {
            Ok(written) => compare_bytes(&doc, &mut problems, name, &written, code),
            Err((line, reason)) => problems.at(&doc, line, reason),
        }
    }
    for (name, code) in &examples {
        match blocks.iter().filter(|(n, _)| n == name).count() {
            1 => {}
            0 => problems.at(
                &doc,
                1,
                format!(
                    "the example `{name}` is missing: add a block ```hex example:{name} with\n{}",
                    hex_lines(code, 16)
                ),
            ),
            _ => problems.at(
                &doc,
                1,
                format!("the example `{name}` appears more than once"),
            ),
        }
    }
    problems.finish("worked examples");
}

/// The data-plane examples say what they carry; the parsers must read that back.
#[test]
fn data_plane_examples_parse_back() {
    let payload = postcard::to_allocvec(&1.5_f64).expect("f64 encodes");
    for (bytes, subs) in [
        (
            data_datagram(&data_example(&payload)),
            data_example(&payload),
        ),
        (data_datagram(&fragment_example()), fragment_example()),
    ] {
        let datagram = DataDatagram::parse(&bytes, DOMAIN).expect("example parses");
        assert_eq!(datagram.header.sender, PARTICIPANT);
        assert_eq!(datagram.reader_participant, CONSUMER);
        assert_eq!(datagram.writer, TO_CONSUMERS.writer);
        assert_eq!(datagram.token, TOKEN);
        assert_eq!(datagram.readers.as_slice(), TO_CONSUMERS.readers);
        let parsed: Result<Vec<_>, _> = datagram.subs().collect();
        assert_eq!(parsed, Ok(subs));
    }
    let bytes = feedback_datagram(&feedback_example());
    let datagram = FeedbackDatagram::parse(&bytes, DOMAIN).expect("example parses");
    assert_eq!(datagram.header.sender, CONSUMER);
    assert_eq!(datagram.writer_participant, PARTICIPANT);
    assert_eq!(datagram.token, TOKEN);
    let parsed: Result<Vec<_>, _> = datagram.subs().collect();
    assert_eq!(parsed, Ok(feedback_example()));
}

#[test]
fn canonical_texts_and_fingerprints_are_what_the_code_computes() {
    let doc = Doc::load("protocol.md");
    let mut problems = Problems::new();
    let examples = canonical_examples();
    let blocks = named_blocks(&doc, "text", "canonical");
    for (name, desc) in &examples {
        let text = desc.canonical_text();
        match blocks.iter().find(|(n, _)| n == name) {
            Some((_, block)) if block.text() == text => {}
            Some((_, block)) => problems.at(
                &doc,
                block.lines.first().map_or(block.line, |(l, _)| *l),
                format!("the canonical text of `{name}` is now\n{text}"),
            ),
            None => problems.at(
                &doc,
                1,
                format!("add a block ```text canonical:{name} with\n{text}"),
            ),
        }
        // The document's rule, applied independently of ndds-core.
        let digest = Sha256::digest(text.as_bytes());
        let mut first = [0_u8; 8];
        first.copy_from_slice(&digest[..8]);
        if u64::from_be_bytes(first) != desc.fingerprint() {
            let line = (1..=doc.len())
                .find(|l| doc.line(*l).contains("first 8 bytes of the SHA-256"))
                .unwrap_or(1);
            problems.at(
                &doc,
                line,
                format!(
                    "the fingerprint of `{name}` is no longer the first 8 bytes of SHA-256 of its \
                     canonical text, big-endian: describe the new rule"
                ),
            );
        }
    }
    for (name, block) in &blocks {
        if examples.iter().all(|(n, _)| n != name) {
            problems.at(
                &doc,
                block.line,
                format!("no canonical example `{name}` in canonical_examples(); add it or remove this block"),
            );
        }
    }
    check_fingerprint_table(&doc, &mut problems, &examples);
    problems.finish("canonical text and fingerprints");
}

fn check_fingerprint_table(
    doc: &Doc,
    problems: &mut Problems,
    examples: &[(&str, TypeDescription)],
) {
    let tables: Vec<_> = doc
        .tables()
        .into_iter()
        .filter(|t| t.starts_with(&["example", "fingerprint"]))
        .collect();
    let rows: Vec<_> = tables.iter().flat_map(|t| &t.rows).collect();
    for (name, desc) in examples {
        let hex = fingerprint_hex(desc.fingerprint());
        match rows.iter().find(|r| r.plain(0) == *name) {
            Some(row) if row.plain(1) == hex => {}
            Some(row) => problems.at(
                doc,
                row.line,
                format!("the fingerprint of `{name}` is now {hex}: the row should read `| `{name}` | `{hex}` |`"),
            ),
            None => problems.at(
                doc,
                tables.first().map_or(1, |t| t.line),
                format!("the fingerprint table lacks `| `{name}` | `{hex}` |`"),
            ),
        }
    }
    for row in rows {
        if examples.iter().all(|(n, _)| row.plain(0) != *n) {
            problems.at(
                doc,
                row.line,
                format!(
                    "`{}` is not a canonical example; remove the row",
                    row.plain(0)
                ),
            );
        }
    }
}

//! Writes the seed corpus, `fuzz/corpus/<target>/`, from real messages made by the crates' own
//! encoders and by real engines talking to each other; every seed is a valid input that
//! reaches deep into its target. Run from the repository root:
//!
//! ```text
//! cargo run --manifest-path fuzz/Cargo.toml --example seeds
//! ```
//!
//! The output is deterministic; the files are committed, so run it again only when a wire
//! format or a target's input format changes.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use bytes::BytesMut;
use ndds_core::discovery::{Destination, Engine};
use ndds_core::ipc::{
    ClientMessage, DaemonMessage, EndpointDecl, Hello, IPC_VERSION, Role, Welcome, encode_body,
};
use ndds_core::seal::{SealMode, Sealer};
use ndds_core::types::TypeDescription;
use ndds_core::wire::data::{Addressing, FLAG_RELIABLE, Fragment, Gap, Heartbeat, Sample};
use ndds_core::wire::feedback::{AckNack, NackFrag, encode_feedback};
use ndds_core::wire::{self, Bye, DataSub, DataWriter, FeedbackSub, Guid, Message, SampleMeta};
use ndds_fuzz::fixture::{self, DOMAIN, keyring};
use ndds_fuzz::{Script, discovery, participant};
use ndds_runtime::CsMat;
use serde::{Deserialize, Serialize};

/// Seeds by target, then by file name.
type Corpus = BTreeMap<&'static str, BTreeMap<String, Vec<u8>>>;

/// A type with every kind of layout node the dynamic decoder walks.
#[derive(Serialize, Deserialize)]
struct Scene {
    name: String,
    poses: Vec<discovery::Pose>,
    shape: Shape,
    tags: BTreeMap<String, i64>,
    ids: BTreeMap<u32, String>,
    grid: [u8; 4],
    pair: (i16, u128, f32),
    flag: Option<bool>,
    letter: char,
    blob: Vec<u8>,
    unit: (),
}

#[derive(Serialize, Deserialize)]
enum Shape {
    Empty,
    Circle(f64),
    Rect { w: f32, h: f32 },
    Poly(Vec<(i32, i32)>),
}

#[derive(Serialize, Deserialize)]
struct Tree {
    value: i32,
    children: Vec<Tree>,
}

fn main() -> std::io::Result<()> {
    let mut corpus = Corpus::new();
    wire_seeds(&mut corpus);
    type_seeds(&mut corpus);
    ipc_seeds(&mut corpus);
    seal_seeds(&mut corpus);
    csmat_seeds(&mut corpus);
    discovery_engine_seeds(&mut corpus);
    participant_seeds(&mut corpus);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus");
    let mut total = 0;
    for (target, seeds) in &corpus {
        // Files of other names stay: regression inputs added after a crash was fixed.
        let dir = root.join(target);
        std::fs::create_dir_all(&dir)?;
        for (name, bytes) in seeds {
            std::fs::write(dir.join(name), bytes)?;
            total += bytes.len();
        }
        println!("{target}: {} seeds", seeds.len());
    }
    println!("{total} bytes in all");
    Ok(())
}

fn add(corpus: &mut Corpus, target: &'static str, name: impl Into<String>, bytes: Vec<u8>) {
    corpus.entry(target).or_default().insert(name.into(), bytes);
}

fn meta(seq: u64) -> SampleMeta {
    SampleMeta {
        seq,
        timestamp_ns: 1_700_000_000_000_000_000 + seq,
        strength: 2,
        persistence_us: 1000,
        flags: FLAG_RELIABLE,
    }
}

/// The datagrams of every kind: header, discovery bodies, data and feedback.
fn wire_seeds(corpus: &mut Corpus) {
    let pose = postcard::to_allocvec(&discovery::Pose {
        x: 1.5,
        y: -2.0,
        label: Some("arm".into()),
    })
    .expect("encodes");
    let chunk = [7u8; 300];
    let subs: Vec<(&str, Vec<DataSub<'_>>)> = vec![
        (
            "sample",
            vec![DataSub::Sample(Sample {
                meta: meta(1),
                payload: &pose,
            })],
        ),
        (
            "fragment",
            vec![DataSub::Fragment(Fragment {
                meta: meta(2),
                total_len: 900,
                frag_size: 300,
                index: 1,
                chunk: &chunk,
            })],
        ),
        (
            "batch_heartbeat",
            vec![
                DataSub::Sample(Sample {
                    meta: meta(3),
                    payload: &pose,
                }),
                DataSub::Sample(Sample {
                    meta: meta(4),
                    payload: &pose,
                }),
                DataSub::Heartbeat(Heartbeat { first: 1, last: 4 }),
            ],
        ),
        ("gap", vec![DataSub::Gap(Gap { from: 2, to: 5 })]),
    ];
    for (name, subs) in &subs {
        let mut writer = DataWriter::new();
        writer.begin(
            DOMAIN,
            0xB0,
            &Addressing {
                reader_participant: 0xA0,
                writer: 1,
                token: 0x0123_4567_89AB_CDEF,
                readers: &[2, 3],
            },
        );
        for sub in subs {
            assert!(writer.push(sub, wire::MAX_DATAGRAM));
        }
        let bytes = writer.bytes().to_vec();
        add(corpus, "data", *name, [&[0u8][..], &bytes].concat());
        add(corpus, "header", format!("data_{name}"), bytes);
    }
    let feedback: Vec<(&str, FeedbackSub<'_>)> = vec![
        (
            "acknack",
            FeedbackSub::AckNack(AckNack {
                reader: 2,
                writer: 1,
                acked: 3,
                missing: &[0b101],
            }),
        ),
        (
            "nackfrag",
            FeedbackSub::NackFrag(NackFrag {
                reader: 2,
                writer: 1,
                seq: 2,
                base: 0,
                missing: &[0xff, 1],
            }),
        ),
    ];
    for (name, sub) in feedback {
        let mut bytes = Vec::new();
        encode_feedback(DOMAIN, 0xA0, 0xB0, 42, &[sub], &mut bytes).expect("encodes");
        add(corpus, "feedback", name, bytes.clone());
        add(corpus, "header", format!("feedback_{name}"), bytes);
    }
    // Discovery bodies as a real engine sends them (Solicit, Announce), and the rest.
    let now = Instant::now();
    let mut engine = Engine::new(discovery::config(1, false), now).expect("valid config");
    for (entity, producer) in [(1, true), (2, false)] {
        engine
            .add_local(now, discovery::endpoint(0xB0, entity, producer, 1))
            .expect("declared");
    }
    engine.remove_locals(&[Guid {
        participant: 0xB0,
        entity: 2,
    }]);
    let mut sent = Vec::new();
    while let Some(transmit) = engine.poll_transmit() {
        sent.push(transmit.payload.to_vec());
    }
    engine.close();
    while let Some(transmit) = engine.poll_transmit() {
        sent.push(transmit.payload.to_vec());
    }
    let mut bye = Vec::new();
    wire::encode(DOMAIN, 0x1001, &Message::Bye(Bye), &mut bye).expect("encodes");
    sent.push(bye);
    for (i, bytes) in sent.into_iter().enumerate() {
        let kind = wire::decode(&bytes)
            .map(|(h, _)| h.kind.name())
            .unwrap_or("other");
        add(
            corpus,
            "discovery_message",
            format!("{i:02}_{kind}"),
            bytes.clone(),
        );
        add(corpus, "header", format!("discovery_{i:02}_{kind}"), bytes);
    }
}

/// Type descriptions, and layouts with payloads for the dynamic decoder.
fn type_seeds(corpus: &mut Corpus) {
    let scene = Scene {
        name: "s".into(),
        poses: vec![discovery::Pose {
            x: 0.1,
            y: f64::NAN,
            label: None,
        }],
        shape: Shape::Rect { w: 1.0, h: 2.5 },
        tags: BTreeMap::from([("a".into(), -1)]),
        ids: BTreeMap::from([(7, "seven".into())]),
        grid: [1, 2, 3, 4],
        pair: (-3, u128::MAX, 0.25),
        flag: Some(true),
        letter: 'é',
        blob: vec![0, 255],
        unit: (),
    };
    let tree = Tree {
        value: 1,
        children: vec![Tree {
            value: 2,
            children: Vec::new(),
        }],
    };
    let descriptions = [
        ("pose", TypeDescription::of::<discovery::Pose>()),
        (
            "scene",
            TypeDescription::describer()
                .with::<Shape>()
                .describe::<Scene>()
                .expect("traces"),
        ),
        ("tree", TypeDescription::of::<Tree>()),
        ("poly", TypeDescription::of::<Shape>()),
        ("opaque", TypeDescription::opaque("ndds::Blob")),
    ];
    let payloads: BTreeMap<&str, Vec<Vec<u8>>> = BTreeMap::from([
        (
            "pose",
            vec![
                postcard::to_allocvec(&scene.poses[0]).expect("encodes"),
                postcard::to_allocvec(&discovery::Pose {
                    x: -0.0,
                    y: 1e300,
                    label: Some("x".into()),
                })
                .expect("encodes"),
            ],
        ),
        (
            "scene",
            vec![postcard::to_allocvec(&scene).expect("encodes")],
        ),
        ("tree", vec![postcard::to_allocvec(&tree).expect("encodes")]),
        (
            "poly",
            vec![
                postcard::to_allocvec(&Shape::Poly(vec![(1, -1), (2, 3)])).expect("encodes"),
                postcard::to_allocvec(&Shape::Empty).expect("encodes"),
                postcard::to_allocvec(&Shape::Circle(2.0)).expect("encodes"),
            ],
        ),
    ]);
    for (name, desc) in descriptions {
        let encoded = postcard::to_allocvec(&desc).expect("encodes");
        add(corpus, "type_layout", name, encoded);
        let Some(layout) = &desc.layout else {
            continue;
        };
        let layout = postcard::to_allocvec(layout).expect("encodes");
        for (i, payload) in payloads.get(name).into_iter().flatten().enumerate() {
            add(
                corpus,
                "dynamic_json",
                format!("{name}_{i}"),
                [&layout[..], payload].concat(),
            );
        }
    }
}

fn ipc_seeds(corpus: &mut Corpus) {
    let info = discovery::endpoint(0xB0, 1, true, 1);
    let client = [
        (
            "hello",
            ClientMessage::Hello(Hello {
                ipc_version: IPC_VERSION,
                participant: 0xB0,
                pid: 42,
                name: "fuzz".into(),
                role: Role::Client,
            }),
        ),
        (
            "declare",
            ClientMessage::Declare(EndpointDecl {
                entity: 1,
                topic: info.topic.clone(),
                type_desc: info.type_desc.clone(),
                fingerprint: info.fingerprint,
                qos: info.qos,
                locator: info.locator,
            }),
        ),
        ("undeclare", ClientMessage::Undeclare { entity: 1 }),
        (
            "query",
            ClientMessage::QueryGraph {
                request: 9,
                after: None,
            },
        ),
    ];
    for (name, message) in client {
        add(
            corpus,
            "ipc_client",
            name,
            encode_body(&message).expect("encodes"),
        );
    }
    let daemon = [
        (
            "welcome",
            DaemonMessage::Welcome(Welcome {
                ipc_version: IPC_VERSION,
                node: 0x1001,
                participant: 0x2002,
                domain: DOMAIN,
                hostname: "host".into(),
                interface: [127, 0, 0, 1],
                pid: 7,
                version: "0.1.0".into(),
                pairwise: true,
            }),
        ),
        (
            "pair_keys",
            DaemonMessage::PairKeys {
                local: 1,
                participant: 0xB0,
                locator: ndds_core::wire::Locator {
                    addr: [127, 0, 0, 1],
                    port: 7400,
                },
                keys: ndds_core::security::DataKeys {
                    send: [1; 32],
                    receive: [2; 32],
                },
            },
        ),
        (
            "refused",
            DaemonMessage::Refused {
                reason: "version".into(),
            },
        ),
        (
            "declared",
            DaemonMessage::Declared {
                entity: 1,
                result: Err("bad topic".into()),
            },
        ),
        (
            "matched",
            DaemonMessage::Matched {
                local: 1,
                remote: info.clone(),
            },
        ),
        (
            "unmatched",
            DaemonMessage::Unmatched {
                local: 1,
                remote: info.guid,
            },
        ),
    ];
    for (name, message) in daemon {
        add(
            corpus,
            "ipc_daemon",
            name,
            encode_body(&message).expect("encodes"),
        );
    }
}

fn seal_seeds(corpus: &mut Corpus) {
    for (name, flags) in [("chacha", 0u8), ("aes", 1), ("aes128", 9), ("aegis", 16)] {
        let keys = keyring(fixture::cipher(flags));
        add(corpus, "keyfile", name, keys.to_file_text().into_bytes());
        let mut script = Script::new();
        script.u8(flags);
        for (i, mode) in [SealMode::Encrypt, SealMode::IntegrityOnly]
            .into_iter()
            .enumerate()
        {
            let mut sealer = Sealer::new(&keys, DOMAIN, 0x100 + i as u64, 1, mode);
            let mut datagram = Vec::new();
            wire::encode(DOMAIN, 0x100, &Message::Bye(Bye), &mut datagram).expect("encodes");
            datagram.extend_from_slice(b"body");
            sealer.seal(&mut datagram).expect("seals");
            script.op_bytes(&datagram);
        }
        let mut plain = Vec::new();
        wire::encode(DOMAIN, 0x100, &Message::Bye(Bye), &mut plain).expect("encodes");
        script.op_bytes(&plain);
        add(corpus, "seal_open", name, script.bytes().to_vec());
    }
    // seal_roundtrip: seal and deliver, hold back, replay, corrupt, pause, other sessions.
    for (name, flags) in [
        ("chacha_encrypt", 0u8),
        ("aes_integrity", 3),
        ("required", 6),
        ("aes128_encrypt", 9),
        ("aegis_encrypt", 16),
        ("aegis_integrity", 18),
    ] {
        let mut script = Script::new();
        script.u8(flags);
        script.op(0, &[1, 1, 2, 3]);
        script.op(1, &[2, 9]);
        script.op(4, &[4, 5]); // the other sender
        script.op(0, &[1]);
        script.op(2, &[1]);
        script.op(2, &[0]);
        script.op(3, &[0, 77, 0]);
        script.op(3 << 3, &[2, 6, 6]); // session 4
        script.op(1 << 3 | 3 << 5, &[3]); // session 2, after 90 s
        add(corpus, "seal_roundtrip", name, script.bytes().to_vec());
    }
}

/// Extension of [`Script`] for seal_open, whose chunks have no operation code.
trait Chunks {
    fn op_bytes(&mut self, bytes: &[u8]);
}

impl Chunks for Script {
    fn op_bytes(&mut self, bytes: &[u8]) {
        let len = u16::try_from(bytes.len()).expect("short");
        for byte in len.to_le_bytes() {
            self.u8(byte);
        }
        for &byte in bytes {
            self.u8(byte);
        }
    }
}

fn csmat_seeds(corpus: &mut Corpus) {
    let plain = CsMat::from_rows("K", &[&[2.0, 0.0], &[0.0, 3.0]]).expect("valid");
    let named = CsMat::from_row_slice("x", 2, 1, &[0.5, f64::NAN])
        .expect("valid")
        .with_row_fields([("q1", "rad"), ("q2", "rad")])
        .expect("two rows")
        .with_col_fields([("v", "")])
        .expect("one column");
    let empty = CsMat::zeros("e", 0, 4);
    for (name, mat) in [("plain", plain), ("named", named), ("empty", empty)] {
        add(
            corpus,
            "csmat",
            name,
            postcard::to_allocvec(&mat).expect("encodes"),
        );
    }
}

/// The discovery engine: what a remote engine (host 1) says over a few seconds, recorded as
/// the datagrams that reach host 0, in clear, framed and sealed.
fn discovery_engine_seeds(corpus: &mut Corpus) {
    use discovery::{flag, op};
    for (name, flags) in [
        ("multicast", 0u8),
        ("unicast", flag::UNICAST),
        ("sealed", flag::KEYED),
        (
            "sealed_aes_integrity",
            flag::KEYED | flag::AES | flag::INTEGRITY_ONLY,
        ),
        ("permissions", flag::KEYED | flag::GUARDED),
    ] {
        let now = Instant::now();
        let remote_config = if flags & flag::GUARDED != 0 {
            discovery::guarded_config(1, flags & flag::UNICAST != 0)
        } else {
            discovery::config(1, flags & flag::UNICAST != 0)
        };
        let mut remote = Engine::new(remote_config, now).expect("valid");
        if flags & flag::KEYED != 0 {
            remote.seal_with(discovery::seal_setup(flags, 7));
        }
        if flags & flag::GUARDED != 0 {
            remote.guard_with(discovery::guard(1));
        }
        let participant = discovery::participant(1, flags & flag::GUARDED != 0);
        remote
            .add_local(now, discovery::endpoint(participant, 1, true, 1))
            .expect("declared");
        remote
            .add_local(now, discovery::endpoint(participant, 2, false, 1))
            .expect("declared");
        let mut script = Script::new();
        script.u8(flags);
        script.op(op::LOCALS, &[0b0000]);
        script.op(op::LOCALS, &[0b0101]);
        let mut at = now;
        for step in 0..6 {
            while let Some(transmit) = remote.poll_transmit() {
                let via = match transmit.destination {
                    Destination::Multicast => 0,
                    Destination::Unicast(_) => 0x80,
                };
                let mut chunk = vec![via];
                chunk.extend_from_slice(&transmit.payload);
                script.op(op::RAW, &chunk);
                // The same body framed (and sealed) by the harness.
                if let Ok((header, _)) = wire::decode(&transmit.payload) {
                    let kind = wire::MessageKind::ALL
                        .iter()
                        .position(|k| *k == header.kind)
                        .expect("a known kind") as u8;
                    let body = &transmit.payload[wire::HEADER_LEN..];
                    let code = if flags & flag::KEYED != 0 {
                        op::SEALED
                    } else {
                        op::FRAMED
                    };
                    script.op(code, &[&[via, kind][..], body].concat());
                }
            }
            if step == 4 {
                remote.remove_locals(&[Guid {
                    participant: 0xB0,
                    entity: 2,
                }]);
            }
            if step == 5 {
                remote.close();
                continue;
            }
            let next = remote
                .poll_timeout()
                .unwrap_or(at + Duration::from_millis(500));
            let wait = next
                .saturating_duration_since(at)
                .max(Duration::from_millis(1));
            let ms = u16::try_from(wait.as_millis()).unwrap_or(u16::MAX);
            at += Duration::from_millis(u64::from(ms));
            remote.handle_timeout(at);
            script.op(op::TIME, &ms.to_le_bytes());
        }
        script.op(op::TIME, &20_000u16.to_le_bytes());
        script.op(op::CLOSE, &[]);
        add(corpus, "discovery_engine", name, script.bytes().to_vec());
    }
}

/// The data plane: the harness's participant (LOCAL) and a real peer core exchange samples
/// both ways, small and fragmented, over a link that drops some datagrams; every datagram
/// that reaches LOCAL is recorded as a RAW operation, and LOCAL's own writes and time steps
/// as theirs, so the script replays the same conversation.
fn participant_seeds(corpus: &mut Corpus) {
    use participant::{CONSUMERS, LOCAL, PEER, PRODUCERS, flag, op};
    for (name, flags) in [
        ("clear", 0u8),
        ("sealed", flag::KEYED),
        (
            "sealed_aes_integrity",
            flag::KEYED | flag::AES | flag::INTEGRITY_ONLY,
        ),
    ] {
        let start = Instant::now();
        let mut harness = participant::Harness::new(flags, start);
        harness.keep_sent();
        let local_addr = fixture::data_addr(0);
        let mut peer = participant::core(PEER, LOCAL, local_addr, start);
        if flags & flag::KEYED != 0 {
            peer.seal_with(participant::seal_setup(flags, 2));
        }
        let mut script = Script::new();
        script.u8(flags);
        let received = SystemTime::UNIX_EPOCH + Duration::from_secs(1_700_000_000);
        let mut dropped = 0u32;
        for round in 0..12u16 {
            // Both sides write: small samples, and every third round one in pieces.
            let size: u16 = if round % 3 == 2 { 2600 } else { 40 };
            let sel = (round % 2) as u8;
            let mut write = vec![sel];
            write.extend_from_slice(&size.to_le_bytes());
            script.op(op::WRITE, &write);
            harness.step(op::WRITE, &write);
            let payload = Arc::new(vec![0x5a; usize::from(size)]);
            let _ = peer.write(harness.now, 1, PRODUCERS[usize::from(sel)], &payload);
            // LOCAL's datagrams reach the peer, except every seventh.
            for (_, bytes) in harness.take_sent() {
                dropped += 1;
                if !dropped.is_multiple_of(7) {
                    peer.handle_datagram(
                        harness.now,
                        received,
                        local_addr,
                        BytesMut::from(&bytes[..]),
                    );
                }
            }
            // The peer's datagrams reach LOCAL, except every fifth.
            let mut to_local = Vec::new();
            while let Some(transmit) = peer.poll_transmit() {
                to_local.push([transmit.head(), transmit.tail()].concat());
                peer.recycle(transmit);
            }
            while peer.poll_event().is_some() {}
            for (i, bytes) in to_local.into_iter().enumerate() {
                if i % 5 == 4 {
                    continue;
                }
                // sel bit 1: delivered as it is (already sealed by the peer).
                let chunk = [&[2u8][..], &bytes].concat();
                script.op(op::RAW, &chunk);
                harness.step(op::RAW, &chunk);
            }
            if round % 4 == 3 {
                script.op(op::TAKEN, &[3]);
                harness.step(op::TAKEN, &[3]);
            }
            let ms = 30u16.to_le_bytes();
            script.op(op::TIME, &ms);
            harness.step(op::TIME, &ms);
            peer.handle_timeout(harness.now);
        }
        add(corpus, "participant", name, script.bytes().to_vec());
    }
    // Framed submessages and feedback, the harness's own prefixes.
    let mut script = Script::new();
    script.u8(0);
    let pose = [1u8, 2, 3];
    let mut writer = DataWriter::new();
    writer.begin(
        DOMAIN,
        PEER,
        &Addressing {
            reader_participant: LOCAL,
            writer: 1,
            token: 0,
            readers: &[],
        },
    );
    let prefix = writer.bytes().len();
    assert!(writer.push(
        &DataSub::Sample(Sample {
            meta: meta(1),
            payload: &pose
        }),
        1200
    ));
    assert!(writer.push(&DataSub::Heartbeat(Heartbeat { first: 1, last: 3 }), 1200));
    script.op(
        op::DATA,
        &[&[0b011u8][..], &writer.bytes()[prefix..]].concat(),
    );
    let mut feedback = Vec::new();
    let acknack = FeedbackSub::AckNack(AckNack {
        reader: CONSUMERS[0],
        writer: PRODUCERS[0],
        acked: 1,
        missing: &[1],
    });
    encode_feedback(DOMAIN, PEER, LOCAL, 0, &[acknack], &mut feedback).expect("encodes");
    let mut varint = Vec::new();
    participant::push_varint(&mut varint, LOCAL);
    let sub_start = wire::HEADER_LEN + varint.len() + 8;
    script.op(op::WRITE, &[0, 40, 0]);
    script.op(op::FEEDBACK, &[&[0u8][..], &feedback[sub_start..]].concat());
    script.op(op::MATCH, &[0]);
    script.op(op::MATCH, &[2]);
    script.op(op::TIME, &500u16.to_le_bytes());
    add(corpus, "participant", "framed", script.bytes().to_vec());
}

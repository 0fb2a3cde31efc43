//! Per-topic permissions between real daemons on three hosts of one sealed domain, set up with
//! the `ndds security` commands themselves:
//!
//! - `h0` is subject `arm`: it publishes `arm/*` and `status/*` and reads everything;
//! - `h1` is subject `viewer`: it holds the domain key but may only publish and read
//!   `status/*`;
//! - `h2` holds the domain key too, but is no subject: it runs with a document it signed itself
//!   that lets it do everything (a host whose administrator went rogue).
//!
//! Neither can read or write `arm/*`: 0 samples either way, while `status/*` flows; each side
//! says why (the refused declaration's error, the consumers' `NotPermitted` notifications on
//! both sides, the daemons' logs), and `ndds nodes` shows who is authenticated as whom. The
//! domain key does not help the third host either: 1000 datagrams it seals with it in arm's
//! name fail their tag at the viewer, which opens arm's data with the pair's data key.
//! Needs root, `ip` and `nft`.

mod support;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use interop_tests::netns::{Cluster, Network};
use interop_tests::{TestDomain, binary};
use support::{WAIT, exclusive, node};

const ARM: usize = 0;
const VIEWER: usize = 1;
const ROGUE: usize = 2;

fn ndds(args: &[&str]) -> String {
    let args: Vec<String> = args.iter().map(|a| (*a).to_owned()).collect();
    let out = interop_tests::process::run(&binary("ndds"), &args, WAIT);
    assert_eq!(out.code, Some(0), "ndds {args:?}: {}", out.stderr);
    out.stdout
}

fn text(path: &Path) -> String {
    path.display().to_string()
}

/// `ndds security id` for an identity file (made by that command).
fn identity(path: &Path) -> String {
    ndds(&["security", "id", "--identity", &text(path)])
        .trim()
        .to_owned()
}

/// An administrator directory with a signed document: `subjects` are (name, identity file,
/// `add` flags).
fn signed_document(dir: &Path, domain: u16, subjects: &[(&str, &Path, &[&str])]) -> PathBuf {
    ndds(&[
        "security",
        "init",
        &text(dir),
        "--domain",
        &domain.to_string(),
    ]);
    let document = dir.join("permissions.toml");
    for (name, id_file, rules) in subjects {
        let key = identity(id_file);
        let mut args = vec!["security", "add", document.to_str().unwrap(), name, &key];
        args.extend_from_slice(rules);
        ndds(&args);
    }
    let admin = dir.join("admin.secret");
    ndds(&[
        "security",
        "sign",
        &text(&document),
        "--admin",
        &text(&admin),
    ]);
    document
}

fn daemon_flags(document: &Path, admin: &Path, identity: &Path) -> Vec<String> {
    vec![
        "--permissions".into(),
        text(document),
        "--admin-key".into(),
        text(admin),
        "--identity".into(),
        text(identity),
    ]
}

#[test]
fn a_host_with_the_key_but_no_permission_for_arm_can_neither_read_nor_write_it() {
    if support::skipped() {
        return;
    }
    let _turn = exclusive();
    let mut domain = TestDomain::sealed();
    let ids: Vec<PathBuf> = (0..3).map(|i| domain.path(&format!("h{i}.id"))).collect();
    let official = signed_document(
        &domain.path("admin"),
        domain.domain,
        &[
            (
                "arm",
                &ids[ARM],
                &[
                    "--publish",
                    "arm/*",
                    "--publish",
                    "status/*",
                    "--subscribe",
                    "*",
                ],
            ),
            (
                "viewer",
                &ids[VIEWER],
                &["--publish", "status/*", "--subscribe", "status/*"],
            ),
        ],
    );
    let rogue = signed_document(
        &domain.path("rogue"),
        domain.domain,
        &[(
            "rogue",
            &ids[ROGUE],
            &["--publish", "*", "--subscribe", "*"],
        )],
    );
    let admin_pub = domain.path("admin").join("admin.pub");
    for host in [ARM, VIEWER] {
        domain.daemon_extra.insert(
            Cluster::daemon_name(host),
            daemon_flags(&official, &admin_pub, &ids[host]),
        );
    }
    domain.daemon_extra.insert(
        Cluster::daemon_name(ROGUE),
        daemon_flags(&rogue, &domain.path("rogue").join("admin.pub"), &ids[ROGUE]),
    );
    let cluster = Cluster::start_in(Network::new(3), domain);

    // What arm publishes and reads.
    let consume = |host, topic: &str| {
        let args = [
            "consume",
            "--topic",
            topic,
            "--count",
            "100000",
            "--timeout",
            "60",
        ];
        node(&cluster, host, &[&args[..], &["--events"]].concat())
    };
    let produce = |host, topic: &str| {
        node(
            &cluster,
            host,
            &["produce", "--topic", topic, "--rate", "100"],
        )
    };
    let _arm_pose = produce(ARM, "arm/pose");
    let _arm_status = produce(ARM, "status/arm");
    let arm_cmd_reader = consume(ARM, "arm/cmd");
    // The viewer reads status (the control: the network and the domain key work), and may
    // not declare arm/* at all: its own daemon refuses, saying why.
    let viewer_status = consume(VIEWER, "status/arm");
    viewer_status
        .event("sample", WAIT)
        .expect("the viewer reads status/arm");
    let wait_for_topic = |host: usize, topic: &str| {
        let deadline = Instant::now() + WAIT;
        while !cluster
            .graph(host)
            .endpoints
            .iter()
            .any(|e| e.info.topic == topic)
        {
            assert!(
                Instant::now() < deadline,
                "host {host} never heard of {topic}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    wait_for_topic(VIEWER, "arm/pose");
    wait_for_topic(VIEWER, "arm/cmd");
    let key = text(cluster.domain().key.as_ref().expect("a sealed domain"));
    let read = cluster.ndds(
        VIEWER,
        &["--key-file", &key, "echo", "arm/pose", "--count", "1"],
        WAIT,
    );
    assert_ne!(
        read.code,
        Some(0),
        "the viewer read arm/pose: {}",
        read.stdout
    );
    assert!(
        read.stderr
            .contains("`viewer` may not subscribe `arm/pose`"),
        "why the viewer may not read: {}",
        read.stderr
    );
    let value = r#"{"seq": 1, "position": [0, 0, 0], "label": "x", "value": 1}"#;
    let write = cluster.ndds(
        VIEWER,
        &[
            "--key-file",
            &key,
            "pub",
            "arm/cmd",
            value,
            "--count",
            "5",
            "--rate",
            "10",
        ],
        WAIT,
    );
    assert_ne!(
        write.code,
        Some(0),
        "the viewer wrote arm/cmd: {}",
        write.stdout
    );
    assert!(
        write.stderr.contains("`viewer` may not publish `arm/cmd`"),
        "why the viewer may not write: {}",
        write.stderr
    );

    // The rogue holds the domain key: it seals 1000 datagrams in the name of arm's
    // participant and sends them to the viewer's consumer of status/arm. They do not open: the
    // viewer opens arm's data with the pair's data key, which only their daemons can derive.
    let arm_participant = cluster
        .graph(ARM)
        .endpoints
        .iter()
        .find(|e| e.info.topic == "status/arm" && e.node == cluster.graph(ARM).local.node)
        .map(|e| e.info.guid.participant)
        .expect("arm's status producer");
    let counted_reader = node(
        &cluster,
        VIEWER,
        &[
            "consume",
            "--topic",
            "status/arm",
            "--count",
            "300",
            "--timeout",
            "30",
        ],
    );
    let viewer_socket = cluster
        .graph(VIEWER)
        .endpoints
        .iter()
        .find(|e| e.info.topic == "status/arm" && e.info.pid == counted_reader.pid())
        .map(|e| std::net::SocketAddrV4::from(e.info.locator))
        .expect("the viewer's counted consumer");
    let keyring = ndds_daemon::keys::load(cluster.domain().key.as_ref().unwrap()).expect("key");
    let domain_id = cluster.domain().domain;
    let forged = 1000;
    let rogue_host = cluster.host(ROGUE);
    let from = rogue_host.ip();
    rogue_host.enter(|| {
        let socket = std::net::UdpSocket::bind((from, 0)).expect("rogue socket");
        let mut sealer = ndds_core::seal::Sealer::new(
            &keyring,
            domain_id,
            arm_participant,
            u64::MAX / 2,
            ndds_core::seal::SealMode::Encrypt,
        );
        for i in 0..forged {
            let mut datagram = Vec::new();
            ndds_core::wire::Header {
                kind: ndds_core::wire::MessageKind::Data,
                domain: domain_id,
                sender: arm_participant,
            }
            .emit(&mut datagram);
            datagram.extend_from_slice(&[i as u8; 64]);
            sealer.seal(&mut datagram).expect("sealed");
            socket.send_to(&datagram, viewer_socket).expect("sent");
            std::thread::sleep(Duration::from_micros(500));
        }
    });
    let done = counted_reader
        .event("done", Duration::from_secs(30))
        .expect("the counted consumer finishes");
    let bad_tag = done["stats"]["seal_dropped"]["bad_tag"]
        .as_u64()
        .unwrap_or(0);
    eprintln!(
        "permissions: {forged} datagrams sealed with the domain key in arm's name: the viewer \
         received {} samples, counted {bad_tag} bad tags",
        done["received"]
    );
    assert_eq!(done["received"], 300);
    assert!(bad_tag >= forged, "{done}");

    // The rogue declares what its own document allows; arm's daemon refuses it.
    let rogue_reader = consume(ROGUE, "arm/pose");
    let _rogue_writer = produce(ROGUE, "arm/cmd");
    let until = Instant::now() + Duration::from_secs(4);
    let rogue_lines = rogue_reader.events_until(until);
    let arm_lines = arm_cmd_reader.events_until(Instant::now() + Duration::from_millis(200));
    let samples =
        |lines: &[serde_json::Value]| lines.iter().filter(|l| l["event"] == "sample").count();
    let not_permitted = |lines: &[serde_json::Value]| {
        lines
            .iter()
            .filter(|l| l["event"] == "notification" && l["kind"] == "NotPermitted")
            .map(|l| l["reason"].as_str().unwrap_or_default().to_owned())
            .collect::<Vec<_>>()
    };
    let (read_by_rogue, written_by_rogue) = (samples(&rogue_lines), samples(&arm_lines));
    let (rogue_told, arm_told) = (not_permitted(&rogue_lines), not_permitted(&arm_lines));
    eprintln!(
        "permissions: rogue read {read_by_rogue} arm/pose samples, arm read {written_by_rogue} \
         of the rogue's arm/cmd samples; the rogue was told {rogue_told:?}; arm was told \
         {arm_told:?}"
    );
    assert_eq!(read_by_rogue, 0, "the rogue read arm/pose");
    assert_eq!(written_by_rogue, 0, "the rogue wrote arm/cmd");
    // Both sides say why: arm's document does not know the rogue's key, and the rogue's
    // document does not know arm's.
    assert!(
        arm_told
            .iter()
            .any(|r| r.contains("is not a subject of permissions document")),
        "{arm_told:?}"
    );
    assert!(
        rogue_told
            .iter()
            .any(|r| r.contains("is not a subject of permissions document")),
        "{rogue_told:?}"
    );
    let arm_log = cluster.daemon(ARM).log_text();
    assert!(
        arm_log.contains("pair refused by the permissions document"),
        "{arm_log}"
    );

    // `ndds nodes` on arm: the viewer authenticated as `viewer`, the rogue authenticated as
    // nobody of the document, its endpoints refused.
    let nodes = cluster.ndds(ARM, &["--key-file", &key, "nodes", "--json"], WAIT);
    let listing: serde_json::Value = serde_json::from_str(&nodes.stdout).expect("nodes --json");
    let by_subject = |subject: Option<&str>| {
        listing["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["local"] == false && n["subject"].as_str() == subject)
            .cloned()
            .unwrap_or_else(|| panic!("no node with subject {subject:?}: {listing}"))
    };
    let viewer = by_subject(Some("viewer"));
    assert_eq!(viewer["authenticated"], true);
    let rogue = by_subject(None);
    assert_eq!(rogue["authenticated"], true);
    assert!(rogue["refused_endpoints"].as_u64().unwrap() >= 2, "{rogue}");
    let shown = cluster
        .ndds(ARM, &["--key-file", &key, "nodes"], WAIT)
        .stdout;
    assert!(shown.contains("subject `viewer`, authenticated"), "{shown}");
    assert!(
        shown.contains("no subject of the document, authenticated, 2 endpoints refused"),
        "{shown}"
    );

    // The administrator admits the third host as `logger` (it may read arm/*, write nothing)
    // and signs a new version; the daemons put it in force without a restart.
    let admin_dir = official.parent().expect("the admin directory").to_owned();
    let rogue_key = identity(&ids[ROGUE]);
    ndds(&[
        "security",
        "add",
        &text(&official),
        "logger",
        &rogue_key,
        "--subscribe",
        "arm/*",
    ]);
    ndds(&[
        "security",
        "sign",
        &text(&official),
        "--admin",
        &text(&admin_dir.join("admin.secret")),
    ]);
    let deadline = Instant::now() + WAIT;
    let logger = loop {
        let nodes = cluster.ndds(ARM, &["--key-file", &key, "nodes", "--json"], WAIT);
        let listing: serde_json::Value = serde_json::from_str(&nodes.stdout).expect("nodes --json");
        let found = listing["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["subject"] == "logger")
            .cloned();
        if let Some(found) = found {
            break found;
        }
        assert!(
            Instant::now() < deadline,
            "the new document never took effect: {listing}"
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(
        logger["refused_endpoints"], 1,
        "only its arm/cmd producer: {logger}"
    );
    let arm_log = cluster.daemon(ARM).log_text();
    assert!(
        arm_log.contains("permissions document changed: the new version is in force"),
        "{arm_log}"
    );
}

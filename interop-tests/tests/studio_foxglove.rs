//! `ndds studio` speaks the Foxglove WebSocket protocol at `/foxglove`: Foxglove's own client
//! (`@foxglove/ws-protocol`'s `FoxgloveClient`, run by Node; `.ci/run` installs it into
//! `target/ci-node` and names it in `NDDS_NODE_MODULES`) connects, finds `arm/endpoint` among
//! the channels with its JSON Schema, subscribes and decodes the arm's samples; bad requests
//! get status messages.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use interop_tests::process::run_command;
use interop_tests::{ClientProcess, TestDomain};

const WAIT: Duration = Duration::from_secs(30);

/// Node and the packages, or a skip (a failure under CI, which installs them).
fn node_modules() -> Option<PathBuf> {
    let modules = std::env::var_os("NDDS_NODE_MODULES").map(PathBuf::from);
    let ready = modules
        .as_ref()
        .is_some_and(|m| m.join("@foxglove/ws-protocol").is_dir() && m.join("ws").is_dir());
    if !ready {
        assert!(
            std::env::var_os("CI").is_none(),
            "NDDS_NODE_MODULES must name node_modules with @foxglove/ws-protocol and ws (.ci/run installs them)"
        );
        eprintln!(
            "skipped: set NDDS_NODE_MODULES to a node_modules holding @foxglove/ws-protocol and ws \
             (npm install --prefix target/ci-node @foxglove/ws-protocol@0.8 ws@8)"
        );
        return None;
    }
    modules
}

fn studio(socket: &Path) -> (ClientProcess, String) {
    let studio = ClientProcess::program("ndds", socket, &["studio", "--port", "0"]);
    let mut foxglove = None;
    for _ in 0..2 {
        if let Some(line) = studio.line(WAIT)
            && let Some(url) = line.strip_prefix("ndds studio: Foxglove at ")
        {
            foxglove = Some(url.to_owned());
        }
    }
    (
        studio,
        foxglove.expect("the studio prints its Foxglove URL"),
    )
}

#[test]
fn foxglove_s_own_client_reads_the_arm_s_endpoint_from_the_studio() {
    let Some(modules) = node_modules() else {
        return;
    };
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let arm = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples/arm.toml");
    let _system = ClientProcess::program(
        "ndds",
        &socket,
        &["run", &arm.display().to_string(), "--plain"],
    );
    let (_studio, url) = studio(&socket);
    assert!(
        url.starts_with("ws://127.0.0.1:") && url.ends_with("/foxglove"),
        "{url}"
    );
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("foxglove/client.js");
    // The arm's topics appear within a few seconds of its start: try until they do.
    let mut last = String::new();
    let deadline = std::time::Instant::now() + WAIT;
    let events: Vec<serde_json::Value> = loop {
        let mut node = Command::new("node");
        node.arg(&script)
            .args([url.as_str(), "arm/endpoint", "10"])
            .env("NODE_PATH", &modules);
        let out = run_command(node, WAIT);
        let events: Vec<serde_json::Value> = out
            .stdout
            .lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect();
        if out.code == Some(0) {
            break events;
        }
        last = format!("{}{}", out.stdout, out.stderr);
        assert!(
            std::time::Instant::now() < deadline,
            "Foxglove's client did not get arm/endpoint: {last}"
        );
        std::thread::sleep(Duration::from_secs(1));
    };
    let _ = last;
    let info = &events[0]["serverInfo"];
    assert!(
        info["name"].as_str().unwrap().starts_with("ndds studio"),
        "{info}"
    );
    assert_eq!(
        info["capabilities"],
        serde_json::json!([]),
        "read-only: no capability"
    );
    let channel = &events[1]["channel"];
    assert_eq!(channel["topic"], "arm/endpoint");
    assert_eq!(channel["encoding"], "json");
    assert_eq!(channel["schemaEncoding"], "jsonschema");
    let schema: serde_json::Value =
        serde_json::from_str(channel["schema"].as_str().unwrap()).expect("a JSON schema");
    assert_eq!(schema["type"], "object", "{schema}");
    let messages: Vec<&serde_json::Value> =
        events.iter().filter_map(|e| e.get("message")).collect();
    assert_eq!(messages.len(), 10, "{events:?}");
    for m in &messages {
        // The arm's tip: a 2x1 CSMat of positions in metres, near (0.9, 1.3).
        assert_eq!(m["rows"], 2, "{m}");
        assert_eq!(m["cols"], 1, "{m}");
        let data = m["data"].as_array().unwrap();
        let x = data[0].as_f64().unwrap();
        let y = data[1].as_f64().unwrap();
        assert!(
            x.abs() < 2.5 && y.abs() < 2.5 && (x * x + y * y).sqrt() > 0.1,
            "{m}"
        );
    }
    let statuses = events
        .iter()
        .find_map(|e| e.get("statuses"))
        .expect("status answers to the bad requests");
    let said: Vec<&str> = statuses
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["message"].as_str().unwrap())
        .collect();
    assert!(said[0].contains("no channel 999999"), "{said:?}");
    assert!(
        said[1].contains("`setParameters` is not supported"),
        "{said:?}"
    );
    assert!(said[2].starts_with("not JSON"), "{said:?}");
}

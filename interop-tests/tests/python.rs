//! The Python package (`ndds-python`): built into the test environment's Python and checked by
//! its own pytest suites (`ndds-python/tests`): pub/sub between Python processes, Python and
//! the Rust `pose_peer` both ways, untyped dicts, CSMats, ports both ways, reliable delivery
//! and deadlines, asyncio, systems loaded and switched from Python, the user guide's Python
//! examples, and the error cases. Every peer is a real process on a real `ndds-daemon` on
//! loopback.
//!
//! The interpreter is `NDDS_PYTHON` (`.ci/run` makes a virtual environment with maturin,
//! pytest and NumPy), else `python3`; without those packages the test skips and says how to
//! set them up, except under CI, where it fails.

use std::path::{Path, PathBuf};
use std::process::Command;

use interop_tests::{binary, python};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace root")
        .to_path_buf()
}

/// Runs `command`, failing the test with its output unless it succeeds; returns stdout.
fn run(what: &str, command: &mut Command) -> String {
    let out = command
        .output()
        .unwrap_or_else(|err| panic!("cannot run {what}: {err}"));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

#[test]
fn the_python_suites_pass() {
    let Some(python) = python::with_modules("python", &["maturin", "pytest", "numpy"]) else {
        return;
    };
    // The package, built from this checkout into that interpreter's environment (a debug
    // build in the workspace's target directory, as every other test uses).
    let venv = python
        .parent()
        .and_then(Path::parent)
        .map(Path::to_path_buf)
        .expect("the interpreter lives in <environment>/bin");
    run(
        "maturin develop (ndds-python)",
        Command::new(&python)
            .args(["-m", "maturin", "develop", "--locked", "--manifest-path"])
            .arg(root().join("ndds-python/Cargo.toml"))
            .env("VIRTUAL_ENV", &venv)
            .current_dir(root()),
    );
    let out = run(
        "pytest ndds-python/tests",
        Command::new(&python)
            .args([
                "-m",
                "pytest",
                "-q",
                "-p",
                "no:cacheprovider",
                "ndds-python/tests",
            ])
            .env("NDDS_DAEMON", binary("ndds-daemon"))
            .env("NDDS_POSE_PEER", env!("CARGO_BIN_EXE_pose_peer"))
            // The suite's daemons and peers name their own domains and sockets.
            .env_remove("NDDS_DOMAIN")
            .env_remove("NDDS_SOCKET")
            .current_dir(root()),
    );
    println!("{out}");
    // pytest's summary line: every test passed, none skipped (a skip would hide a gap).
    let summary = out.lines().last().unwrap_or_default();
    assert!(
        summary.contains(" passed") && !summary.contains("failed") && !summary.contains("skipped"),
        "pytest: {summary}"
    );
}

//! Python for tests that read our files with readers we did not write (the `mcap` package,
//! `jsonschema`).
//!
//! The interpreter is `NDDS_PYTHON` when set (`.ci/run` makes a virtual environment with the
//! packages and sets it), else `python3`. Where it is missing, or lacks a package, a test
//! skips with a message saying how to set it up; under CI (`CI=true`) or with
//! `NDDS_REQUIRE_PYTHON=1` it fails instead, so CI never skips these checks.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The interpreter with `modules` importable, or `None` after printing why the caller skips.
pub fn with_modules(test: &str, modules: &[&str]) -> Option<PathBuf> {
    let python =
        std::env::var_os("NDDS_PYTHON").map_or_else(|| PathBuf::from("python3"), PathBuf::from);
    let import = format!("import {}", modules.join(", "));
    let found = Command::new(&python)
        .args(["-c", &import])
        .output()
        .is_ok_and(|out| out.status.success());
    if found {
        return Some(python);
    }
    let why = format!(
        "{test}: skipped: `{}` cannot `{import}`; set up with `python3 -m venv /tmp/ndds-py && \
         /tmp/ndds-py/bin/pip install {}` and run with NDDS_PYTHON=/tmp/ndds-py/bin/python",
        python.display(),
        modules.join(" ")
    );
    let required = std::env::var("CI").is_ok_and(|v| v == "true")
        || std::env::var("NDDS_REQUIRE_PYTHON").is_ok_and(|v| v == "1");
    assert!(!required, "{why} (required under CI)");
    eprintln!("{why}");
    None
}

/// Runs `script` (a path under this crate's `scripts/`) with `args`; returns its stdout,
/// failing the test with its stderr if it fails.
pub fn run(python: &Path, script: &str, args: &[&str]) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scripts")
        .join(script);
    let out = Command::new(python)
        .arg(&path)
        .args(args)
        .output()
        .unwrap_or_else(|err| panic!("cannot run {}: {err}", python.display()));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{script} failed: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

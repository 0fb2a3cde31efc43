//! `ndds new` as a user uses it: a component crate is made, its known-answer test passes as
//! generated, its program runs its description file with every `ndds run` flag, and the plain
//! `ndds run` refuses that file saying why and what to do. A new system runs with `ndds run`.
//!
//! The crate is built with cargo (offline: the checkout's lock file is copied in, so every
//! dependency is in the local registry already) into `target/scaffold`, a target directory of
//! its own: its profile is not the workspace's, so nothing could be shared anyway, and a
//! build of its own never waits for the workspace's lock.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use interop_tests::binary;
use interop_tests::process::{Output, run_command};

fn checkout() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .canonicalize()
        .unwrap()
}

fn text(out: &Output) -> String {
    format!(
        "status {:?}\n--- stdout\n{}\n--- stderr\n{}",
        out.code, out.stdout, out.stderr
    )
}

/// The outcome of an `ndds` command (short: a minute at most).
fn ndds(args: &[&str], dir: &Path) -> Output {
    let mut command = Command::new(binary("ndds"));
    command.args(args).current_dir(dir);
    run_command(command, Duration::from_secs(60))
}

fn ok(out: &Output) -> bool {
    out.code == Some(0)
}

fn cargo(dir: &Path, args: &[&str]) -> Output {
    let mut command = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    command
        .current_dir(dir)
        .arg("--offline")
        .args(args)
        .env("CARGO_TARGET_DIR", checkout().join("target/scaffold"))
        // The workspace's test run sets these for its own crates, not this one.
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_MANIFEST_DIR");
    // A first build compiles every dependency: generous, for two cores.
    run_command(command, Duration::from_secs(1500))
}

#[test]
fn a_new_component_crate_builds_tests_and_runs_its_system() {
    let dir = tempfile::tempdir().unwrap();
    let made = dir.path().join("lead_lag");
    let made_str = made.to_str().unwrap();
    let out = ndds(&["new", "component", "lead_lag"], dir.path());
    assert!(ok(&out), "{}", text(&out));
    for file in [
        "Cargo.toml",
        "Cargo.lock",
        "src/lib.rs",
        "src/main.rs",
        "system.toml",
        "README.md",
    ] {
        assert!(made.join(file).is_file(), "{file} not made");
    }
    let again = ndds(
        &["new", "component", "lead_lag", "--dir", made_str],
        dir.path(),
    );
    assert!(!ok(&again));
    assert!(text(&again).contains("exists already"), "{}", text(&again));

    // The known-answer test passes as generated.
    let test = cargo(&made, &["test"]);
    assert!(ok(&test), "{}", text(&test));
    assert!(
        text(&test).contains("a_step_approaches_its_value_by_the_known_factor ... ok"),
        "{}",
        text(&test)
    );

    // Its program is `ndds run` with the component: --check and --simulate.
    let check = cargo(&made, &["run", "--quiet", "--", "system.toml", "--check"]);
    assert!(ok(&check), "{}", text(&check));
    assert!(
        text(&check).contains("verified, nothing started"),
        "{}",
        text(&check)
    );
    let simulate = cargo(
        &made,
        &["run", "--quiet", "--", "system.toml", "--simulate", "2"],
    );
    assert!(ok(&simulate), "{}", text(&simulate));
    let out = text(&simulate);
    assert!(out.contains("simulated 2.0 s"), "{out}");
    assert!(out.contains("; 0 module errors)"), "{out}");
    assert!(
        out.contains("smooth"),
        "the filtered CSMat is displayed: {out}"
    );
    // A flag of its own is refused as `ndds run` refuses it, under the program's name.
    let bad = cargo(
        &made,
        &["run", "--quiet", "--", "system.toml", "--simulate", "soon"],
    );
    assert!(!ok(&bad));
    assert!(text(&bad).contains("--simulate"), "{}", text(&bad));

    // The plain `ndds run` does not know the type, and says what to do.
    let plain = ndds(&["run", "--check", "lead_lag/system.toml"], dir.path());
    assert!(!ok(&plain));
    let err = text(&plain);
    assert!(err.contains("unknown component type `lead_lag`"), "{err}");
    assert!(
        err.contains("known only to the program that registers it"),
        "{err}"
    );
    assert!(err.contains("cargo run -- "), "{err}");
}

#[test]
fn a_new_system_runs_with_ndds_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = ndds(&["new", "system", "plant"], dir.path());
    assert!(ok(&out), "{}", text(&out));
    let run = ndds(&["run", "--simulate", "2", "plant/system.toml"], dir.path());
    let out = text(&run);
    assert!(ok(&run), "{out}");
    assert!(out.contains("; 0 module errors)"), "{out}");
    let bad = ndds(&["new", "system", "Plant"], dir.path());
    assert!(!ok(&bad));
    assert!(text(&bad).contains("lowercase letters"), "{}", text(&bad));
}

//! `ndds shell` on a real system: `ndds run examples/arm.toml` (the PD/LQG arm, two habitats,
//! two configurations, a state machine and a port declared in the file) on a test daemon on
//! loopback, and `ndds shell` against it: scripted with `-c` and `--script` (output, errors
//! naming what exists, exit status), and interactively on a pseudo-terminal (TAB completion,
//! history with the Up arrow, errors, `watch` stopped by a key, Ctrl-D).

mod common;

use std::io::{Read as _, Write as _};
use std::os::fd::OwnedFd;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::{Run, Running, World};

/// The example system: habitats `control` (200 Hz) and `plant` (500 Hz), configurations
/// `JointPD` and `endptLQG`, machine `arm`, port `arm-configure`.
const ARM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/arm.toml");

/// Starts the arm on `world`'s daemon and waits until `ndds shell` reaches it and both its
/// habitats sample (its command port answers before they start).
fn start_arm(world: &World) -> Running {
    let mut system = world.spawn(&["run", ARM, "--plain", "--seconds", "120"]);
    let deadline = Instant::now() + common::SETTLE;
    loop {
        let run = world.ndds(&["shell", "-c", "ls habitats"]);
        if run.success() && run.stdout.matches(" Hz  running ").count() == 2 {
            return system;
        }
        assert!(system.is_running(), "ndds run ended early");
        assert!(
            Instant::now() < deadline,
            "the system never answered: {run}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn shell(world: &World, commands: &str) -> Run {
    world.ndds(&["shell", "-c", commands])
}

/// The line of `text` that starts with `first` (after blanks).
fn line_of<'a>(text: &'a str, first: &str) -> &'a str {
    text.lines()
        .find(|l| l.split_whitespace().next() == Some(first))
        .unwrap_or_else(|| panic!("no line starting with {first:?} in\n{text}"))
}

#[test]
fn scripted_commands_list_show_set_switch_change_rates_send_and_query() {
    let world = World::start();
    let _system = start_arm(&world);

    let ls = shell(&world, "ls");
    let out = ls.ok();
    for expected in [
        "habitats (2)",
        "control  200 Hz  running",
        "configurations (2)",
        "JointPD",
        "endptLQG",
        "machines (1)",
        "arm  stimuli: Coarse (transient), Precise (transient), Settled (transient)",
        "arm-configure  takes text: query arm-configure TEXT",
        "joint_goal     2x1  settable",
    ] {
        assert!(out.contains(expected), "{expected:?} missing: {ls}");
    }

    // show: the fields and units of the description; set, then show the new values.
    let run = shell(
        &world,
        "show joint_goal; set joint_goal 0.4 0.9; show joint_goal",
    );
    let out = run.ok();
    assert!(out.contains("joint_goal  (2 x 1)"), "{run}");
    assert!(out.contains("q1 [rad]  0.5\nq2 [rad]    1\n"), "{run}");
    assert!(
        out.contains("system `arm`: CSMat `joint_goal` set to [0.4, 0.9]"),
        "{run}"
    );
    assert!(out.contains("q1 [rad]  0.4\nq2 [rad]  0.9\n"), "{run}");

    // switch (the supervisor only ever switches to endptLQG by itself, so it stays).
    let run = shell(&world, "switch endptLQG; ls configurations");
    let out = run.ok();
    assert!(
        out.contains("configuration `endptLQG`"),
        "the system's answer is printed: {run}"
    );
    assert!(out.contains("endptLQG  (active)"), "{run}");

    // A misspelt configuration: the close one and every one, exit status 1.
    let run = shell(&world, "switch endptlqg");
    let err = run.err();
    assert!(
        err.starts_with(
            "ndds: system `arm` has no configuration `endptlqg` (did you mean `endptLQG`?); \
             configurations: JointPD, endptLQG"
        ),
        "{run}"
    );

    // A habitat's rate, seen in the statistics; the achieved rate follows it.
    let run = shell(&world, "habitat control rate 100; stats");
    let out = run.ok();
    assert!(
        out.contains("habitat `control` of system `arm`: rate 200 Hz -> 100 Hz"),
        "{run}"
    );
    let control: Vec<&str> = line_of(out, "control").split_whitespace().collect();
    assert_eq!(control[1..3], ["running", "100"], "{run}");
    let achieved: f64 = control[3].parse().unwrap();
    assert!((60.0..140.0).contains(&achieved), "{run}");
    assert_eq!(line_of(out, "plant").split_whitespace().nth(2), Some("500"));

    // send to the machine: Coarse holds joint control (JointPD) from any state.
    let run = shell(&world, "send arm Coarse; ls configurations");
    let out = run.ok();
    assert!(out.contains("arm: Coarse: "), "{run}");
    assert!(out.contains("-> Held (switch JointPD"), "{run}");
    assert!(out.contains("JointPD   (active)"), "{run}");

    // query the port the description declares: the request is text.
    let run = shell(&world, "query arm-configure endptLQG; ls configurations");
    let out = run.ok();
    assert!(
        out.contains("system `arm` switched to configuration `endptLQG`"),
        "{run}"
    );
    assert!(out.contains("endptLQG  (active)"), "{run}");
}

#[test]
fn errors_stop_a_script_unless_it_keeps_going_and_name_what_exists() {
    let world = World::start();
    let _system = start_arm(&world);

    // The first failing command ends it: `ls` after it does not run.
    let run = shell(&world, "show nothing; ls habitats");
    let err = run.err();
    assert!(
        err.starts_with("ndds: system `arm` has no CSMat `nothing`; CSMats: angles, command,"),
        "{run}"
    );
    assert!(!run.stdout.contains("habitats"), "{run}");

    // --keep-going: every error said, every other command run, and still status 1.
    let run = world.ndds(&[
        "shell",
        "--keep-going",
        "-c",
        "shw joint_goal; send arm Precice; reset plnt; set tip 1 2; ls machines",
    ]);
    let err = run.err();
    for expected in [
        "ndds: unknown command `shw` (did you mean `show` or `set`?); commands: ls, show,",
        "ndds: state machine `arm` has no stimulus `Precice` (did you mean `Precise`?); \
         stimuli: Coarse, Precise, Settled",
        "ndds: system `arm` has no habitat `plnt` (did you mean `plant`?); habitats: control, \
         plant",
        "ndds: CSMat `tip` is written by module `subscribe:arm/endpoint` every sample; only \
         parameters and reference inputs (CSMats no module writes) can be set: endpoint_goal, \
         joint_goal,",
        "ndds: 4 of 5 commands failed",
    ] {
        assert!(err.contains(expected), "{expected:?} missing: {run}");
    }
    assert!(run.stdout.contains("machines (1)"), "{run}");

    // A script: comments, one command a line; its error names the file and line.
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("operator.ndds");
    std::fs::write(
        &script,
        "# set the goal and look\nset joint_goal 0.3 0.8  # rad\nset joint_goal 0.3\nstats\n",
    )
    .unwrap();
    let path = script.display().to_string();
    let run = world.ndds(&["shell", "--script", &path]);
    let err = run.err();
    assert!(
        err.starts_with(&format!(
            "ndds: {path}:3: CSMat `joint_goal` is 2x1: give 2 values, row-major; 1 given"
        )),
        "{run}"
    );
    assert!(run.stdout.contains("set to [0.3, 0.8]"), "{run}");
    assert!(
        !run.stdout.contains("achieved"),
        "stopped before stats: {run}"
    );

    // watch, not on a terminal: a few snapshots, a second apart.
    let run = shell(&world, "watch joint_goal 1.5");
    let out = run.ok();
    assert_eq!(out.matches("joint_goal  (2 x 1)").count(), 2, "{run}");
    assert!(
        out.contains("t = 0.0 s") && out.contains("t = 1.0 s"),
        "{run}"
    );

    // help: every command, each documented in docs/cli.md's table.
    let run = shell(&world, "help; help set");
    let out = run.ok();
    let usages: Vec<&str> = out
        .lines()
        .skip_while(|l| *l != "commands:")
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .map(|l| l.split("  ").find(|part| !part.is_empty()).unwrap())
        .collect();
    assert!(usages.len() >= 12, "{run}");
    let docs =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/cli.md")).unwrap();
    for usage in &usages {
        let name = usage.split_whitespace().next().unwrap();
        assert!(
            docs.contains(&format!("| `{name}")),
            "docs/cli.md's `ndds shell` table lacks `{name}`"
        );
    }
    assert!(
        out.contains("usage: set MAT V1 V2 ...\nset a parameter or reference input"),
        "{run}"
    );

    // A system that is not there.
    let run = world.ndds(&["shell", "--system", "amr", "-c", "ls"]);
    assert!(
        run.err()
            .contains("no system `amr` runs in this domain (did you mean `arm`?); running: arm"),
        "{run}"
    );
    // Commands from a pipe (here: none) run as a script does.
    assert!(world.ndds(&["shell"]).ok().is_empty());
}

/// What the shell wrote to its terminal so far, read on a thread of its own.
struct Screen {
    text: Arc<Mutex<String>>,
}

impl Screen {
    fn read_from(master: OwnedFd) -> Self {
        let text = Arc::new(Mutex::new(String::new()));
        let shared = Arc::clone(&text);
        std::thread::spawn(move || {
            let mut master = std::fs::File::from(master);
            let mut buffer = [0u8; 4096];
            // Ends with EIO once the shell and every copy of the terminal's side closed.
            while let Ok(n @ 1..) = master.read(&mut buffer) {
                let mut text = shared.lock().unwrap();
                text.push_str(&String::from_utf8_lossy(&buffer[..n]));
            }
        });
        Screen { text }
    }

    fn all(&self) -> String {
        self.text.lock().unwrap().clone()
    }

    /// Waits until `what` appears after byte `from`; returns where it ends.
    fn wait_for(&self, what: &str, from: usize) -> usize {
        let deadline = Instant::now() + common::RUN_LIMIT;
        loop {
            let text = self.all();
            if let Some(at) = text.get(from..).and_then(|rest| rest.find(what)) {
                return from + at + what.len();
            }
            assert!(
                Instant::now() < deadline,
                "no {what:?} on the terminal after byte {from}: {:?}",
                text.get(from..).unwrap_or("")
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// `ndds shell` on a new pseudo-terminal (its standard input, output and error), with its
/// history under `state`. Returns the process, its screen and its keyboard.
fn shell_on_terminal(socket: &Path, state: &Path) -> (Child, Screen, std::fs::File) {
    let size = nix::pty::Winsize {
        ws_row: 40,
        ws_col: 160,
        ws_xpixel: 0,
        ws_ypixel: 0,
    };
    let pty = nix::pty::openpty(Some(&size), None).expect("a pseudo-terminal");
    let terminal = pty.slave;
    let child = Command::new(env!("CARGO_BIN_EXE_ndds"))
        .arg("--socket")
        .arg(socket)
        .arg("shell")
        .env("TERM", "xterm")
        .env("XDG_STATE_HOME", state)
        .env_remove("NDDS_DOMAIN")
        .env_remove("NDDS_SOCKET")
        .env_remove("RUST_LOG")
        .stdin(Stdio::from(terminal.try_clone().unwrap()))
        .stdout(Stdio::from(terminal.try_clone().unwrap()))
        .stderr(Stdio::from(terminal))
        .spawn()
        .expect("start ndds shell");
    let keys = std::fs::File::from(pty.master.try_clone().unwrap());
    (child, Screen::read_from(pty.master), keys)
}

#[test]
fn on_a_terminal_tab_completes_up_recalls_and_errors_do_not_end_the_shell() {
    let world = World::start();
    let _system = start_arm(&world);
    let state = tempfile::tempdir().unwrap();
    let (mut child, screen, mut keys) = shell_on_terminal(world.socket(), state.path());
    let mut press = |text: &str| {
        keys.write_all(text.as_bytes()).unwrap();
        keys.flush().unwrap();
        // One key sequence at a time, as typed: the editor reads escape sequences whole.
        std::thread::sleep(Duration::from_millis(150));
    };
    let mut at = screen.wait_for("ndds shell on system `arm` (habitats: control, plant)", 0);
    at = screen.wait_for("arm> ", at);

    // TAB completes the command and the CSMat: only a completed `joint_goal` shows a table.
    press("sho\t");
    press("joint_g\t");
    press("\r");
    at = screen.wait_for("joint_goal  (2 x 1)", at);
    at = screen.wait_for("q1 [rad]", at);
    at = screen.wait_for("arm> ", at);

    // Two TABs list what fits.
    press("switch \t");
    press("\t");
    at = screen.wait_for("JointPD", at);
    at = screen.wait_for("endptLQG", at);
    press("\x15"); // Ctrl-U: the line is cleared.

    // An error is said, and the shell goes on.
    press("switch endptlqg\r");
    at = screen.wait_for(
        "ndds: system `arm` has no configuration `endptlqg` (did you mean `endptLQG`?); \
         configurations: JointPD, endptLQG",
        at,
    );
    at = screen.wait_for("arm> ", at);

    // Up recalls the last line; Up again the one before (the completed `show`).
    press("\x1b[A");
    press("\x1b[A");
    press("\r");
    at = screen.wait_for("joint_goal  (2 x 1)", at);
    at = screen.wait_for("arm> ", at);
    // Up recalls the misspelt switch (two lines back now), mended before Enter.
    press("\x1b[A");
    press("\x1b[A");
    press("\x7f\x7f\x7fLQG\r");
    at = screen.wait_for("configuration `endptLQG`", at);
    at = screen.wait_for("arm> ", at);

    // watch redraws in place until a key.
    press("watch tip\r");
    at = screen.wait_for("Enter, q or Ctrl-C stops", at);
    std::thread::sleep(Duration::from_millis(1000));
    press("q");
    at = screen.wait_for("arm> ", at);
    let drawn = screen.all();
    assert!(
        drawn.matches("tip  (2 x 1)").count() >= 3,
        "redrawn about 5 times a second: {drawn:?}"
    );

    // Ctrl-D leaves.
    press("\x04");
    let deadline = Instant::now() + common::RUN_LIMIT;
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("Ctrl-D did not end the shell: {:?}", &screen.all()[at..]);
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "{status}");
    // The history is kept for the next session.
    let history = std::fs::read_to_string(state.path().join("ndds/shell_history")).unwrap();
    assert!(history.contains("switch endptlqg"), "{history}");
    assert!(history.contains("show joint_goal"), "{history}");
}

/// `ndds habitat`: each action's answer, a refusal naming the habitats, and the new rate in
/// the habitat's *published* statistics (`cs/arm/control/stats`, as `ndds echo` reads them).
#[test]
fn ndds_habitat_changes_a_rate_seen_in_the_published_statistics() {
    let world = World::start();
    let _system = start_arm(&world);
    let published_rate = || -> Option<f64> {
        let run = world.ndds(&[
            "echo",
            "cs/arm/control/stats",
            "--field",
            "rate_hz",
            "--count",
            "1",
            "--wait",
            "5",
        ]);
        run.success()
            .then(|| run.stdout.trim().parse().ok())
            .flatten()
    };
    assert_eq!(published_rate(), Some(200.0));

    let run = world.ndds(&["habitat", "control", "rate", "50"]);
    assert!(
        run.ok()
            .contains("habitat `control` of system `arm`: rate 200 Hz -> 50 Hz"),
        "{run}"
    );
    // Statistics are published once a second: the new rate is in one of the next ones.
    assert!(
        common::eventually(common::SETTLE, || published_rate() == Some(50.0)),
        "the published statistics never said 50 Hz"
    );

    let run = world.ndds(&["habitat", "control", "reset"]);
    assert!(run.ok().contains("reset at its next sample"), "{run}");
    let run = world.ndds(&["habitat", "plant", "stop"]);
    assert!(
        run.ok().contains("habitat `plant` of system `arm` stopped"),
        "{run}"
    );
    let run = world.ndds(&["habitat", "plant", "start", "--system", "arm"]);
    assert!(
        run.ok().contains("habitat `plant` of system `arm` started"),
        "{run}"
    );

    let run = world.ndds(&["habitat", "contrl", "rate", "100"]);
    assert!(
        run.err().contains(
            "system `arm` has no habitat `contrl` (did you mean `control`?); habitats: control, \
             plant"
        ),
        "{run}"
    );
    let run = world.ndds(&["habitat", "control", "rate", "0"]);
    assert!(run.err().contains("0 Hz is not a usable rate"), "{run}");
    let run = world.ndds(&["habitat", "control", "rate", "100", "--system", "arn"]);
    assert!(
        run.err().contains("no system `arn` runs in this domain"),
        "{run}"
    );
}

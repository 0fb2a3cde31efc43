//! `ndds run`'s status never hides a message: a real `ndds run` process on a test daemon,
//! whose subscribed input nobody publishes, gets a wrong-shaped sample from the test (its
//! habitat thread logs a warning while the status is live). Piped (plain), the status lists
//! the input as never received and stderr keeps the warning; on a pseudo-terminal (`script`),
//! the bytes replayed through a small terminal model leave the warning on screen above the
//! last status block.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use common::{Running, World};
use ndds_client::ProducerQos;
use ndds_runtime::CsMat;

/// What the habitat thread logs for the wrong-shaped sample.
const WARNING: &str = "is 3x1; CSMat `";

/// A 100 Hz controller subscribing `topic`, written to `dir`.
fn description(dir: &Path, topic: &str) -> String {
    let path = dir.join("status.toml");
    let text = format!(
        r#"
[system]
name = "status{}"

[[habitat]]
name = "control"
rate = 100.0

[[subscribe]]
mat = "angles"
topic = "{topic}"
habitat = "control"
shape = [2, 1]

[[component]]
name = "double"
type = "gain"
habitat = "control"
input = "angles"
output = "command"
k = 2.0
"#,
        fastrand::u32(..)
    );
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

/// Once the running system subscribes `topic`, sends it a few 3x1 samples for its 2x1 CSMat.
fn send_wrong_shape(world: &World, topic: &str, run: &mut Running) {
    let participant = world.participant("status-test");
    let producer = participant
        .producer::<CsMat>(topic, ProducerQos::default())
        .unwrap();
    assert!(
        producer.wait_for_consumers(1, common::SETTLE),
        "ndds run never subscribed {topic}"
    );
    // A few status reports first: the warning comes while the status is live.
    std::thread::sleep(Duration::from_millis(1200));
    let wrong = CsMat::from_row_slice("angles", 3, 1, &[1.0, 2.0, 3.0]).unwrap();
    for _ in 0..5 {
        producer.write(&wrong).unwrap();
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(run.is_running(), "ndds run ended early");
}

#[test]
fn the_status_lists_a_never_received_input_and_the_warning_stays() {
    let world = World::start();
    let dir = tempfile::tempdir().unwrap();
    let topic = format!("run-status/{}/angles", fastrand::u64(..));
    let file = description(dir.path(), &topic);
    let mut run = world.spawn(&["run", &file, "--seconds", "5", "--interval", "0.3"]);
    send_wrong_shape(&world, &topic, &mut run);
    let run = run.finish(common::RUN_LIMIT);
    let out = run.ok();
    let never = format!("input {topic} -> angles: never received (waited ");
    assert!(out.contains(&never), "{run}");
    // The status goes on after the warning, and counts what it refused.
    assert!(
        out.contains("samples refused (undecodable or of another shape)"),
        "{run}"
    );
    assert!(run.stderr.contains(WARNING), "{run}");
    // Nominal and achieved rate side by side.
    assert!(out.contains("rate Hz  achieved"), "{run}");
    let control = out
        .lines()
        .rfind(|l| l.trim_start().starts_with("control "))
        .expect("a habitat line");
    let achieved: f64 = control.split_whitespace().nth(2).unwrap().parse().unwrap();
    assert!(achieved > 10.0 && achieved < 200.0, "{control}");
}

#[test]
fn on_a_terminal_the_warning_stays_above_the_redrawn_status() {
    if Command::new("script").arg("--version").output().is_err() {
        eprintln!("skipped: `script` (util-linux) is not installed; it gives ndds run a pty");
        return;
    }
    let world = World::start();
    let dir = tempfile::tempdir().unwrap();
    let topic = format!("run-status/{}/angles", fastrand::u64(..));
    let file = description(dir.path(), &topic);
    let ndds = format!(
        "{} --socket {} run {file} --seconds 5 --interval 0.3",
        env!("CARGO_BIN_EXE_ndds"),
        world.socket().display()
    );
    let mut command = Command::new("script");
    command
        .args(["-q", "-e", "-f", "-c", &ndds, "/dev/null"])
        .env_remove("RUST_LOG")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut run = Running::from_command(command, &format!("script -c '{ndds}'"));
    send_wrong_shape(&world, &topic, &mut run);
    let run = run.finish(common::RUN_LIMIT);
    assert!(run.success(), "{run}");
    let raw = &run.stdout;
    assert!(raw.contains("\x1b[?7l"), "not drawn in place: {raw:?}");
    assert!(raw.contains(WARNING), "{raw:?}");
    let screen = Screen::replay(raw);
    let text = screen.lines.join("\n");
    let warning = screen
        .lines
        .iter()
        .position(|l| l.contains(WARNING))
        .unwrap_or_else(|| panic!("the warning was erased; screen:\n{text}\nraw: {raw:?}"));
    let last_block = screen
        .lines
        .iter()
        .rposition(|l| l.contains(" habitat ") && l.contains("achieved"))
        .unwrap_or_else(|| panic!("no status on screen:\n{text}"));
    assert!(
        warning < last_block,
        "the warning is not above the status:\n{text}"
    );
    // One status block on screen, not stray copies of earlier ones.
    let blocks = screen
        .lines
        .iter()
        .filter(|l| l.contains("achieved"))
        .count();
    assert_eq!(blocks, 1, "stray status lines:\n{text}");
    assert!(text.contains("ndds run: stopped"), "{text}");
}

/// Just enough of a terminal to replay `ndds run`'s output: text and newlines, cursor up
/// (`CSI n A`), erase below (`CSI J`); other control sequences (colours, auto-wrap) change
/// nothing on screen. Lines never wrap (the block is drawn with auto-wrap off).
struct Screen {
    lines: Vec<String>,
    row: usize,
}

impl Screen {
    fn replay(raw: &str) -> Self {
        let mut screen = Screen {
            lines: vec![String::new()],
            row: 0,
        };
        let mut chars = raw.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '\x1b' if chars.peek() == Some(&'[') => {
                    chars.next();
                    let mut params = String::new();
                    while let Some(&p) = chars.peek() {
                        if p.is_ascii_digit() || p == ';' || p == '?' {
                            params.push(p);
                            chars.next();
                        } else {
                            break;
                        }
                    }
                    match chars.next() {
                        Some('A') => {
                            let n: usize = params.parse().unwrap_or(1);
                            screen.row = screen.row.saturating_sub(n);
                        }
                        Some('J') => {
                            screen.lines.truncate(screen.row + 1);
                            screen.lines[screen.row].clear();
                        }
                        _ => {}
                    }
                }
                '\n' => {
                    screen.row += 1;
                    if screen.lines.len() <= screen.row {
                        screen.lines.push(String::new());
                    }
                }
                '\r' => {}
                c => screen.lines[screen.row].push(c),
            }
        }
        screen
    }
}

/// The model itself: a block redrawn in place replaces the old one; lines above stay.
#[test]
fn the_terminal_model_erases_only_what_the_cursor_went_up_over() {
    let screen = Screen::replay("one\nb1\nb2\n\x1b[2A\x1b[Jwarn\nB1\nB2\n");
    assert_eq!(screen.lines, ["one", "warn", "B1", "B2", ""]);
}

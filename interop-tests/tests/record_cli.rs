//! `ndds record`, `ndds play` and `ndds bag` as a user runs them, through a real daemon: a
//! recorder killed with -9 leaves a file read up to its last chunk; split files; play's loop,
//! remap, start, duration and rate; bag filter and cut; a disk that fills (a small tmpfs,
//! as root) stops the recording with the file closed properly.

use std::path::Path;
use std::time::{Duration, Instant};

use interop_tests::{ClientProcess, TestDomain, participant};
use ndds_client::{ConsumerQos, ProducerQos};

const WAIT: Duration = Duration::from_secs(20);

fn json(text: &str) -> serde_json::Value {
    serde_json::from_str(text.trim()).unwrap_or_else(|e| panic!("{e}: {text}"))
}

/// Writes `count` u64 samples (0, 1, ...) on `topic` at `hz`, once the recorder took it.
fn publish(socket: &Path, topic: &str, count: u64, hz: f64, payload: usize) {
    let source = participant(socket, "source");
    let producer = source
        .producer::<(u64, serde_bytes::ByteBuf)>(topic, ProducerQos::default())
        .unwrap();
    assert!(
        producer.wait_for_consumers(1, WAIT),
        "the recorder took {topic}"
    );
    std::thread::sleep(Duration::from_millis(200));
    let started = Instant::now();
    // Random bytes, new in each sample: compression cannot shrink them (the split test counts
    // on the size).
    let mut rng = fastrand::Rng::with_seed(7);
    for i in 0..count {
        let blob = serde_bytes::ByteBuf::from((0..payload).map(|_| rng.u8(..)).collect::<Vec<_>>());
        let due = started + Duration::from_secs_f64(i as f64 / hz);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        producer.write(&(i, blob)).unwrap();
    }
    std::thread::sleep(Duration::from_millis(300));
}

#[test]
fn a_recorder_killed_with_sigkill_leaves_a_file_read_up_to_its_last_chunk() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let bag = domain.path("killed.mcap").display().to_string();
    let mut recorder = ClientProcess::program(
        "ndds",
        &socket,
        &["record", "data", "-o", &bag, "--chunk-size", "64K"],
    );
    publish(&socket, "data", 500, 500.0, 1000);
    recorder.kill9();
    let out = domain.ndds("a", &["bag", "info", "--json", &bag], WAIT);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    let info = &json(&out.stdout)[0];
    println!("killed recorder: {info}");
    assert_eq!(info["state"], "truncated", "{info}");
    assert_eq!(info["finished"], false);
    let messages = info["messages"].as_u64().unwrap();
    // Everything but the last chunk (64 KiB of ~1 KiB samples) is there.
    assert!((500 - 70..500).contains(&messages), "{messages}");
    let text = domain.ndds("a", &["bag", "info", &bag], WAIT).stdout;
    assert!(
        text.contains("truncated") && text.contains("unknown"),
        "{text}"
    );
    // And it plays what it holds.
    let play = domain.ndds(
        "a",
        &["play", &bag, "--delay", "0", "--rate", "10", "--json"],
        WAIT,
    );
    assert_eq!(play.code, Some(0), "{}", play.stderr);
    assert!(play.stderr.contains("truncated"), "{}", play.stderr);
    assert_eq!(json(&play.stdout)["published"], messages);
}

#[test]
fn split_files_play_loop_remap_start_duration_and_bag_filter_cut() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let dir = domain.path("split").display().to_string();
    let recorder = ClientProcess::program(
        "ndds",
        &socket,
        &[
            "record",
            "data",
            "-o",
            &dir,
            "--max-size",
            "100K",
            "--chunk-size",
            "16K",
            "--compression",
            "lz4",
            "--summary-json",
        ],
    );
    // 2 s at 200 Hz of 2 KiB samples: about 800 KiB, so several files.
    publish(&socket, "data", 400, 200.0, 2048);
    recorder.interrupt();
    let summary = json(&recorder.line(WAIT).expect("summary"));
    let files = summary["files"].as_array().unwrap().len();
    println!("split: {files} files, {}", summary["messages"]);
    assert!(files >= 4, "{summary}");
    assert_eq!(summary["messages"], 400);

    // Play the directory: remapped, from 0.5 s for 1 s, twice as fast, looped twice.
    let sink = participant(&socket, "sink");
    let consumer = sink
        .consumer::<(u64, serde_bytes::ByteBuf)>(
            "replayed",
            ConsumerQos {
                depth: 4096,
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let player = ClientProcess::program(
        "ndds",
        &socket,
        &[
            "play",
            &dir,
            "--remap",
            "data=replayed",
            "--start",
            "0.5",
            "--duration",
            "1",
            "--rate",
            "2",
            "--loop",
            "--delay",
            "1",
            "--json",
        ],
    );
    let mut got = Vec::new();
    let deadline = Instant::now() + WAIT;
    // Two passes of about 200 samples (0.5 s to 1.5 s at 200 Hz).
    while got.len() < 410 && Instant::now() < deadline {
        if let Ok(sample) = consumer.recv_timeout(Duration::from_millis(100)) {
            got.push(sample.value.0);
        }
    }
    player.interrupt();
    assert!(got.len() >= 410, "{} samples", got.len());
    // A pass is 0.5 s to 1.5 s of the recording: samples 100 to 300, in order; then the
    // loop starts again at --start.
    let restart = (1..got.len())
        .find(|i| got[*i] < got[i - 1])
        .expect("a second pass");
    let first_pass = &got[..restart];
    println!(
        "play: first pass {}..={} ({} samples)",
        first_pass[0],
        got[restart - 1],
        restart
    );
    assert!((99..=101).contains(&first_pass[0]), "{first_pass:?}");
    assert!((199..=202).contains(&restart), "{first_pass:?}");
    assert!(
        first_pass.windows(2).all(|w| w[1] == w[0] + 1),
        "{first_pass:?}"
    );
    assert_eq!(
        got[restart], first_pass[0],
        "the loop starts again at --start"
    );

    // bag filter by topic (none left of another topic) and cut by time.
    let merged = domain.path("merged.mcap").display().to_string();
    let mut args = vec![
        "bag",
        "cut",
        "-o",
        &merged,
        "--start",
        "0.5",
        "--duration",
        "0.5",
    ];
    let parts: Vec<String> = summary["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap().to_owned())
        .collect();
    args.extend(parts.iter().map(String::as_str));
    let out = domain.ndds("a", &args, WAIT);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    let cut = json(&out.stdout);
    println!("cut: {cut}");
    assert!((99..=102).contains(&cut["kept"].as_u64().unwrap()), "{cut}");
    let filtered = domain.path("none.mcap").display().to_string();
    let out = domain.ndds(
        "a",
        &[
            "bag", "filter", &merged, "-o", &filtered, "--topics", "other",
        ],
        WAIT,
    );
    assert_eq!(json(&out.stdout)["kept"], 0, "{}", out.stdout);
    // An existing output is never overwritten.
    let out = domain.ndds("a", &["bag", "cut", &merged, "-o", &filtered], WAIT);
    assert_ne!(out.code, Some(0));
    assert!(out.stderr.contains("exists"), "{}", out.stderr);
}

#[test]
fn a_disk_that_fills_stops_the_recording_with_the_file_closed_properly() {
    if !nix::unistd::Uid::effective().is_root() {
        let why = "a_disk_that_fills_stops_the_recording_with_the_file_closed_properly: skipped: \
                   mounting a small tmpfs needs root";
        let required = std::env::var("CI").is_ok_and(|v| v == "true")
            || std::env::var("NDDS_REQUIRE_NETNS").is_ok_and(|v| v == "1");
        assert!(!required, "{why} (required under CI)");
        eprintln!("{why}");
        return;
    }
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let mount = domain.path("small");
    std::fs::create_dir_all(&mount).unwrap();
    let mounted = std::process::Command::new("mount")
        .args([
            "-t",
            "tmpfs",
            "-o",
            "size=24m",
            "ndds-test",
            &mount.display().to_string(),
        ])
        .status()
        .expect("mount");
    assert!(mounted.success(), "mount a tmpfs");
    struct Unmount<'a>(&'a Path);
    impl Drop for Unmount<'_> {
        fn drop(&mut self) {
            let _ = std::process::Command::new("umount").arg(self.0).status();
        }
    }
    let _unmount = Unmount(&mount);
    let bag = mount.join("full.mcap").display().to_string();
    let recorder = ClientProcess::program(
        "ndds",
        &socket,
        &[
            "record",
            "data",
            "-o",
            &bag,
            "--compression",
            "none",
            "--summary-json",
        ],
    );
    // 64 KiB samples at 500 Hz (32 MiB/s): the 24 MiB disk (8 MiB kept free) fills in 0.5 s.
    let stopped = std::thread::spawn({
        let socket = socket.clone();
        move || publish(&socket, "data", 1000, 500.0, 64 << 10)
    });
    let summary = json(&recorder.line(WAIT).expect("a summary when stopped"));
    let _ = stopped.join();
    println!("disk full: {summary}");
    let why = summary["stopped"]
        .as_str()
        .expect("stopped early, saying why");
    assert!(why.contains("closed properly"), "{why}");
    let out = domain.ndds("a", &["bag", "info", "--json", &bag], WAIT);
    let info = &json(&out.stdout)[0];
    assert_eq!(info["state"], "complete", "{info}");
    assert_eq!(info["finished"], true, "{info}");
    assert_eq!(info["messages"], summary["messages"]);
}

#[test]
fn a_recorder_that_cannot_keep_up_counts_each_lost_sample_once() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let bag = domain.path("overflow.mcap").display().to_string();
    // A queue of 256 KiB between the network and the disk: 8 KiB samples flat out overflow it.
    let recorder = ClientProcess::program(
        "ndds",
        &socket,
        &[
            "record",
            "ndds/perf/data",
            "-o",
            &bag,
            "--queue",
            "256K",
            "--summary-json",
        ],
    );
    std::thread::sleep(Duration::from_millis(500));
    let publish = domain.ndds(
        "a",
        &["perf", "pub", "--size", "8k", "--duration", "2", "--json"],
        WAIT,
    );
    assert_eq!(publish.code, Some(0), "{}", publish.stderr);
    let written = json(&publish.stdout)["written"].as_u64().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    recorder.interrupt();
    let summary = json(&recorder.line(WAIT).expect("summary"));
    let topic = &summary["topics"][0];
    let (recorded, gaps, overflow) = (
        topic["messages"].as_u64().unwrap(),
        topic["lost_gaps"].as_u64().unwrap(),
        topic["lost_overflow"].as_u64().unwrap(),
    );
    let mut reader = ndds_bag::BagReader::open(Path::new(&bag)).unwrap();
    let (mut first, mut last) = (None, 0);
    while let Some(message) = reader.next_message().unwrap() {
        first.get_or_insert(message.sequence);
        last = message.sequence;
    }
    let first = first.expect("something recorded");
    println!(
        "overflow: {written} written, {recorded} recorded, {gaps} gaps, {overflow} overflow, \
         recorded seqs {first}..={last}"
    );
    assert!(overflow > 0, "the queue overflowed");
    // Every seq from the first recorded to the last is recorded, a gap or overflow, once;
    // overflow after the last recorded one adds to that, never past what was written.
    let span = u64::from(last - first) + 1;
    assert!(
        recorded + gaps + overflow >= span,
        "{recorded} + {gaps} + {overflow} < {span}"
    );
    assert!(
        recorded + gaps + overflow <= written,
        "counted twice: more than {written} written"
    );
}

/// What `ndds play` wrote to its terminal so far, read from the pseudo-terminal's master side
/// on a thread of its own (the player would block on a full terminal otherwise).
struct Screen {
    text: std::sync::Arc<std::sync::Mutex<String>>,
}

impl Screen {
    fn read_from(master: std::os::fd::OwnedFd) -> Self {
        let text = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        let shared = std::sync::Arc::clone(&text);
        std::thread::spawn(move || {
            use std::io::Read;
            let mut master = std::fs::File::from(master);
            let mut buffer = [0u8; 4096];
            // Ends with EIO once the player and every copy of the terminal's other side closed.
            while let Ok(n @ 1..) = master.read(&mut buffer) {
                shared
                    .lock()
                    .unwrap()
                    .push_str(&String::from_utf8_lossy(&buffer[..n]));
            }
        });
        Screen { text }
    }

    /// The last status line drawn (the text after the last carriage return).
    fn status(&self) -> String {
        let text = self.text.lock().unwrap();
        let last = text.rsplit('\r').find(|line| !line.trim().is_empty());
        last.unwrap_or_default().replace("\x1b[K", "")
    }

    /// The status line once it shows `what` and has settled (the same twice, 60 ms apart: a
    /// line read while it was being written is not taken).
    fn wait_for(&self, what: &str) -> String {
        let mut status = String::new();
        let found = interop_tests::wait_until(WAIT, || {
            status = self.status();
            if !status.contains(what) {
                return false;
            }
            std::thread::sleep(Duration::from_millis(60));
            let again = self.status();
            let settled = again == status;
            status = again;
            settled
        });
        assert!(
            found.is_some(),
            "no {what:?} on the terminal; last: {status:?}"
        );
        status
    }

    fn all(&self) -> String {
        self.text.lock().unwrap().clone()
    }
}

/// Starts `ndds ARGS` (with the daemon at `socket`) on a new pseudo-terminal: its standard
/// input, output and error. Returns the process, its screen, the terminal's side (to read
/// its modes) and the keyboard (the master side, to type on).
fn on_terminal(
    socket: &Path,
    args: &[&str],
) -> (
    std::process::Child,
    Screen,
    std::os::fd::OwnedFd,
    std::fs::File,
) {
    let pty = nix::pty::openpty(None, None).expect("a pseudo-terminal");
    let terminal = pty.slave;
    let child = std::process::Command::new(interop_tests::binary("ndds"))
        .arg("--socket")
        .arg(socket)
        .args(args)
        .env("NDDS_EMBEDDED", "never")
        .stdin(terminal.try_clone().unwrap())
        .stdout(terminal.try_clone().unwrap())
        .stderr(terminal.try_clone().unwrap())
        .spawn()
        .expect("start ndds");
    let keys = std::fs::File::from(pty.master.try_clone().unwrap());
    (child, Screen::read_from(pty.master), terminal, keys)
}

#[test]
fn record_on_a_terminal_shows_a_live_status_line_and_its_summary() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let bag = domain.path("live.mcap").display().to_string();
    let (mut recorder, screen, terminal, _keys) =
        on_terminal(&socket, &["record", "data", "-o", &bag]);
    // While samples arrive the line counts them, per topic too; then it settles on the total.
    let publishing = std::thread::spawn({
        let socket = socket.clone();
        move || publish(&socket, "data", 100, 50.0, 64)
    });
    let status = screen.wait_for("| data ");
    assert!(
        status.starts_with("recording ") && status.contains("1 topics"),
        "{status:?}"
    );
    publishing.join().unwrap();
    let status = screen.wait_for("100 msgs");
    assert!(
        status.contains("| data 100") && status.contains("lost 0"),
        "{status:?}"
    );
    // Ctrl-C: the line is cleared and the summary printed; the file is finished.
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(recorder.id() as i32),
        nix::sys::signal::Signal::SIGINT,
    )
    .unwrap();
    let ended = interop_tests::wait_until(WAIT, || recorder.try_wait().unwrap().is_some());
    assert!(ended.is_some(), "Ctrl-C ends the recording");
    assert!(recorder.wait().unwrap().success());
    drop(terminal);
    let shown = interop_tests::wait_until(WAIT, || screen.all().contains(&bag));
    let all = screen.all();
    assert!(shown.is_some(), "the summary names the file: {all:?}");
    let out = domain.ndds("a", &["bag", "info", "--json", &bag], WAIT);
    let info = &json(&out.stdout)[0];
    assert_eq!(info["finished"], true, "{info}");
    assert_eq!(info["messages"], 100, "{info}");
}

#[test]
fn play_on_a_terminal_pauses_steps_changes_rate_and_quits_on_keys() {
    use nix::sys::termios::{LocalFlags, tcgetattr};
    use std::io::Write;

    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let bag = domain.path("keys.mcap").display().to_string();
    let mut recorder = ClientProcess::program("ndds", &socket, &["record", "data", "-o", &bag]);
    publish(&socket, "data", 60, 20.0, 16);
    recorder.interrupt();
    assert_eq!(
        recorder.wait(WAIT),
        Some(0),
        "the recorder finished its file"
    );

    let watcher = participant(&socket, "watcher");
    let consumer = watcher
        .consumer::<(u64, serde_bytes::ByteBuf)>("data", ConsumerQos::default())
        .unwrap();
    let mut received = Vec::new();
    let take = |received: &mut Vec<u64>| {
        while let Ok(sample) = consumer.try_recv() {
            received.push(sample.value.0);
        }
    };

    let (mut player, screen, terminal, mut keys) =
        on_terminal(&socket, &["play", &bag, "--paused"]);
    let mut press = |key: &[u8]| keys.write_all(key).expect("type on the terminal");

    // Paused from the start: the terminal says so, with the keys, and nothing is published.
    let status = screen.wait_for("paused [");
    assert!(
        status.contains("space pause") && status.contains("0/60 msgs"),
        "{status:?}"
    );
    let modes = tcgetattr(&terminal).unwrap().local_flags;
    assert!(
        !modes.intersects(LocalFlags::ICANON | LocalFlags::ECHO),
        "keys are read one by one, unechoed, while playing: {modes:?}"
    );
    std::thread::sleep(Duration::from_secs(1));
    take(&mut received);
    assert_eq!(received, Vec::<u64>::new(), "published while paused");

    // `s` steps one message at a time.
    for step in 0..2u64 {
        press(b"s");
        let arrived = interop_tests::wait_until(WAIT, || {
            take(&mut received);
            received.len() as u64 > step
        });
        assert!(arrived.is_some(), "step {step}: {received:?}");
        std::thread::sleep(Duration::from_millis(500));
        take(&mut received);
        assert_eq!(
            received,
            (0..=step).collect::<Vec<_>>(),
            "one message per step"
        );
    }
    screen.wait_for("2/60 msgs");

    // `+` doubles the rate, `-` halves it; space resumes.
    press(b"+");
    screen.wait_for("x2.00");
    press(b"+-");
    screen.wait_for("x2.00");
    press(b" ");
    screen.wait_for("playing [");
    let flowing = interop_tests::wait_until(WAIT, || {
        take(&mut received);
        received.len() >= 12
    });
    assert!(flowing.is_some(), "resumed: {received:?}");

    // Space pauses again: at most one message already due gets out after it.
    press(b" ");
    screen.wait_for("paused [");
    std::thread::sleep(Duration::from_millis(300));
    take(&mut received);
    let at_pause = received.len();
    std::thread::sleep(Duration::from_secs(1));
    take(&mut received);
    assert!(
        received.len() <= at_pause + 1,
        "{at_pause} then {}",
        received.len()
    );
    assert!(
        received.len() < 60,
        "still paused before the end: {}",
        received.len()
    );
    assert_eq!(
        received,
        (0..received.len() as u64).collect::<Vec<_>>(),
        "in order, none lost"
    );

    // `q` quits with the summary, and the terminal's modes are given back.
    press(b"q");
    let quit = interop_tests::wait_until(WAIT, || player.try_wait().unwrap().is_some());
    assert!(quit.is_some(), "q quits");
    assert!(player.wait().unwrap().success());
    let restored = tcgetattr(&terminal).unwrap().local_flags;
    assert!(
        restored.contains(LocalFlags::ICANON | LocalFlags::ECHO),
        "terminal restored: {restored:?}"
    );
    drop(terminal);
    let shown = interop_tests::wait_until(WAIT, || screen.all().contains("published "));
    let all = screen.all();
    assert!(shown.is_some(), "summary on quitting: {all:?}");
    assert!(
        all.contains(&format!("published {} messages", received.len())),
        "the summary counts the {} received: {all:?}",
        received.len()
    );
}

//! The embedded daemon's life across real processes on loopback: its socket goes when its
//! process exits normally; a stale socket reads as "no daemon"; when the process that embedded
//! the daemon exits, a survivor takes the role over (data keeps flowing, `ndds topics` keeps
//! working, one daemon); a second `ndds-daemon` on a served socket says so in one line.
//!
//! The SDK processes are this test binary run again with `NDDS_TEST_ROLE` set: the `child`
//! test below plays the role and returns, so the process ends the way a program's `main` does.

use std::io::{BufRead as _, BufReader, Read as _, Write as _};
use std::net::Ipv4Addr;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use interop_tests::{TestDomain, wait_until};
use ndds_client::{ConsumerQos, DaemonConfig, EmbeddedPolicy, Participant, ProducerQos, RecvError};

const WAIT: Duration = Duration::from_secs(10);
const TOPIC: &str = "survivor/count";

/// An SDK process of this test: this binary running the `child` test in a role.
struct Child {
    child: std::process::Child,
    lines: Receiver<String>,
}

impl Child {
    fn start(domain: &TestDomain, role: &str) -> Child {
        let mut child = Command::new(std::env::current_exe().unwrap())
            .args(["--exact", "child", "--nocapture", "--test-threads=1", "-q"])
            .env("NDDS_TEST_ROLE", role)
            .env("NDDS_TEST_SOCKET", domain.socket("embedded"))
            .env("NDDS_TEST_DOMAIN", domain.domain.to_string())
            .env("NDDS_TEST_PORT", domain.port.to_string())
            .env("NDDS_TEST_GROUP", domain.group.to_string())
            .env_remove("NDDS_SOCKET")
            .env_remove("NDDS_DOMAIN")
            .env_remove("NDDS_EMBEDDED")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start a child role");
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let started = Child { child, lines };
        started.expect_line("ready");
        started
    }

    /// Waits for a line starting with `prefix`; returns the rest of it.
    fn expect_line(&self, prefix: &str) -> String {
        let deadline = Instant::now() + WAIT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if line.starts_with(prefix) => return line[prefix.len()..].to_owned(),
                Ok(_) => {}
                Err(_) => panic!("no {prefix:?} line within {WAIT:?}"),
            }
        }
    }

    /// Samples printed since the last call.
    fn samples(&self) -> usize {
        self.lines
            .try_iter()
            .filter(|l| l.starts_with("sample"))
            .count()
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Closes its stdin (the `embed` role then returns) and waits for its exit code.
    fn finish(&mut self) -> Option<i32> {
        drop(self.child.stdin.take());
        let deadline = Instant::now() + WAIT;
        while Instant::now() < deadline {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status.code();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        None
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The embedded daemon configuration of the children: the test's domain, on loopback.
fn child_config() -> DaemonConfig {
    let var = |name: &str| std::env::var(name).expect(name);
    let mut config = DaemonConfig::new(
        var("NDDS_TEST_DOMAIN").parse().unwrap(),
        Ipv4Addr::LOCALHOST,
    );
    config.socket = var("NDDS_TEST_SOCKET").into();
    config.port = var("NDDS_TEST_PORT").parse().unwrap();
    config.group = var("NDDS_TEST_GROUP").parse().unwrap();
    config.unicast_port = Some(0);
    config.announce_period = interop_tests::PERIOD;
    config.lease = interop_tests::LEASE;
    config
}

/// Not a test on its own: the role of a child process (see the module docs).
#[test]
fn child() {
    let Ok(role) = std::env::var("NDDS_TEST_ROLE") else {
        return;
    };
    let participant = Participant::builder()
        .embedded(EmbeddedPolicy::Auto)
        .embedded_config(child_config())
        .name(role.as_str())
        .connect()
        .expect("connect");
    let out = |line: String| {
        let mut stdout = std::io::stdout().lock();
        let _ = writeln!(stdout, "{line}");
        let _ = stdout.flush();
    };
    match role.as_str() {
        // Embeds the daemon (it starts first), then lives until its stdin closes.
        "embed" => {
            let _producer = participant
                .producer::<u64>("embedder/alive", ProducerQos::default())
                .unwrap();
            out(format!("ready {}", participant.daemon().pid));
            let _ = std::io::stdin().read_to_end(&mut Vec::new());
        }
        "produce" => {
            let producer = participant
                .producer::<u64>(TOPIC, ProducerQos::default())
                .unwrap();
            out(format!("ready {}", participant.daemon().pid));
            for i in 0.. {
                let _ = producer.write(&i);
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        "consume" => {
            let consumer = participant
                .consumer::<u64>(TOPIC, ConsumerQos::default())
                .unwrap();
            out(format!("ready {}", participant.daemon().pid));
            loop {
                match consumer.recv_timeout(Duration::from_millis(100)) {
                    Ok(sample) => out(format!("sample {}", sample.value)),
                    Err(err) if err.is_timeout() => {}
                    Err(RecvError::Closed) | Err(_) => return,
                }
            }
        }
        other => panic!("unknown role {other}"),
    }
}

#[test]
fn a_program_that_embedded_the_daemon_and_exits_normally_leaves_no_socket() {
    let domain = TestDomain::new();
    let mut embedder = Child::start(&domain, "embed");
    let socket = domain.socket("embedded");
    assert!(
        socket.exists(),
        "the embedded daemon serves {}",
        socket.display()
    );
    assert_eq!(embedder.finish(), Some(0), "a normal exit");
    assert!(!socket.exists(), "{} left behind", socket.display());
    let out = domain.ndds("embedded", &["topics"], WAIT);
    assert_ne!(out.code, Some(0));
    assert!(
        out.stderr.contains("no ndds daemon is running"),
        "{}",
        out.stderr
    );
}

#[test]
fn a_stale_socket_reads_as_no_daemon_running() {
    let domain = TestDomain::new();
    let socket = domain.socket("stale");
    // A socket file nobody listens on: what a killed daemon leaves.
    drop(std::os::unix::net::UnixListener::bind(&socket).unwrap());
    assert!(socket.exists());
    let out = domain.ndds("stale", &["topics"], WAIT);
    assert_ne!(out.code, Some(0), "{}", out.stderr);
    assert!(
        out.stderr.contains("no ndds daemon is running") && out.stderr.contains("stale socket"),
        "{}",
        out.stderr
    );
    assert!(!out.stderr.contains("Connection refused"), "{}", out.stderr);
}

#[test]
fn a_survivor_takes_the_daemon_over_when_the_embedding_process_exits() {
    let domain = TestDomain::new();
    let socket = domain.socket("embedded");
    let mut embedder = Child::start(&domain, "embed");
    let producer = Child::start(&domain, "produce");
    let consumer = Child::start(&domain, "consume");
    consumer.expect_line("sample");

    assert_eq!(embedder.finish(), Some(0));
    let exited = Instant::now();
    // Samples keep flowing meanwhile, and after.
    std::thread::sleep(Duration::from_millis(300));
    consumer.samples();
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        consumer.samples() > 5,
        "samples stopped when the embedder exited"
    );

    // The real `ndds topics` against the socket lists the survivors' topic again.
    let listed = wait_until(WAIT, || {
        let out = domain.ndds("embedded", &["topics", "--json"], WAIT);
        out.code == Some(0) && out.stdout.contains(TOPIC)
    });
    eprintln!("topics listed {listed:?} after the embedder exited");
    assert!(listed.is_some(), "no daemon took over within {WAIT:?}");

    // Exactly one daemon: both survivors are its clients, and no other daemon announces.
    let tool = domain.tool("embedded");
    let one = wait_until(WAIT, || {
        let graph = tool.graph().unwrap();
        let clients: Vec<u32> = graph.clients.iter().map(|c| c.pid).collect();
        clients.contains(&producer.pid()) && clients.contains(&consumer.pid())
    });
    assert!(
        one.is_some(),
        "both survivors on the daemon at {}",
        socket.display()
    );
    std::thread::sleep(interop_tests::PERIOD * 3);
    let graph = tool.graph().unwrap();
    assert!(
        graph.nodes.is_empty(),
        "another daemon announces itself: {:?}",
        graph.nodes
    );
    assert!(
        [producer.pid(), consumer.pid()].contains(&graph.local.info.pid),
        "the daemon runs in a survivor (pid {})",
        graph.local.info.pid
    );
    consumer.samples();
    std::thread::sleep(Duration::from_millis(300));
    assert!(consumer.samples() > 5, "samples flow after the takeover");
    eprintln!(
        "took over and verified {:?} after the exit",
        exited.elapsed()
    );
}

#[test]
fn a_second_daemon_on_a_served_socket_says_so_in_one_line() {
    let domain = TestDomain::new();
    let first = domain.daemon("d");
    let mut command = Command::new(interop_tests::binary("ndds-daemon"));
    command
        .args(domain.daemon_args("d"))
        .env("RUST_BACKTRACE", "1")
        .env_remove("RUST_LOG");
    let out = interop_tests::process::run_command(command, WAIT);
    assert_ne!(out.code, Some(0));
    let expected = format!(
        "ndds-daemon: a daemon already serves {} (pid {}); stop it or choose another --socket / \
         --domain",
        domain.socket("d").display(),
        first.pid()
    );
    assert_eq!(out.stderr.trim(), expected, "one line, nothing else");
    assert!(
        Path::new(&domain.socket("d")).exists(),
        "the first daemon's socket is untouched"
    );
}

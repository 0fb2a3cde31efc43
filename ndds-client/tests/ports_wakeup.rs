//! Port primitives sleep on what they wait for: a blocked `receive`, `select`, `waitfor` and
//! `Responder` wake when a message arrives, and a waiting thread burns (almost) no CPU and
//! wakes a handful of times, not once a millisecond (counted as voluntary context switches:
//! the old 1 ms sleep loops made hundreds over these waits). Bounds are generous: these are
//! behaviour checks, not timings.

mod common;

use std::sync::Arc;
use std::time::{Duration, Instant};

use ndds_client::ports::{PortOwner, PortUser, Rendezvous, Responder, Selectable, Usage, select};

const WAIT: Duration = Duration::from_secs(10);
/// How long the waits under test last before what they wait for comes.
const QUIET: Duration = Duration::from_millis(400);
/// CPU a thread may use over a quiet wait (a 1 ms poll loop would use far more).
const IDLE_CPU: Duration = Duration::from_millis(30);
/// Times a waiting thread may wake over a quiet wait (a 1 ms poll loop: hundreds).
const IDLE_WAKES: u64 = 40;
/// How late a waiter may wake after the arrival, at most (generous: a loaded CI host).
const PROMPT: Duration = Duration::from_secs(2);

fn participant(dir: &std::path::Path, name: &str) -> ndds_client::Participant {
    common::participant(&common::unique_config(dir, name))
}

/// CPU time the calling thread has used, and how often it went to sleep (voluntary context
/// switches).
fn thread_usage() -> Spent {
    // SAFETY: getrusage only writes the struct it is given.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: a valid pointer to a rusage.
    let rc = unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut usage) };
    assert_eq!(rc, 0, "getrusage");
    let micros = |t: libc::timeval| t.tv_sec as u64 * 1_000_000 + t.tv_usec as u64;
    Spent {
        cpu: Duration::from_micros(micros(usage.ru_utime) + micros(usage.ru_stime)),
        wakes: usage.ru_nvcsw as u64,
    }
}

#[derive(Clone, Copy, Debug)]
struct Spent {
    cpu: Duration,
    wakes: u64,
}

impl std::ops::Sub for Spent {
    type Output = Spent;

    fn sub(self, earlier: Spent) -> Spent {
        Spent {
            cpu: self.cpu.saturating_sub(earlier.cpu),
            wakes: self.wakes.saturating_sub(earlier.wakes),
        }
    }
}

/// Asserts that `used` is what a thread sleeping on a channel uses over a quiet wait.
fn assert_idle(what: &str, used: Spent) {
    eprintln!("{what}: {used:?} over a {QUIET:?} wait");
    assert!(used.cpu < IDLE_CPU, "{what} used {:?} of CPU", used.cpu);
    assert!(used.wakes < IDLE_WAKES, "{what} woke {} times", used.wakes);
}

/// CPU ticks and voluntary context switches so far of this process's threads named
/// `prefix...`.
fn named_threads(prefix: &str) -> Spent {
    let ticks_per_s = {
        // SAFETY: sysconf has no preconditions.
        let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
        if t > 0 { t as u64 } else { 100 }
    };
    let (mut ticks, mut wakes) = (0u64, 0u64);
    for task in std::fs::read_dir("/proc/self/task").unwrap().flatten() {
        let comm = std::fs::read_to_string(task.path().join("comm")).unwrap_or_default();
        if !comm.trim_end().starts_with(prefix) {
            continue;
        }
        let stat = std::fs::read_to_string(task.path().join("stat")).unwrap_or_default();
        // Fields after the parenthesised name: state is field 3, utime 14, stime 15.
        let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
        let fields: Vec<&str> = rest.split_whitespace().collect();
        let field = |n: usize| fields.get(n - 3).and_then(|f| f.parse::<u64>().ok());
        ticks += field(14).unwrap_or(0) + field(15).unwrap_or(0);
        let status = std::fs::read_to_string(task.path().join("status")).unwrap_or_default();
        wakes += status
            .lines()
            .find_map(|l| l.strip_prefix("voluntary_ctxt_switches:"))
            .and_then(|v| v.trim().parse::<u64>().ok())
            .unwrap_or(0);
    }
    Spent {
        cpu: Duration::from_millis(ticks * 1000 / ticks_per_s),
        wakes,
    }
}

type Owner = PortOwner<u32, u32>;
type User = PortUser<u32, u32>;

/// A user and an owner of `port` that have found each other (one exchange done).
fn connected(p: &ndds_client::Participant, port: &str) -> (Arc<Owner>, Arc<User>) {
    let owner = Arc::new(PortOwner::<u32, u32>::declare(p, port, "server").unwrap());
    let user = Arc::new(PortUser::<u32, u32>::declare(p, port, "client").unwrap());
    let warm = {
        let user = Arc::clone(&user);
        std::thread::spawn(move || user.send(&0, WAIT))
    };
    let (_, reply) = owner.receive(WAIT).unwrap();
    reply.reply(&0).unwrap();
    warm.join().unwrap().unwrap();
    (owner, user)
}

/// Sends `value` after `QUIET`, returning when it was sent and the reply.
fn send_later(
    user: &Arc<PortUser<u32, u32>>,
    value: u32,
) -> std::thread::JoinHandle<(Instant, u32)> {
    let user = Arc::clone(user);
    std::thread::spawn(move || {
        std::thread::sleep(QUIET);
        let sent = Instant::now();
        (sent, user.send(&value, WAIT).unwrap())
    })
}

#[test]
fn a_blocked_receive_wakes_on_arrival_without_burning_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "wake-receive");
    let (owner, user) = connected(&p, "wake.receive");
    let sender = send_later(&user, 7);
    let cpu = thread_usage();
    let (n, reply) = owner.receive(WAIT).unwrap();
    let woke = Instant::now();
    let used = thread_usage() - cpu;
    reply.reply(&(n + 1)).unwrap();
    let (sent, answer) = sender.join().unwrap();
    assert_eq!((n, answer), (7, 8));
    assert!(
        woke - sent < PROMPT,
        "woke {:?} after the send",
        woke - sent
    );
    assert_idle("receive", used);
}

#[test]
fn a_blocked_send_waits_for_its_reply_without_burning_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "wake-send");
    let (owner, user) = connected(&p, "wake.send");
    let server = std::thread::spawn(move || {
        let (n, reply) = owner.receive(WAIT).unwrap();
        std::thread::sleep(QUIET);
        reply.reply(&(n * 2)).unwrap();
        Instant::now()
    });
    let cpu = thread_usage();
    let answer = user.send(&21, WAIT).unwrap();
    let woke = Instant::now();
    let used = thread_usage() - cpu;
    let replied = server.join().unwrap();
    assert_eq!(answer, 42);
    assert!(
        woke - replied < PROMPT,
        "woke {:?} after the reply",
        woke - replied
    );
    assert_idle("send", used);
}

#[test]
fn a_blocked_select_wakes_on_arrival_without_burning_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "wake-select");
    let (low, low_user) = connected(&p, "wake.low");
    let (high, _high_user) = connected(&p, "wake.high");
    high.set_priority(5);
    let sender = send_later(&low_user, 3);
    let ports: [&dyn Selectable; 2] = [&*high, &*low];
    let cpu = thread_usage();
    let chosen = select(&ports, WAIT).unwrap();
    let woke = Instant::now();
    let used = thread_usage() - cpu;
    assert_eq!(chosen, 1, "the port with a request");
    let (n, reply) = low.receive(WAIT).unwrap();
    reply.reply(&n).unwrap();
    let (sent, _) = sender.join().unwrap();
    assert!(
        woke - sent < PROMPT,
        "woke {:?} after the send",
        woke - sent
    );
    assert_idle("select", used);
}

#[test]
fn a_waitfor_sleeps_until_the_last_task_arrives() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "wake-waitfor");
    let early = Rendezvous::<u32>::join(&p, "wake.rv", "early", &["early", "late"]).unwrap();
    let late = Rendezvous::<u32>::join(&p, "wake.rv", "late", &["early", "late"]).unwrap();
    let latecomer = std::thread::spawn(move || {
        std::thread::sleep(QUIET);
        let arrived = Instant::now();
        let sum = late
            .wait(&2, WAIT, |all| all.values().sum::<u32>())
            .unwrap();
        (arrived, sum, late)
    });
    let cpu = thread_usage();
    let sum = early
        .wait(&1, WAIT, |all| all.values().sum::<u32>())
        .unwrap();
    let woke = Instant::now();
    let used = thread_usage() - cpu;
    let (arrived, other, _late) = latecomer.join().unwrap();
    assert_eq!((sum, other), (3, 3));
    assert!(
        woke - arrived < PROMPT,
        "woke {:?} after the arrival",
        woke - arrived
    );
    assert_idle("waitfor", used);
}

#[test]
fn idle_owners_users_and_responders_use_no_cpu_and_answer_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "wake-idle");
    let mut responder = Responder::new(&p, "idle").unwrap();
    responder.handle("idle.q", 0, |n: u32| n + 1).unwrap();
    let asker = PortUser::<u32, u32>::declare_with(&p, "idle.q", "asker", &[Usage::Query]).unwrap();
    assert_eq!(asker.query(&1, WAIT).unwrap(), 2);
    let (_owner, _user) = connected(&p, "idle.cmd");
    // Threads of ports: the responder's worker, each owner's declaration thread (the old
    // announcers woke every 10 ms, the responder's receivers every 50 ms).
    let before = (named_threads("respond-"), named_threads("port-"));
    std::thread::sleep(Duration::from_millis(600));
    let used = [
        ("responder", named_threads("respond-") - before.0),
        ("owners", named_threads("port-") - before.1),
    ];
    eprintln!("idle over 600 ms: {used:?}");
    for (what, used) in used {
        // Tick resolution is 10 ms: allow a few.
        assert!(
            used.cpu <= Duration::from_millis(40),
            "idle {what} used {:?}",
            used.cpu
        );
        assert!(
            used.wakes < IDLE_WAKES,
            "idle {what} woke {} times",
            used.wakes
        );
    }
    let start = Instant::now();
    assert_eq!(asker.query(&5, WAIT).unwrap(), 6);
    assert!(
        start.elapsed() < PROMPT,
        "an idle responder took {:?}",
        start.elapsed()
    );
}

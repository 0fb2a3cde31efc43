//! The appendix of Shin's paper, whole (`ndds-client/examples/chip_line.rs`): run by one
//! command on loopback, stopped by Ctrl-C, and spread over three hosts simulated with network
//! namespaces — GATE and RELEASE on the first, LOAD_IT and its children on the second, the two
//! chip robots on the third — where RELEASE is killed and replaced.
//!
//! What the line must do is checked from the events its processes print (JSON lines, with
//! times from a clock every process of the machine shares): pallets flow, every card gets
//! every chip, the feeder rack is never in two robots' hands at once, an emptied feeder is
//! reported and the other steps go on, and killing RELEASE makes GATE's timeout handler run
//! and a replacement RELEASE take LET_1_GO over.

mod support;

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use interop_tests::netns::Cluster;
use interop_tests::{ClientProcess, TestDomain};
use serde_json::Value;
use support::exclusive;

const WAIT: Duration = Duration::from_secs(60);

/// Every event printed so far by `processes`, oldest first (by their own clock).
#[derive(Default)]
struct Events(Vec<Value>);

impl Events {
    /// Takes the lines the processes printed meanwhile.
    fn pump(&mut self, processes: &[&ClientProcess]) {
        for process in processes {
            while let Some(line) = process.line(Duration::ZERO) {
                if let Ok(value) = serde_json::from_str::<Value>(&line) {
                    self.0.push(value);
                }
            }
        }
        self.0.sort_by_key(|e| e["t_us"].as_u64().unwrap_or(0));
    }

    /// Pumps until `check` holds (or `WAIT` passes); whether it held.
    fn until(
        &mut self,
        processes: &[&ClientProcess],
        mut check: impl FnMut(&Events) -> bool,
    ) -> bool {
        let deadline = Instant::now() + WAIT;
        while Instant::now() < deadline {
            self.pump(processes);
            if check(self) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        false
    }

    fn of<'a>(&'a self, module: &'a str, event: &'a str) -> impl Iterator<Item = &'a Value> + 'a {
        self.0
            .iter()
            .filter(move |e| e["event"] == event && (module.is_empty() || e["module"] == module))
    }

    fn count(&self, module: &str, event: &str) -> usize {
        self.of(module, event).count()
    }

    /// Pallets that left the line.
    fn done(&self) -> BTreeSet<u64> {
        self.of("", "done")
            .filter_map(|e| e["pallet"].as_u64())
            .collect()
    }

    /// The line's invariants over every event so far; a description of each violation.
    fn violations(&self) -> Vec<String> {
        let mut found = Vec::new();
        // The feeder rack is never in two robots' hands at once.
        let mut holder: Option<&Value> = None;
        for e in &self.0 {
            match e["event"].as_str() {
                Some("grasp_begin") => {
                    if let Some(h) = holder {
                        found.push(format!("{} grasped while {} held the rack", e, h));
                    }
                    holder = Some(e);
                }
                Some("grasp_end") => holder = None,
                Some("violation") => found.push(format!("the rack saw {e}")),
                _ => {}
            }
        }
        // Every card that left the line got every chip.
        let mut chips: BTreeMap<u64, BTreeSet<u64>> = BTreeMap::new();
        for e in self.of("", "inserted") {
            if let (Some(p), Some(f)) = (e["pallet"].as_u64(), e["feeder"].as_u64()) {
                chips.entry(p).or_default().insert(f);
            }
        }
        let all: BTreeSet<u64> = [1, 4, 12].into();
        for pallet in self.done() {
            if chips.get(&pallet) != Some(&all) {
                found.push(format!(
                    "pallet {pallet} left with chips {:?}",
                    chips.get(&pallet)
                ));
            }
        }
        found
    }
}

#[test]
fn the_appendix_line_runs_by_one_command_and_stops_on_ctrl_c() {
    let domain = TestDomain::new();
    let _daemon = domain.daemon("line");
    let socket = domain.socket("line");
    // To the end: eight pallets, feeder 4 runs empty after three chips.
    let mut line =
        ClientProcess::program("chip_line", &socket, &["--pallets", "8", "--feeder4", "3"]);
    let mut events = Events::default();
    assert!(
        events.until(&[&line], |e| e.count("chip_line", "stopping") == 1),
        "the line did not finish: {} pallets done",
        events.done().len()
    );
    assert_eq!(line.wait(WAIT), Some(0), "chip_line exits cleanly");
    events.pump(&[&line]);
    assert_eq!(
        events.done(),
        (0..8).collect(),
        "every pallet left the line"
    );
    assert_eq!(events.violations(), Vec::<String>::new());
    assert!(
        events.count("", "feeder_empty") >= 1,
        "the empty feeder was reported"
    );
    assert!(events.count("RACK", "refilled") >= 1, "and refilled");
    assert_eq!(events.count("LOAD_IT", "costarted"), 1);
    assert_eq!(events.count("", "release_timeout"), 0);
    // Ctrl-C in the middle: the modules stop, the process exits 0.
    let mut line = ClientProcess::program("chip_line", &socket, &["--pallets", "1000"]);
    let mut events = Events::default();
    assert!(
        events.until(&[&line], |e| e.done().len() >= 2),
        "pallets flow"
    );
    line.interrupt();
    assert_eq!(
        line.wait(Duration::from_secs(20)),
        Some(0),
        "Ctrl-C stops it cleanly"
    );
    events.pump(&[&line]);
    assert_eq!(events.count("chip_line", "stopping"), 1);
    assert_eq!(events.violations(), Vec::<String>::new());
}

#[test]
fn the_appendix_line_over_three_hosts_survives_killing_release() {
    if support::skipped() {
        return;
    }
    let _turn = exclusive();
    let cluster = Cluster::new(3);
    let program = |host: usize, args: &[&str]| {
        ClientProcess::program_on(cluster.host(host), "chip_line", &cluster.socket(host), args)
    };
    let chips = program(
        2,
        &[
            "--modules",
            "CHIP_IT,CHIP_IT2",
            "--seconds",
            "150",
            "--feeder4",
            "3",
        ],
    );
    let load = program(1, &["--modules", "LOAD_IT", "--seconds", "150"]);
    let mut release = program(0, &["--modules", "RELEASE", "--seconds", "150"]);
    let gate = program(
        0,
        &["--modules", "GATE", "--seconds", "150", "--pallets", "14"],
    );
    let mut events = Events::default();
    assert!(
        events.until(&[&chips, &load, &release, &gate], |e| e.done().len() >= 4),
        "pallets do not flow across the hosts: {} done",
        events.done().len()
    );
    // The module tree, seen from LOAD_IT's host.
    let tree = cluster.ndds(1, &["modules", "--json", "--listen", "2"], WAIT);
    let tree: Value = serde_json::from_str(&tree.stdout).expect("ndds modules --json");
    let card = tree["modules"]
        .as_array()
        .and_then(|m| m.iter().find(|m| m["name"] == "LOAD_CARD"))
        .cloned();
    assert_eq!(
        card.map(|c| c["parent"].clone()),
        Some(Value::from("LOAD_IT")),
        "{tree}"
    );
    // RELEASE dies: GATE's send on LET_1_GO times out and its exception handler runs.
    release.kill9();
    assert!(
        events.until(&[&chips, &load, &gate], |e| e
            .count("GATE", "release_timeout")
            >= 1),
        "GATE's LET_1_GO.TIMEOUT handler never ran"
    );
    // A replacement under another name takes the port over; the line goes on to the end.
    let release2 = program(
        0,
        &[
            "--modules",
            "RELEASE",
            "--release-name",
            "RELEASE2",
            "--seconds",
            "150",
        ],
    );
    assert!(
        events.until(&[&chips, &load, &gate, &release2], |e| e.done().len() >= 14),
        "the line did not finish after the replacement: {} done, events: {:?}",
        events.done().len(),
        events.0.iter().rev().take(20).collect::<Vec<_>>()
    );
    events.pump(&[&chips, &load, &gate, &release2]);
    assert!(
        events.count("RELEASE2", "released") >= 1,
        "RELEASE2 released pallets"
    );
    assert_eq!(events.done(), (0..14).collect());
    assert_eq!(events.violations(), Vec::<String>::new());
    assert!(
        events.count("", "feeder_empty") >= 1,
        "an emptied feeder was reported"
    );
    assert!(
        events.count("LOAD_IT", "status") >= 1,
        "LOAD_IT queried its children"
    );
}

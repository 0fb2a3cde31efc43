//! `ndds modules` against modules running in this process: the tree, with parents, children
//! not started yet, tasks and ports, and the same as JSON.

mod common;

use std::time::Duration;

use common::World;
use ndds_client::ports::{ModuleBuilder, Restrictions, Usage};

#[test]
fn ndds_modules_shows_the_tree_a_costart_made() {
    let world = World::start();
    let p = world.participant("modules-tree");
    let load_card = ModuleBuilder::new(&p, "LOAD_CARD")
        .uses::<(), u32>("ASK_CHILD1", &[Usage::Response], None)
        .response("ASK_CHILD1.STATUS", |()| 3_u32)
        .task("FREEZE_PALLET", |task| {
            while !task.stopping() {
                std::thread::sleep(Duration::from_millis(20));
            }
        });
    let screw_in_card = ModuleBuilder::new(&p, "SCREW_IN_CARD");
    let running = ModuleBuilder::new(&p, "LOAD_IT")
        .owns::<(), u32>(
            "ASK_CHILD1",
            Restrictions {
                usages: vec![Usage::Query],
                ..Restrictions::default()
            },
        )
        .child(load_card)
        .child(screw_in_card)
        .body(|ctx| {
            // SCREW_IN_CARD is left for later: the tree says so.
            ctx.costart(&["LOAD_CARD"]).unwrap();
        })
        .load()
        .unwrap()
        .start()
        .unwrap();
    let want = format!(
        "LOAD_IT  (pid {pid} on {host})\n  owns   ASK_CHILD1\n  uses   -\n  not started  SCREW_IN_CARD\n    LOAD_CARD  (pid {pid} on {host})\n      owns   -\n      uses   ASK_CHILD1\n      tasks  FREEZE_PALLET\n",
        pid = std::process::id(),
        host = gethostname()
    );
    let mut last = String::new();
    let shown = common::eventually(Duration::from_secs(10), || {
        last = world.ndds(&["modules", "--listen", "2"]).ok().to_owned();
        last == want
    });
    assert!(shown, "got:\n{last}\nwanted:\n{want}");
    let json = world.ndds(&["modules", "--json", "--listen", "2"]).json();
    let modules = json["modules"].as_array().unwrap();
    assert_eq!(modules.len(), 2, "{json}");
    let card = modules.iter().find(|m| m["name"] == "LOAD_CARD").unwrap();
    assert_eq!(card["parent"], "LOAD_IT");
    drop(running);
    let gone = common::eventually(Duration::from_secs(10), || {
        world.ndds(&["modules", "--listen", "0.2"]).ok() == "no modules\n"
    });
    assert!(gone, "the modules stayed after they stopped");
}

fn gethostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_owned())
        .unwrap_or_default()
}

#[test]
fn ndds_modules_check_reads_a_specification_file_without_a_daemon() {
    // The appendix's specifications, as shipped with the example: they hold together.
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../ndds-client/examples/chip_line.toml"
    );
    let nowhere = std::path::Path::new("/nonexistent/ndds.sock");
    let out = common::ndds_at(nowhere, &["modules", "--check", spec]);
    assert!(
        out.ok()
            .contains("8 module(s) hold together: GATE, RELEASE, RELEASE2, LOAD_IT"),
        "{out}"
    );
    // A file whose modules disagree: every problem, where it was written, and a failure.
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "[[module]]\nname = \"OWNER\"\n[[module.owns]]\nport = \"P\"\nusages = [\"receive\"]\n\n\
         [[module]]\nname = \"USER\"\nresponses = [\"P.ANSWER\"]\n[[module.uses]]\nport = \"P\"\nusages = [\"query\"]\n\
         [[module.uses]]\nport = \"Q\"\nusages = [\"sned\"]\n",
    )
    .unwrap();
    let out = common::ndds_at(nowhere, &["modules", "--check", bad.to_str().unwrap()]);
    let printed = out.stdout.clone();
    assert!(out.err().contains("1 problem(s)"), "{out}");
    assert!(
        printed.contains("bad.toml:15:11: unknown usage `sned`"),
        "{out}"
    );
    std::fs::write(&bad, "[[module]]\nname = \"OWNER\"\n[[module.owns]]\nport = \"P\"\nusages = [\"receive\"]\n\n[[module]]\nname = \"USER\"\n[[module.uses]]\nport = \"P\"\nusages = [\"query\"]\n").unwrap();
    let out = common::ndds_at(nowhere, &["modules", "--check", bad.to_str().unwrap()]);
    assert!(out.err().contains("1 problem(s)"), "{out}");
    assert!(
        out.stdout
            .contains("port `P`: `USER` uses it with Query, which complements none of the owner's usages [Receive]"),
        "{out}"
    );
}

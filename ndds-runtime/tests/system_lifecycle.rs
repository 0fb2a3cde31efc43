//! Loading, starting, stopping and dropping systems with state machines and triggers, many
//! times: no thread ever panics (a machine used to be dropped, and joined, on its own thread
//! when a trigger held it).

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use ndds_runtime::system::{LoadOptions, System};

#[test]
fn systems_with_machines_and_triggers_come_and_go_without_panics() {
    let panics = Arc::new(AtomicUsize::new(0));
    let counted = Arc::clone(&panics);
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        counted.fetch_add(1, Ordering::SeqCst);
        default(info);
    }));
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/sequence.toml");
    for round in 0..200 {
        let system = System::load_with(
            &file,
            None,
            LoadOptions::simulated().with_library(ndds_components::library()),
        )
        .unwrap();
        system.start().unwrap();
        // Far enough for the triggers to fire and the machine to switch configurations.
        for _ in 0..(round % 4) * 10 {
            system.simulate(0.1).unwrap();
        }
        if round % 2 == 0 {
            system.stop();
            assert!(
                system.machine("task").is_none(),
                "stopped machines are gone"
            );
        }
        drop(system);
    }
    assert_eq!(panics.load(Ordering::SeqCst), 0, "a thread panicked");
}

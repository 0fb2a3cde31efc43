//! Commands that ask a running system to do something say whether it did: the quickstart's
//! arm (`ndds run examples/arm.toml`, a real process on a test daemon) refuses misspelt
//! stimuli, unknown configurations and samples of the wrong shape, and `ndds` exits non-zero
//! with the system's reason; what it accepts is reported as done. A second copy of the
//! system in the domain is refused at start, naming the first one's host and pid.

mod common;

use common::{Running, SETTLE, World};

fn arm_file() -> String {
    concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/arm.toml").to_owned()
}

/// The quickstart's system under `world`'s daemon, once its command ports are up.
fn start_arm(world: &World) -> Running {
    let file = arm_file();
    let mut arm = world.spawn(&["run", "--plain", &file]);
    let participant = world.participant("loud-test");
    let ready = world.graph_until(&participant, |g| {
        ["port/fsm.arm/owner", "port/cs.arm/owner"]
            .iter()
            .all(|port| g.endpoints.iter().any(|e| e.info.topic == *port))
    });
    assert!(ready, "the arm's command ports never appeared");
    assert!(arm.is_running(), "ndds run ended early");
    arm
}

#[test]
fn misspelt_stimuli_are_refused_with_the_machines_reason() {
    let world = World::start();
    let _arm = start_arm(&world);

    let run = world.ndds(&["fsm", "send", "arm", "Corse"]);
    let err = run.err();
    assert!(
        err.contains("machine `arm` has no stimulus `Corse` (did you mean `Coarse`?); it accepts: Coarse, Precise, Settled"),
        "{run}"
    );
    assert!(!err.contains("sent"), "{run}");
    let run = world.ndds(&["fsm", "send", "arm", "Coarse=1"]);
    assert!(
        run.err()
            .contains("`Coarse` is a transient stimulus and takes no value"),
        "{run}"
    );
    let run = world.ndds(&["fsm", "send", "arm", "Object=Visibel"]);
    assert!(run.err().contains("has no stimulus `Object`"), "{run}");
    // A good stimulus with a bad one: neither is taken.
    let run = world.ndds(&["fsm", "send", "arm", "Coarse", "Corse"]);
    assert!(run.failed(), "{run}");
    let run = world.ndds(&["fsm", "show", "arm"]);
    assert!(
        !run.ok().contains("state       Held"),
        "Coarse of a refused command ran: {run}"
    );
    assert!(
        run.ok().contains("accepts     Coarse Precise Settled"),
        "{run}"
    );

    // What it takes is reported as done, with the transition it caused.
    let run = world.ndds(&["fsm", "send", "arm", "Coarse"]);
    assert!(run.ok().contains("arm: Coarse: "), "{run}");
    assert!(
        run.ok().contains("-> Held (switch JointPD, code 0)"),
        "{run}"
    );

    // A machine that does not exist is named with the ones that do.
    let run = world.ndds(&["fsm", "send", "--wait", "1", "armm", "Coarse"]);
    assert!(
        run.err()
            .contains("no state machine `armm` answered within 1s; did you mean `arm`?"),
        "{run}"
    );
}

#[test]
fn configure_commands_report_the_outcome_and_refusals_exit_non_zero() {
    let world = World::start();
    let _arm = start_arm(&world);

    // Hold the supervisor (Coarse: JointPD, no switching on its own), then command.
    world.ndds(&["fsm", "send", "arm", "Coarse"]).ok();
    // No --reliable needed: the command goes through the runtime's port.
    let run = world.ndds(&["pub", "cs/arm/configure", "\"endptLQG\""]);
    assert!(run.success(), "{run}");
    assert!(
        run.stderr
            .contains("system `arm` switched to configuration `endptLQG`"),
        "{run}"
    );
    // Asking for the configuration it is in changes nothing, and says so.
    let run = world.ndds(&["pub", "cs/arm/configure", "\"endptLQG\""]);
    assert!(
        run.stderr
            .contains("system `arm` is in configuration `endptLQG` already; nothing changed"),
        "{run}"
    );
    for extra in [&[][..], &["--reliable"][..]] {
        let mut args = vec!["pub", "cs/arm/configure", "\"Bogus\""];
        args.extend_from_slice(extra);
        let run = world.ndds(&args);
        assert!(
            run.err()
                .contains("system `arm` has no configuration `Bogus`; it has: JointPD, endptLQG"),
            "{run}"
        );
    }
    // A bare word is a JSON string without its quotes.
    let run = world.ndds(&["pub", "cs/arm/configure", "JointPD"]);
    assert!(run.err().contains("write '\"JointPD\"'"), "{run}");
}

#[test]
fn samples_nobody_can_take_are_not_reported_as_published() {
    let world = World::start();
    let _arm = start_arm(&world);

    let run = world.ndds(&["pub", "arm/torque", "[1,2,3]"]);
    assert!(
        run.err().contains(
            "system `arm` subscribes `arm/torque` into CSMat `torque`, which is 2x1; this sample is 3x1"
        ),
        "{run}"
    );
    assert!(run.err().contains("nothing was sent"), "{run}");
    let run = world.ndds(&["pub", "arm/torque", "[0,0]"]);
    assert!(run.stderr.contains("to 1 consumer(s)"), "{run}");
    assert!(run.success(), "{run}");
    let run = world.ndds(&["pub", "--force", "arm/torque", "[1,2,3]"]);
    assert!(run.success(), "--force publishes anyway: {run}");

    let run = world.ndds(&[
        "pub",
        "--type",
        "f64",
        "--wait",
        "0.5",
        "nobody/listens",
        "1",
    ]);
    assert!(
        run.err()
            .contains("no consumer of \"nobody/listens\" matched within 500ms; nothing was sent"),
        "{run}"
    );
}

#[test]
fn a_second_copy_of_a_running_system_is_refused() {
    let world = World::start();
    let arm = start_arm(&world);
    let file = arm_file();
    let second = world
        .spawn(&["run", "--plain", "--seconds", "3", &file])
        .finish(SETTLE * 2);
    let err = second.err();
    assert!(
        err.contains("system `arm` already runs in this domain")
            && err.contains(&format!("(pid {})", arm.pid())),
        "{second}"
    );
    assert!(
        !second.stdout.contains("running"),
        "the copy must not start: {second}"
    );
    // Checking the file starts nothing, so the running copy does not refuse it.
    let check = world.ndds(&["run", "--check", &file]);
    assert!(check.success(), "{check}");
}

#[test]
fn a_domain_the_named_daemon_does_not_serve_is_an_error() {
    let world = World::start();
    let serves = world.config.domain;
    let other = if serves == 232 { 1 } else { serves + 1 };
    let run = world.ndds(&["--domain", &other.to_string(), "topics"]);
    assert!(
        run.err().contains(&format!(
            "--domain {other} was asked for, but the daemon at the socket given by --socket \
             serves domain {serves}"
        )),
        "{run}"
    );
    let run = world.ndds(&["--domain", &serves.to_string(), "topics"]);
    assert!(run.success(), "{run}");
}

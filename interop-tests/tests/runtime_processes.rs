//! The PD/LQG example across two processes under two daemons on loopback: the plant program
//! (`arm_plant`) under one, the controller program (`arm_controller`) under the other, both
//! exactly as users run them. The test watches the arm through ndds and switches the
//! controller's configuration over the network.

mod examples;

use examples::{WAIT, program, settles};
use interop_tests::{TestDomain, wait_until};
use ndds_client::{ConsumerQos, EmbeddedPolicy, Participant, ProducerQos, Reliability};
use ndds_runtime::{CsMat, HabitatStats};

#[test]
fn plant_and_controller_in_two_processes_close_the_loop_and_switch_over_the_network() {
    let domain = TestDomain::new();
    let _plant_host = domain.daemon("plant-host");
    let _control_host = domain.daemon("control-host");
    let _plant = program(&domain, "plant-host", "arm_plant");
    let _controller = program(&domain, "control-host", "arm_controller");

    let observer = Participant::builder()
        .socket(domain.socket("plant-host"))
        .embedded(EmbeddedPolicy::Never)
        .name("observer")
        .connect()
        .expect("observer connects");
    let qos = ConsumerQos {
        depth: 1024,
        ..ConsumerQos::default()
    };
    let tips = observer.consumer::<CsMat>("arm/tip", qos).unwrap();
    let stats = observer
        .consumer::<HabitatStats>("cs/arm-controller/control/stats", ConsumerQos::default())
        .unwrap();

    // JointPD: the PD controller settles at kp / (k + kp) of the 0.1 m reference.
    let pd_final = 0.1 * 400.0 / 404.0;
    assert!(
        settles(&tips, pd_final, 0.002),
        "JointPD never settled at {pd_final}"
    );

    let command = observer
        .producer::<String>(
            "cs/arm-controller/configure",
            ProducerQos {
                reliability: Reliability::Reliable { depth: 16 },
                ..ProducerQos::default()
            },
        )
        .unwrap();
    assert!(
        command.wait_for_consumers(1, WAIT),
        "the controller's command topic"
    );
    command.write(&"endptLQG".to_owned()).unwrap();

    // endptLQG: no steady-state error.
    assert!(settles(&tips, 0.1, 0.0005), "endptLQG never settled at 0.1");
    let mut last = None;
    let reported = wait_until(WAIT, || {
        while let Ok(sample) = stats.try_recv() {
            last = Some(sample.value);
        }
        last.as_ref()
            .is_some_and(|s| s.configuration == "endptLQG" && s.samples > 0)
    });
    let last = last.expect("habitat statistics arrive");
    assert!(
        reported.is_some(),
        "statistics never showed endptLQG: {last:?}"
    );
    assert_eq!(last.runtime, "arm-controller");
    assert_eq!(last.habitat, "control");
    assert!((last.rate_hz - 200.0).abs() < 1e-6, "{last:?}");
    assert!(last.running && last.period_jitter.count > 0, "{last:?}");
}

//! A consumer whose type differs from its topic's producer learns why from its timeout error:
//! the producers not matched and both types, by their short names and shapes.

mod common;

use std::time::Duration;

use common::{eventually, participant, unique_config};
use ndds_client::{ConsumerQos, Mismatch, ProducerQos, RecvError, Unmatched};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

const WAIT: Duration = Duration::from_secs(5);

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct Pose {
    x: f64,
    y: f64,
}

/// The same shape as [`Pose`] under another name: another type.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct PoseMsg {
    x: f64,
    y: f64,
}

mod with_z {
    /// `Pose` with an extra field.
    #[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
    pub struct Pose {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }
}

/// A producer of `P` and a consumer of `C` on one topic; returns the consumer's timeout error,
/// with the producer writing meanwhile.
fn timeout_error<P, C>(value: P) -> (Unmatched, String)
where
    P: Serialize + DeserializeOwned,
    C: Serialize + DeserializeOwned + std::fmt::Debug,
{
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let producer = p.producer::<P>("arm/pose", ProducerQos::default()).unwrap();
    let consumer = p.consumer::<C>("arm/pose", ConsumerQos::default()).unwrap();
    assert!(eventually(WAIT, || !consumer.incompatible().is_empty()));
    producer.write(&value).unwrap();
    let err = consumer.recv_timeout(Duration::from_secs(1)).unwrap_err();
    let text = err.to_string();
    match err {
        RecvError::TimeoutUnmatched(unmatched) => (*unmatched, text),
        other => panic!("expected TimeoutUnmatched, got {other:?}"),
    }
}

fn type_names(unmatched: &Unmatched) -> (String, String) {
    assert_eq!(unmatched.producers.len(), 1, "{unmatched:?}");
    assert_eq!(unmatched.producers[0].pid, std::process::id());
    match &unmatched.producers[0].mismatch {
        Mismatch::Type { consumer, producer } => (consumer.shape(), producer.shape()),
        other => panic!("expected a type mismatch, got {other:?}"),
    }
}

#[test]
fn another_struct_name_of_the_same_shape_is_named_in_the_timeout() {
    let (unmatched, text) = timeout_error::<Pose, PoseMsg>(Pose::default());
    assert_eq!(unmatched.topic, "arm/pose");
    assert_eq!(unmatched.waited, Duration::from_secs(1));
    assert_eq!(
        type_names(&unmatched),
        (
            "PoseMsg{x: f64, y: f64}".into(),
            "Pose{x: f64, y: f64}".into()
        )
    );
    assert!(
        text.starts_with(
            "timed out after 1 s waiting for a sample on `arm/pose`: 1 producer not matched: \
             type PoseMsg{x: f64, y: f64} vs Pose{x: f64, y: f64}"
        ),
        "{text}"
    );
    assert!(!text.contains("::"), "short names only: {text}");
}

#[test]
fn f32_against_f64_is_named_in_the_timeout() {
    let (unmatched, text) = timeout_error::<f64, f32>(1.5);
    assert_eq!(type_names(&unmatched), ("f32".into(), "f64".into()));
    assert!(text.contains("type f32 vs f64"), "{text}");
}

#[test]
fn an_extra_field_is_visible_in_the_timeout() {
    let (unmatched, text) = timeout_error::<Pose, with_z::Pose>(Pose::default());
    assert_eq!(
        type_names(&unmatched),
        (
            "Pose{x: f64, y: f64, z: f64}".into(),
            "Pose{x: f64, y: f64}".into()
        )
    );
    assert!(
        text.contains("type Pose{x: f64, y: f64, z: f64} vs Pose{x: f64, y: f64}"),
        "{text}"
    );
    assert!(!text.contains("type_mismatch::"), "no module paths: {text}");
}

#[test]
fn a_plain_timeout_stays_a_plain_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let config = unique_config(dir.path(), "a");
    let p = participant(&config);
    let consumer = p
        .consumer::<Pose>("arm/pose", ConsumerQos::default())
        .unwrap();
    let err = consumer
        .recv_timeout(Duration::from_millis(100))
        .unwrap_err();
    assert_eq!(err, RecvError::Timeout);
    assert!(err.is_timeout());
}

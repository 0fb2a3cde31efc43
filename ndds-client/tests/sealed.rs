//! A sealed domain in the SDK: participants given the domain's key (here through their
//! embedded daemon's configuration) seal their data and exchange samples; a participant of
//! the same daemon without the key matches but receives nothing it could read; a key file
//! that others may read is refused with its own error.

mod common;

use std::os::unix::fs::PermissionsExt as _;
use std::time::Duration;

use common::{participant, unique_config};
use ndds_client::{ConnectError, ConsumerQos, EmbeddedPolicy, Participant, ProducerQos};
use ndds_core::seal::{DomainKey, Keyring};

const WAIT: Duration = Duration::from_secs(5);

#[test]
fn key_holders_exchange_samples_and_a_participant_without_the_key_reads_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = unique_config(dir.path(), "sealed");
    config.key = Some(Keyring::new(1, DomainKey::from_bytes([3; 32])));
    let (writer_side, reader_side) = (participant(&config), participant(&config));
    let outsider = Participant::builder()
        .socket(&config.socket)
        .embedded(EmbeddedPolicy::Never)
        .connect()
        .unwrap();
    let producer = writer_side
        .producer::<u64>("sealed/value", ProducerQos::default())
        .unwrap();
    let inside = reader_side
        .consumer::<u64>("sealed/value", ConsumerQos::default())
        .unwrap();
    let outside = outsider
        .consumer::<u64>("sealed/value", ConsumerQos::default())
        .unwrap();
    assert!(producer.wait_for_consumers(2, WAIT), "both consumers match");
    for value in 0..20u64 {
        producer.write(&value).unwrap();
    }
    // Every one, intact: datagrams received into one buffer are opened in place side by side.
    let values: Vec<u64> = (0..20)
        .map(|_| {
            inside
                .recv_timeout(WAIT)
                .expect("a sealed sample arrives")
                .value
        })
        .collect();
    assert_eq!(values, (0..20).collect::<Vec<u64>>());
    assert!(outside.recv_timeout(Duration::from_millis(500)).is_err());
    assert!(outsider.stats().received > 0, "the datagrams reached it");
    assert_eq!(outside.stats().received, 0, "and none was read as a sample");
    // Each side counts what it could and could not open.
    let (outsider_stats, reader_stats) = (outsider.stats(), reader_side.stats());
    assert!(outsider_stats.sealed_without_key > 0, "{outsider_stats:?}");
    assert_eq!(outsider_stats.seal_opened, 0);
    assert!(reader_stats.seal_opened >= 20, "{reader_stats:?}");
    assert_eq!(reader_stats.seal_dropped("bad_tag"), 0);
    assert!(writer_side.stats().unsealable == 0);
}

#[test]
fn a_key_file_that_others_may_read_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("domain.key");
    std::fs::write(
        &path,
        Keyring::new(1, DomainKey::from_bytes([4; 32])).to_file_text(),
    )
    .unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
    let config = unique_config(dir.path(), "exposed");
    let err = Participant::builder()
        .embedded_config(config)
        .key_file(&path)
        .connect()
        .unwrap_err();
    assert!(matches!(err, ConnectError::KeyFile(_)), "{err}");
    assert!(err.to_string().contains("chmod 600"), "{err}");
}

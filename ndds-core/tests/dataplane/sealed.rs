//! Sealed domains: participants that share the domain key exchange reliable streams through
//! loss, reordering and duplication exactly as unsealed ones do, with every duplicate refused
//! by the replay window before the data plane sees it; a participant with another key, or
//! none, neither reads nor writes their topics, and each side counts why.

use std::time::Duration;

use ndds_core::participant::{CoreStats, Event, SealSetup};
use ndds_core::seal::{DomainKey, Keyring, OpenError, SealMode};

use crate::sim::{App, Link, MTU, SimNet, WriterApp, exactly, guid};
use crate::{MS, reliable_consumer, reliable_producer};

fn setup(key: u8, session: u64, mode: SealMode) -> SealSetup {
    SealSetup {
        keyring: Keyring::new(1, DomainKey::from_bytes([key; 32])),
        mode,
        session,
        require_encryption: false,
    }
}

fn stats(net: &SimNet, node: usize) -> CoreStats {
    net.nodes[node].core.stats()
}

/// Nodes 0 and 1 sealed with the domain key and requiring data keys (a domain with
/// permissions).
fn pairwise(seed: u64) -> SimNet {
    let mut net = SimNet::new(seed, 2);
    for node in 0..2 {
        net.nodes[node]
            .core
            .seal_with(setup(7, 1, SealMode::Encrypt));
        assert!(net.nodes[node].core.require_pair_keys());
    }
    net
}

/// Gives nodes 0 and 1 the data keys of their pair, from `shared`, as their daemons would.
fn install_pair_keys(net: &mut SimNet, shared: u8) {
    use crate::sim::{locator, participant_id};
    use ndds_core::security::DataKeys;
    let now = net.now;
    for (a, b) in [(0, 1), (1, 0)] {
        let keys = DataKeys::derive(&[shared; 32], participant_id(a), participant_id(b));
        assert!(
            net.nodes[a]
                .core
                .set_pair_keys(now, participant_id(b), locator(b), &keys)
        );
    }
}

#[test]
fn sealed_reliable_streams_are_whole_through_loss_reordering_and_duplicates() {
    for mode in [SealMode::Encrypt, SealMode::IntegrityOnly] {
        let mut net = SimNet::new(41, 3);
        for node in 0..3 {
            net.nodes[node]
                .core
                .seal_with(setup(7, 1000 + node as u64, mode));
        }
        net.link = Link {
            latency: MS,
            jitter: MS * 3,
            loss: 0.1,
            duplicate: 0.1,
        };
        net.add_producer(0, 1, reliable_producer(32));
        for node in 1..3 {
            net.add_consumer(node, 10, reliable_consumer(None), App::Eager);
            net.connect((0, 1), (node, 10));
        }
        let total = 300;
        let mut writer = WriterApp::new(0, 1, total, Duration::from_micros(300), 0);
        // Whole samples and samples in pieces.
        writer.sizes = vec![100, 3000];
        net.add_writer(writer);
        let all = |n: &SimNet| (1..3).all(|c| n.consumer(c, 10).got.len() as u64 >= total);
        assert!(
            net.run_until(net.at_ms(60_000), all),
            "{mode:?}: {:?}",
            net.stats
        );
        for node in 1..3 {
            let log = net.consumer(node, 10);
            assert_eq!(
                exactly(&log.seqs_from(guid(0, 1)), 1, total),
                Ok(()),
                "{mode:?}"
            );
            assert!(log.got.iter().all(|g| g.intact), "{mode:?}");
            assert_eq!(log.lost(), vec![], "{mode:?}");
        }
        // Sealed datagrams still fit the path.
        assert!(net.stats.largest <= MTU, "{mode:?}: {}", net.stats.largest);
        assert_eq!(net.stats.too_big, 0);
        for node in 0..3 {
            let seal = stats(&net, node).seal;
            assert!(seal.opened > 0, "{mode:?}: node {node}: {seal:?}");
            // Duplicated datagrams: refused by the window, never seen by the data plane.
            assert!(
                seal.dropped(OpenError::Replayed) > 0,
                "{mode:?}: node {node}: {seal:?}"
            );
            assert_eq!(seal.dropped(OpenError::BadTag), 0, "{mode:?}: node {node}");
        }
    }
}

#[test]
fn a_participant_with_another_key_or_none_reads_and_writes_nothing() {
    // Node 0 produces; node 1 (the right key) consumes; node 2 holds another key and node 3
    // none, both matched as if discovery had let them in.
    let mut net = SimNet::new(5, 4);
    net.nodes[0].core.seal_with(setup(7, 1, SealMode::Encrypt));
    net.nodes[1].core.seal_with(setup(7, 1, SealMode::Encrypt));
    net.nodes[2].core.seal_with(setup(8, 1, SealMode::Encrypt));
    net.add_producer(0, 1, reliable_producer(16));
    for node in 1..4 {
        net.add_consumer(node, 10, reliable_consumer(None), App::Eager);
        net.connect((0, 1), (node, 10));
    }
    // The outsiders also produce on the topic, towards node 1.
    for node in 2..4 {
        net.add_producer(node, 2, reliable_producer(16));
        net.connect((node, 2), (1, 10));
        net.add_writer(WriterApp::new(node, 2, 50, MS, 0));
    }
    let total = 100;
    net.add_writer(WriterApp::new(0, 1, total, MS, 0));
    net.run_for(Duration::from_secs(5));
    let good = net.consumer(1, 10);
    assert_eq!(exactly(&good.seqs_from(guid(0, 1)), 1, total), Ok(()));
    assert!(good.seqs_from(guid(2, 2)).is_empty());
    assert!(good.seqs_from(guid(3, 2)).is_empty());
    assert!(net.consumer(2, 10).got.is_empty());
    assert!(net.consumer(3, 10).got.is_empty());
    // Node 1 refused both: a tag that does not verify, and datagrams not sealed at all.
    let at_good = stats(&net, 1).seal;
    assert!(at_good.dropped(OpenError::BadTag) > 0, "{at_good:?}");
    assert!(at_good.dropped(OpenError::NotSealed) > 0, "{at_good:?}");
    assert!(stats(&net, 2).seal.dropped(OpenError::BadTag) > 0);
    assert!(stats(&net, 3).sealed_without_key > 0);
    // The outsiders could not open a heartbeat, so they never answered: the producer took
    // them for silent readers and let them go from its window (delivery to node 1 went on).
    let silenced: Vec<_> = net.nodes[0]
        .producer_events
        .iter()
        .filter_map(|(_, event)| match event {
            Event::ReaderSilenced { reader, .. } => Some(*reader),
            _ => None,
        })
        .collect();
    assert!(silenced.contains(&guid(2, 10)), "{silenced:?}");
    assert!(silenced.contains(&guid(3, 10)), "{silenced:?}");
    assert!(!silenced.contains(&guid(1, 10)), "{silenced:?}");
}

/// Data keys of a domain with permissions: the pair of nodes 0 and 1 holds keys from their
/// daemons; node 2 holds the domain key too, is even matched both ways (as if discovery had
/// let it in), and ignores the rule (it seals with the domain key, as in a domain without
/// permissions), but no daemon gave it keys. Nothing of the pair reaches it, nothing it sends
/// is opened, and a datagram it seals with the domain key in node 0's name fails its tag.
#[test]
fn with_data_keys_a_host_with_only_the_domain_key_reads_and_writes_nothing() {
    use crate::sim::{locator, participant_id};
    use ndds_core::security::DataKeys;
    let mut net = SimNet::new(9, 3);
    for node in 0..3 {
        net.nodes[node]
            .core
            .seal_with(setup(7, 1, SealMode::Encrypt));
    }
    for node in 0..2 {
        assert!(net.nodes[node].core.require_pair_keys());
    }
    let shared = [42u8; 32];
    let now = net.now;
    for (a, b) in [(0, 1), (1, 0)] {
        let keys = DataKeys::derive(&shared, participant_id(a), participant_id(b));
        assert!(
            net.nodes[a]
                .core
                .set_pair_keys(now, participant_id(b), locator(b), &keys)
        );
    }
    net.add_producer(0, 1, reliable_producer(16));
    net.add_producer(2, 2, reliable_producer(16));
    for node in 1..3 {
        net.add_consumer(node, 10, reliable_consumer(None), App::Eager);
        net.connect((0, 1), (node, 10));
    }
    net.connect((2, 2), (1, 10));
    let total = 100;
    net.add_writer(WriterApp::new(0, 1, total, MS, 0));
    net.add_writer(WriterApp::new(2, 2, 50, MS, 0));
    net.run_for(Duration::from_secs(3));
    // Node 2 forges a datagram in node 0's name, sealed with the domain key.
    let mut forged = Vec::new();
    ndds_core::wire::Header {
        kind: ndds_core::wire::MessageKind::Data,
        domain: net.nodes[0].core.config().domain,
        sender: participant_id(0),
    }
    .emit(&mut forged);
    forged.extend_from_slice(&[0u8; 24]);
    ndds_core::seal::Sealer::new(
        &setup(7, 9, SealMode::Encrypt).keyring,
        net.nodes[0].core.config().domain,
        participant_id(0),
        9,
        SealMode::Encrypt,
    )
    .seal(&mut forged)
    .unwrap();
    net.inject(locator(0), 1, forged);
    net.run_for(Duration::from_millis(100));

    let good = net.consumer(1, 10);
    assert_eq!(exactly(&good.seqs_from(guid(0, 1)), 1, total), Ok(()));
    assert!(
        good.seqs_from(guid(2, 2)).is_empty(),
        "node 2 wrote to node 1"
    );
    assert!(net.consumer(2, 10).got.is_empty(), "node 2 read node 0");
    // Node 0 sent node 2 nothing; node 1 opened nothing of node 2's, and not the forgery.
    assert!(stats(&net, 0).unkeyed > 0, "{:?}", stats(&net, 0));
    let at_one = stats(&net, 1).seal;
    assert!(at_one.dropped(OpenError::Unkeyed) > 0, "{at_one:?}");
    assert_eq!(at_one.dropped(OpenError::BadTag), 1, "{at_one:?}");
    assert!(at_one.opened > 0);
}

/// The daemon gives a pair's keys again with every match of the pair: a second install keeps
/// the sealer and its counter (a new one at counter 0 would reuse nonces under the same key)
/// and the receiver's replay window, so the stream goes on whole and nothing is refused.
#[test]
fn data_keys_given_again_reuse_no_nonce() {
    let mut net = pairwise(10);
    install_pair_keys(&mut net, 5);
    net.add_producer(0, 1, reliable_producer(16));
    net.add_consumer(1, 10, reliable_consumer(None), App::Eager);
    net.connect((0, 1), (1, 10));
    let total = 200;
    net.add_writer(WriterApp::new(0, 1, total, MS, 0));
    net.run_for(Duration::from_millis(80));
    install_pair_keys(&mut net, 5);
    net.run_for(Duration::from_secs(3));
    let log = net.consumer(1, 10);
    assert_eq!(exactly(&log.seqs_from(guid(0, 1)), 1, total), Ok(()));
    let seal = stats(&net, 1).seal;
    assert_eq!(seal.dropped(OpenError::Replayed), 0, "{seal:?}");
    assert_eq!(seal.dropped(OpenError::BadTag), 0, "{seal:?}");
}

/// A pair unmatched for [`PAIR_KEY_IDLE`] loses its keys on both sides (the tables shrink);
/// given again with a new match, they seal for a new session: no (key, session, counter) is
/// ever sent twice, the receiver refuses nothing, and the stream goes on.
#[test]
fn data_keys_of_a_pair_long_unmatched_are_dropped_and_given_again_without_reusing_a_nonce() {
    use ndds_core::participant::PAIR_KEY_IDLE;
    let mut net = pairwise(11);
    net.tap = Some(Vec::new());
    install_pair_keys(&mut net, 6);
    net.add_producer(0, 1, reliable_producer(16));
    net.add_consumer(1, 10, reliable_consumer(None), App::Eager);
    net.connect((0, 1), (1, 10));
    net.add_writer(WriterApp::new(0, 1, 50, MS, 0));
    net.run_for(Duration::from_secs(1));
    assert_eq!(
        exactly(&net.consumer(1, 10).seqs_from(guid(0, 1)), 1, 50),
        Ok(())
    );
    // Matched for a while longer: the keys stay.
    net.run_for(PAIR_KEY_IDLE + Duration::from_secs(40));
    assert_eq!(net.nodes[0].core.pair_peers(), 1);
    net.disconnect((0, 1), (1, 10));
    net.run_for(PAIR_KEY_IDLE - Duration::from_secs(30));
    assert_eq!(
        net.nodes[0].core.pair_peers(),
        1,
        "dropped before PAIR_KEY_IDLE"
    );
    net.run_for(Duration::from_secs(70));
    for node in 0..2 {
        assert_eq!(
            net.nodes[node].core.pair_peers(),
            0,
            "node {node} kept its keys"
        );
    }
    // Matched again: the daemon gives the same keys again.
    // (Another producer of node 0: the pair is the same pair of participants.)
    install_pair_keys(&mut net, 6);
    net.add_producer(0, 2, reliable_producer(16));
    net.connect((0, 2), (1, 10));
    net.add_writer(WriterApp::new(0, 2, 50, MS, 0));
    net.run_for(Duration::from_secs(2));
    assert_eq!(
        exactly(&net.consumer(1, 10).seqs_from(guid(0, 2)), 1, 50),
        Ok(())
    );
    let seal = stats(&net, 1).seal;
    assert_eq!(seal.dropped(OpenError::Replayed), 0, "{seal:?}");
    assert_eq!(seal.dropped(OpenError::BadTag), 0, "{seal:?}");
    // Every sealed datagram's (sender, destination, session, counter) once: its nonce under
    // the pair's key was never used again.
    let mut nonces = std::collections::HashSet::new();
    let tap = net.tap.take().unwrap();
    for (from, to, bytes) in &tap {
        let session = u64::from_le_bytes(bytes[20..28].try_into().unwrap());
        let counter = u64::from_le_bytes(bytes[28..36].try_into().unwrap());
        assert!(
            nonces.insert((*from, *to, session, counter)),
            "node {from} sealed counter {counter} of session {session} for {to} twice"
        );
    }
    assert!(tap.len() > 100, "{} datagrams", tap.len());
}

/// A rotation of the domain key keeps what was opened from senders with data keys: a
/// datagram of the pair recorded before the rotation, replayed after it, is refused.
#[test]
fn a_domain_key_rotation_keeps_the_replay_windows_of_pairs() {
    use crate::sim::locator;
    let mut net = pairwise(12);
    net.tap = Some(Vec::new());
    install_pair_keys(&mut net, 8);
    net.add_producer(0, 1, reliable_producer(16));
    net.add_consumer(1, 10, reliable_consumer(None), App::Eager);
    net.connect((0, 1), (1, 10));
    net.add_writer(WriterApp::new(0, 1, 20, MS, 0));
    net.run_for(Duration::from_secs(1));
    assert_eq!(
        exactly(&net.consumer(1, 10).seqs_from(guid(0, 1)), 1, 20),
        Ok(())
    );
    let recorded: Vec<Vec<u8>> = net
        .tap
        .take()
        .unwrap()
        .into_iter()
        .filter(|(from, to, _)| *from == 0 && *to == locator(1))
        .map(|(_, _, bytes)| bytes.to_vec())
        .collect();
    // (What was still in flight arrives first.)
    net.run_for(Duration::from_millis(100));
    // Both rotate to epoch 2, the old epoch no longer accepted.
    for node in 0..2 {
        net.nodes[node]
            .core
            .set_keyring(Keyring::new(2, DomainKey::from_bytes([9; 32])));
    }
    let before = stats(&net, 1).seal;
    for bytes in &recorded {
        net.inject(locator(0), 1, bytes.clone());
    }
    net.run_for(Duration::from_millis(100));
    let after = stats(&net, 1).seal;
    assert_eq!(
        after.opened, before.opened,
        "a recorded datagram opened again"
    );
    assert_eq!(
        after.dropped(OpenError::Replayed) - before.dropped(OpenError::Replayed),
        recorded.len() as u64
    );
    assert_eq!(
        exactly(&net.consumer(1, 10).seqs_from(guid(0, 1)), 1, 20),
        Ok(())
    );
}

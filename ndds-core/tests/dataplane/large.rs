//! Samples larger than a datagram: cut into pieces at the MTU, the missing pieces asked for
//! (`NackFrag`) and resent; a best-effort consumer repairs only the newest sample
//! (last-is-best), a reliable one every sample.

use std::time::Duration;

use ndds_core::arbitration::Rules;

use crate::sim::{App, Link, MTU, SimNet, WriterApp, exactly, guid};
use crate::{MS, best_effort_consumer, best_effort_producer, reliable_consumer, reliable_producer};

/// 20 000 B: 18 pieces at a 1200 B MTU.
const LARGE: usize = 20_000;

fn best_effort_large(net: &mut SimNet, loss: f64, total: u64, interval: Duration) -> usize {
    net.set_link(0, 1, Link::lossy(loss));
    net.add_producer(0, 1, best_effort_producer(0, Duration::ZERO));
    net.add_consumer(1, 2, best_effort_consumer(Rules::default()), App::Eager);
    net.connect((0, 1), (1, 2));
    net.add_writer(WriterApp::new(0, 1, total, interval, LARGE))
}

#[test]
fn best_effort_large_samples_are_repaired_piece_by_piece() {
    // 10 % loss: without repair 0.9^18, 15 % of the samples would be whole. Written every
    // 50 ms, each is the newest long enough to be repaired.
    let mut net = SimNet::new(21, 2);
    best_effort_large(&mut net, 0.1, 40, 50 * MS);
    net.run_until(net.at_ms(3_000), |_| false);
    let log = net.consumer(1, 2);
    let seqs = log.seqs_from(guid(0, 1));
    assert!(seqs.len() >= 38, "{} of 40 whole: {seqs:?}", seqs.len());
    assert!(seqs.windows(2).all(|w| w[0] < w[1]));
    assert!(log.got.iter().all(|g| g.intact && g.len == LARGE));
    // The consumer's requests reached the producer, and its answers stayed within the MTU.
    assert!(net.nodes[0].core.stats().received > 0);
    assert!(net.stats.largest <= MTU);
    assert_eq!(net.stats.too_big, 0);
}

#[test]
fn only_the_newest_best_effort_large_sample_is_repaired() {
    // A large sample every 2 ms, faster than a repair round (5 ms before asking): a sample
    // still incomplete when a newer one starts is given up, so what arrives is increasing,
    // and the last one, newest when the writer stops, is repaired and delivered.
    let mut net = SimNet::new(22, 2);
    best_effort_large(&mut net, 0.15, 30, 2 * MS);
    net.run_until(net.at_ms(2_000), |_| false);
    let log = net.consumer(1, 2);
    let seqs = log.seqs_from(guid(0, 1));
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
    assert_eq!(seqs.last(), Some(&30), "{seqs:?}");
    assert!(log.got.iter().all(|g| g.intact));
    // Older partial samples were given up, not all repaired.
    assert!(seqs.len() < 30, "{seqs:?}");
}

#[test]
fn reliable_large_samples_cross_heavy_loss_whole_and_in_order() {
    // 200 KB samples (about 180 pieces, repaired piece by piece rather than resent whole)
    // and 3 KB ones, alternating, over 20 % loss with reordering.
    let mut net = SimNet::new(23, 2);
    net.set_link(
        0,
        1,
        Link {
            jitter: 2 * MS,
            ..Link::lossy(0.2)
        },
    );
    net.add_producer(0, 1, reliable_producer(16));
    net.add_consumer(1, 2, reliable_consumer(Some(16)), App::Eager);
    net.connect((0, 1), (1, 2));
    let mut writer = WriterApp::new(0, 1, 12, 5 * MS, 0);
    writer.sizes = vec![200_000, 3_000];
    net.add_writer(writer);
    let done = net.run_until(net.at_ms(30_000), |n| n.consumer(1, 2).got.len() == 12);
    assert!(done, "{:?} at {:?}", net.stats, net.elapsed());
    let log = net.consumer(1, 2);
    assert_eq!(exactly(&log.seqs_from(guid(0, 1)), 1, 12), Ok(()));
    assert!(log.got.iter().all(|g| g.intact));
    assert_eq!(log.lost(), vec![]);
    assert!(net.stats.largest <= MTU);
}

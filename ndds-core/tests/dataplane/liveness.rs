//! A reliable reader that never acknowledges (its acknowledgements never reach the
//! producer, or its host froze) holds the producer's window only until the reader liveness:
//! then it is reported (`Event::ReaderSilenced`), the window opens (`Event::WindowOpen`) and
//! the writer goes back to its normal pace; the healthy reader loses nothing.

use std::time::Duration;

use ndds_core::participant::Event;
use ndds_core::reliability::WriterConfig;

use crate::sim::{App, SimNet, WriterApp, exactly, guid};
use crate::{MS, reliable_consumer, reliable_producer_with};

const PRODUCER: (usize, u32) = (0, 1);
const HEALTHY: (usize, u32) = (1, 2);
const SILENT: (usize, u32) = (2, 2);
const LIVENESS: Duration = Duration::from_millis(300);
const TOTAL: u64 = 500;

/// A producer writing to a healthy and a soon silent reader (`silence` makes it so at
/// 100 ms), run until the healthy one has everything.
fn run(silence: impl FnOnce(&mut SimNet)) -> SimNet {
    let mut net = SimNet::new(71, 3);
    let config = WriterConfig {
        depth: 16,
        reader_liveness: Some(LIVENESS),
        ..WriterConfig::default()
    };
    net.add_producer(PRODUCER.0, PRODUCER.1, reliable_producer_with(config));
    for c in [HEALTHY, SILENT] {
        net.add_consumer(c.0, c.1, reliable_consumer(Some(64)), App::Eager);
        net.connect(PRODUCER, c);
    }
    net.add_writer(WriterApp::new(PRODUCER.0, PRODUCER.1, TOTAL, 2 * MS, 200));
    net.run_until(net.at_ms(100), |_| false);
    silence(&mut net);
    let done = net.run_until(net.at_ms(10_000), |n| {
        n.consumer(HEALTHY.0, HEALTHY.1).got.len() as u64 == TOTAL
    });
    assert!(done, "{:?}", net.stats);
    net
}

/// The producer blocked once, for at most the liveness and a few heartbeat periods, and
/// reported the silent reader; the healthy one got everything.
fn assert_silenced_within_the_liveness(net: &SimNet) {
    let events = &net.nodes[PRODUCER.0].producer_events;
    let silenced: Vec<Duration> = events
        .iter()
        .filter(|(_, e)| {
            *e == Event::ReaderSilenced {
                producer: PRODUCER.1,
                reader: guid(SILENT.0, SILENT.1),
            }
        })
        .map(|(at, _)| *at)
        .collect();
    assert_eq!(silenced.len(), 1, "{events:?}");
    let writer = &net.writers[0];
    // The window closed once, about 16 samples after the reader went silent, and opened
    // again within the liveness (counted from its last acknowledgement) plus a heartbeat
    // period.
    assert_eq!(writer.blocked.len(), 1, "{:?}", writer.blocked);
    let (closed, opened) = writer.blocked[0];
    assert!(
        opened - closed <= LIVENESS,
        "blocked {closed:?}..{opened:?}"
    );
    assert!(
        opened <= 100 * MS + LIVENESS + 25 * MS,
        "opened at {opened:?}"
    );
    assert!(opened >= silenced[0]);
    assert!(events.iter().any(|(at, e)| *at == opened
        && *e
            == Event::WindowOpen {
                producer: PRODUCER.1
            }));
    // Then it wrote at its own pace: 500 samples every 2 ms, delayed only by the block.
    let last = *writer.written_at.last().expect("wrote");
    assert!(
        last <= 998 * MS + (opened - closed) + 2 * MS,
        "last write at {last:?}"
    );
    let healthy = net.consumer(HEALTHY.0, HEALTHY.1);
    assert_eq!(
        exactly(&healthy.seqs_from(guid(PRODUCER.0, PRODUCER.1)), 1, TOTAL),
        Ok(())
    );
    assert_eq!(healthy.lost(), vec![]);
}

#[test]
fn a_reader_whose_acknowledgements_never_arrive_is_silenced_within_the_liveness() {
    let net = run(|net| net.cut_one_way(SILENT.0, PRODUCER.0));
    assert_silenced_within_the_liveness(&net);
    // It still received everything sent to everyone, and nothing of it was evicted before
    // it arrived: it lost nothing either.
    let silent = net.consumer(SILENT.0, SILENT.1);
    assert_eq!(
        exactly(&silent.seqs_from(guid(PRODUCER.0, PRODUCER.1)), 1, TOTAL),
        Ok(())
    );
}

#[test]
fn a_frozen_reader_is_silenced_within_the_liveness_and_learns_its_loss_when_back() {
    let mut net = run(|net| net.down(SILENT.0));
    assert_silenced_within_the_liveness(&net);
    // Back, it acknowledges again, learns what the history no longer holds as lost, and
    // gets what follows.
    net.up(SILENT.0);
    net.writers[0].total = TOTAL + 10;
    let done = net.run_until(net.at_ms(20_000), |n| {
        n.consumer(SILENT.0, SILENT.1)
            .got
            .last()
            .is_some_and(|g| g.seq == TOTAL + 10)
    });
    assert!(done, "{:?}", net.stats);
    let silent = net.consumer(SILENT.0, SILENT.1);
    let stream = crate::sim::stream_of(silent, guid(PRODUCER.0, PRODUCER.1));
    let lost = crate::sim::covers(&stream, 1, TOTAL + 10).expect("each seq once, in order");
    assert_eq!(lost.len(), 1, "{lost:?}");
    let healthy = net.consumer(HEALTHY.0, HEALTHY.1);
    assert_eq!(
        exactly(
            &healthy.seqs_from(guid(PRODUCER.0, PRODUCER.1)),
            1,
            TOTAL + 10
        ),
        Ok(())
    );
}

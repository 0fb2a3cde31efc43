//! Reliable streams over a simulated link (see `sim.rs`): complete, ordered, duplicate-free
//! delivery under random loss, outages, reordering and duplication; exactly the unrepairable
//! range reported lost when the history is too short; flow control by a slow reader; a dead
//! reader removed; late joiners; and resends in proportion to losses. All in virtual time.

mod sim;

use std::time::Duration;

use ndds_core::reliability::{ReaderConfig, WriterConfig};
use proptest::prelude::*;

use sim::{Consumer, Link, Producer, Sim, check_stream};

const MS: Duration = Duration::from_millis(1);

fn writer_config(depth: usize) -> WriterConfig {
    WriterConfig {
        depth,
        ..WriterConfig::default()
    }
}

fn reader_config(depth: usize) -> ReaderConfig {
    ReaderConfig {
        depth,
        ..ReaderConfig::default()
    }
}

fn producer(total: u64, interval: Duration, respect_window: bool) -> Producer {
    Producer {
        total,
        interval,
        respect_window,
        bytes: 100,
    }
}

/// Random link faults: loss, jitter, duplication, and maybe an outage.
fn link() -> impl Strategy<Value = Link> {
    (
        0.0..0.3f64,
        0u64..6,
        0.0..0.1f64,
        proptest::option::of((0u64..300, 0u64..200)),
    )
        .prop_map(|(loss, jitter_ms, duplicate, outage)| Link {
            latency: MS,
            jitter: MS * jitter_ms as u32,
            loss,
            duplicate,
            outages: outage
                .map(|(at, len)| (MS * at as u32, MS * (at + len) as u32))
                .into_iter()
                .collect(),
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// A writer that respects its window never evicts what a reader needs: every reader gets
    /// every sample exactly once, in order, nothing reported lost, whatever the faults.
    #[test]
    fn every_reader_gets_every_sample_once_in_order(
        seed in any::<u64>(),
        links in proptest::collection::vec(link(), 1..4),
        depth in 4usize..64,
        reader_depth in 4usize..64,
        total in 50u64..300,
        interval_us in 0u64..2000,
    ) {
        let interval = Duration::from_micros(interval_us);
        let mut sim = Sim::new(seed, writer_config(depth), producer(total, interval, true));
        for link in links {
            let key = sim.add_node(reader_config(reader_depth), link, Consumer::Eager);
            sim.attach(key);
        }
        let deadline = sim.at_ms(120_000);
        sim.run_until(deadline, Sim::done);
        for (key, node) in sim.nodes.iter().enumerate() {
            let lost = check_stream(&node.got, 1, total);
            prop_assert_eq!(lost, Ok(vec![]), "reader {} {:?}", key, node.reader.stats());
            prop_assert_eq!(node.reader.stats().delivered, total);
        }
        prop_assert!(sim.max_history <= depth);
        prop_assert!(sim.max_buffered <= reader_depth);
    }

    /// A writer that writes past its window (its timeout expired) evicts samples: each
    /// reader still gets every seq once, in order, either as a sample or inside one merged
    /// `Lost` range, and only seqs the writer declared gone are reported lost.
    #[test]
    fn an_overflowing_history_reports_exactly_the_unrepairable_seqs(
        seed in any::<u64>(),
        links in proptest::collection::vec(link(), 1..3),
        depth in 2usize..16,
        total in 50u64..300,
        interval_us in 100u64..1000,
    ) {
        let interval = Duration::from_micros(interval_us);
        let mut sim = Sim::new(seed, writer_config(depth), producer(total, interval, false));
        for link in links {
            let key = sim.add_node(reader_config(64), link, Consumer::Eager);
            sim.attach(key);
        }
        let deadline = sim.at_ms(120_000);
        sim.run_until(deadline, Sim::done);
        for (key, node) in sim.nodes.iter().enumerate() {
            let lost = check_stream(&node.got, 1, total);
            prop_assert!(lost.is_ok(), "reader {}: {:?}", key, lost);
            for (from, to) in lost.unwrap() {
                for seq in from..to {
                    prop_assert!(
                        node.told_gone.iter().any(|&(a, b)| a <= seq && seq < b),
                        "reader {} reports {} lost, never declared gone", key, seq
                    );
                }
            }
        }
        prop_assert!(sim.max_history <= depth);
    }

    /// A reader matched while samples flow, over a faulty link, gets exactly the samples
    /// written from then on.
    #[test]
    fn a_late_joiner_gets_exactly_what_follows_its_match(
        seed in any::<u64>(),
        early in link(),
        late in link(),
        join_at in 1u64..200,
        total in 200u64..300,
    ) {
        let mut sim = Sim::new(seed, writer_config(32), producer(join_at - 1, MS / 2, true));
        let first = sim.add_node(reader_config(32), early, Consumer::Eager);
        sim.attach(first);
        let deadline = sim.at_ms(120_000);
        sim.run_until(deadline, |s| s.next_seq == join_at);
        let second = sim.add_node(reader_config(32), late, Consumer::Eager);
        sim.attach(second);
        sim.producer.total = total;
        sim.run_until(deadline, Sim::done);
        prop_assert_eq!(check_stream(&sim.nodes[first].got, 1, total), Ok(vec![]));
        let node = &sim.nodes[second];
        prop_assert_eq!(check_stream(&node.got, join_at, total), Ok(vec![]));
        prop_assert!(node.acknacks.iter().all(|(acked, _)| *acked >= join_at));
    }
}

#[test]
fn an_outage_longer_than_the_history_loses_exactly_what_was_evicted() {
    // Seqs 1..=100, one a millisecond; the link is down from 20 ms to 200 ms; depth 10 and
    // the producer does not wait. Seqs 20..=100 are sent into the outage; the history keeps
    // 91..=100, so exactly 20..91 are lost.
    let mut sim = Sim::new(7, writer_config(10), producer(100, MS, false));
    let link = Link {
        outages: vec![(20 * MS, 200 * MS)],
        ..Link::clean()
    };
    let key = sim.add_node(reader_config(64), link, Consumer::Eager);
    sim.attach(key);
    sim.start_writing_at(MS);
    let deadline = sim.at_ms(2_000);
    sim.run_until(deadline, Sim::done);
    let node = &sim.nodes[key];
    assert_eq!(check_stream(&node.got, 1, 100), Ok(vec![(20, 91)]));
    assert_eq!(node.reader.stats().lost_reports, 1);
    assert_eq!(node.reader.stats().lost, 71);
}

#[test]
fn a_slow_reader_closes_the_window_and_memory_stays_bounded() {
    // The producer could write 200 samples in 20 ms; the consumer takes one every 10 ms.
    let depth = 16;
    let mut sim = Sim::new(
        3,
        writer_config(depth),
        producer(200, Duration::from_micros(100), true),
    );
    let slow = Consumer::Slow {
        every: 10 * MS,
        batch: 1,
    };
    let key = sim.add_node(reader_config(depth), Link::clean(), slow);
    sim.attach(key);
    let deadline = sim.at_ms(10_000);
    sim.run_until(deadline, Sim::done);
    assert!(sim.done());
    let node = &sim.nodes[key];
    assert_eq!(check_stream(&node.got, 1, 200), Ok(vec![]));
    assert!(sim.max_history <= depth, "history {}", sim.max_history);
    assert!(
        sim.max_buffered <= depth,
        "reader held {}",
        sim.max_buffered
    );
    assert!(sim.writer.stats().window_full > 0);
    // The producer went at the consumer's pace: blocked most of the ~2 s.
    assert!(
        sim.blocked_for >= 1500 * MS,
        "blocked {:?}",
        sim.blocked_for
    );
    assert_eq!(sim.writer.stats().resends, 0, "nothing was lost");
}

#[test]
fn a_dead_reader_blocks_the_window_until_removed() {
    let depth = 32;
    let mut sim = Sim::new(5, writer_config(depth), producer(500, MS, true));
    let live = sim.add_node(reader_config(depth), Link::clean(), Consumer::Eager);
    let dead = sim.add_node(reader_config(depth), Link::clean(), Consumer::Eager);
    sim.attach(live);
    sim.attach(dead);
    sim.run_for(100 * MS);
    sim.nodes[dead].alive = false;
    sim.run_for(400 * MS);
    assert!(!sim.writer.window_open());
    assert_eq!(sim.writer.history_len(), depth);
    let stuck_at = sim.next_seq;
    assert!(
        stuck_at < 150,
        "blocked soon after the reader died: {stuck_at}"
    );
    sim.detach(dead);
    assert!(sim.writer.window_open());
    let deadline = sim.now + 2000 * MS;
    sim.run_until(deadline, Sim::done);
    assert!(sim.done());
    assert_eq!(check_stream(&sim.nodes[live].got, 1, 500), Ok(vec![]));
    sim.run_for(100 * MS);
    assert_eq!(
        sim.writer.history_len(),
        0,
        "everything acknowledged, nothing kept"
    );
}

#[test]
fn a_late_joiner_starts_at_the_next_sample_and_asks_for_nothing_older() {
    // Reader 0 is slow, so the writer's history holds old samples when reader 1 joins at
    // seq 1000; reader 1 must neither get nor ask for any of them.
    let mut sim = Sim::new(
        11,
        writer_config(256),
        producer(1100, Duration::from_micros(100), true),
    );
    let slow = Consumer::Slow {
        every: MS,
        batch: 2,
    };
    let early = sim.add_node(reader_config(256), Link::clean(), slow);
    let late = sim.add_node(reader_config(256), Link::clean(), Consumer::Eager);
    sim.attach(early);
    let deadline = sim.at_ms(60_000);
    sim.producer.total = 999;
    sim.run_until(deadline, |s| s.next_seq == 1000);
    assert!(
        sim.writer.history_len() > 100,
        "old samples held for the slow reader"
    );
    sim.attach(late);
    sim.producer.total = 1100;
    sim.run_until(deadline, Sim::done);
    assert!(sim.done());
    assert_eq!(check_stream(&sim.nodes[early].got, 1, 1100), Ok(vec![]));
    let node = &sim.nodes[late];
    assert_eq!(check_stream(&node.got, 1000, 1100), Ok(vec![]));
    assert!(
        node.acknacks
            .iter()
            .all(|(acked, asked)| *acked >= 1000 && asked.is_empty()),
        "{:?}",
        &node.acknacks[..3]
    );
}

#[test]
fn a_late_joiner_whose_greeting_is_lost_still_starts_where_it_matched() {
    // The greeting heartbeat is lost and samples reach the new reader first; the periodic
    // heartbeat that follows still names seq 100 as its start.
    let mut sim = Sim::new(13, writer_config(64), producer(300, MS, true));
    let first = sim.add_node(reader_config(64), Link::clean(), Consumer::Eager);
    sim.attach(first);
    sim.producer.total = 99;
    sim.run_until(sim.at_ms(10_000), |s| s.next_seq == 100);
    sim.producer.total = 300;
    let now = sim.now - sim.t0;
    let link = Link {
        outages: vec![(now, now + MS / 2)],
        ..Link::clean()
    };
    let late = sim.add_node(reader_config(64), link, Consumer::Eager);
    sim.attach(late);
    sim.run_until(sim.at_ms(10_000), Sim::done);
    let node = &sim.nodes[late];
    assert_eq!(node.stats.control_dropped, 1, "the greeting");
    assert_eq!(check_stream(&node.got, 100, 300), Ok(vec![]));
    assert!(node.acknacks.iter().all(|(acked, _)| *acked >= 100));
}

#[test]
fn resends_are_in_proportion_to_losses() {
    // 10 % loss both ways, 3 readers, 3000 samples one a millisecond.
    let mut sim = Sim::new(17, writer_config(256), producer(3000, MS, true));
    let lossy = Link {
        loss: 0.1,
        ..Link::clean()
    };
    for _ in 0..3 {
        let key = sim.add_node(reader_config(256), lossy.clone(), Consumer::Eager);
        sim.attach(key);
    }
    sim.run_until(sim.at_ms(60_000), Sim::done);
    assert!(sim.done());
    let dropped: u64 = sim.nodes.iter().map(|n| n.stats.samples_dropped).sum();
    let originals: u64 = sim.nodes.iter().map(|n| n.stats.originals_dropped).sum();
    let resends = sim.writer.stats().resends;
    for node in &sim.nodes {
        assert_eq!(check_stream(&node.got, 1, 3000), Ok(vec![]));
    }
    println!(
        "originals dropped {originals}, samples dropped {dropped}, resends {resends}, \
         heartbeats {}, duplicates at readers {}",
        sim.writer.stats().heartbeats,
        sim.nodes
            .iter()
            .map(|n| n.reader.stats().duplicates)
            .sum::<u64>()
    );
    assert!(resends >= originals, "every lost original was resent");
    assert!(
        resends <= dropped + dropped / 4 + 10,
        "no storm: {resends} resends for {dropped} lost samples"
    );
}

#[test]
fn no_loss_no_repair_traffic() {
    let mut sim = Sim::new(
        19,
        writer_config(64),
        producer(2000, Duration::from_micros(200), true),
    );
    let key = sim.add_node(reader_config(64), Link::clean(), Consumer::Eager);
    sim.attach(key);
    sim.run_until(sim.at_ms(10_000), Sim::done);
    assert_eq!(check_stream(&sim.nodes[key].got, 1, 2000), Ok(vec![]));
    let stats = sim.writer.stats();
    assert_eq!((stats.resends, stats.gaps), (0, 0));
    assert_eq!(sim.nodes[key].reader.stats().nacks, 0);
    assert_eq!(sim.blocked_for, Duration::ZERO, "acks keep the window open");
    assert!(
        stats.heartbeats < 2000 / 8,
        "about one heartbeat a quarter window: {}",
        stats.heartbeats
    );
}

#[test]
fn loss_costs_throughput_in_proportion() {
    // A producer as fast as the window allows over a link of unlimited bandwidth and a 2 ms
    // round trip: the window is the only limit, so every repair stalls it (the worst case).
    let run = |loss| {
        let mut sim = Sim::new(
            23,
            writer_config(256),
            producer(20_000, Duration::ZERO, true),
        );
        let link = Link {
            loss,
            ..Link::clean()
        };
        let key = sim.add_node(reader_config(256), link, Consumer::Eager);
        sim.attach(key);
        sim.run_until(sim.at_ms(60_000), Sim::done);
        assert_eq!(check_stream(&sim.nodes[key].got, 1, 20_000), Ok(vec![]));
        sim.now - sim.t0
    };
    let clean = run(0.0);
    let lossy = run(0.1);
    println!("20000 samples: {clean:?} without loss, {lossy:?} with 10 % loss");
    assert!(lossy < clean * 3, "10 % loss: {lossy:?} against {clean:?}");
}

/// Late joiners get the last value (DDS TRANSIENT_LOCAL): with `late_joiners = 3`, a reader
/// that matches after 0, 1 or 5 samples were written gets the newest of them (none, 1, or
/// 3..=5) in order before everything written after, over a clean and a lossy link.
#[test]
fn late_joiners_get_the_kept_samples_first_in_order() {
    for (written, lossy) in [(0, false), (1, false), (5, false), (5, true), (40, true)] {
        let config = WriterConfig {
            late_joiners: 3,
            ..writer_config(64)
        };
        let mut sim = Sim::new(17 + written, config, producer(written + 50, MS, true));
        if written > 0 {
            sim.producer.total = written;
            sim.run_until(sim.at_ms(10_000), |s| s.next_seq == written + 1);
        }
        let link = if lossy {
            Link {
                loss: 0.2,
                ..Link::clean()
            }
        } else {
            Link::clean()
        };
        let late = sim.add_node(reader_config(64), link, Consumer::Eager);
        sim.attach(late);
        sim.producer.total = written + 50;
        sim.run_until(sim.at_ms(60_000), Sim::done);
        assert!(sim.done(), "after {written} samples, lossy {lossy}");
        let first = written.saturating_sub(2).max(1);
        assert_eq!(
            check_stream(&sim.nodes[late].got, first, written + 50),
            Ok(vec![]),
            "after {written} samples, lossy {lossy}"
        );
    }
}

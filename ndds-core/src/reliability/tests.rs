//! The writer's and the reader's rules, one scenario per test, in virtual time. The whole
//! protocol over a lossy simulated link is in `tests/reliability/`.

use std::time::{Duration, Instant};

use proptest::prelude::*;

use super::*;

const MS: Duration = Duration::from_millis(1);

fn reader(depth: usize) -> ReliableReader<u64> {
    ReliableReader::new(ReaderConfig {
        depth,
        nack_retry: 20 * MS,
        nack_retry_min: MS,
        partial_timeout: 100 * MS,
    })
}

/// A reader whose stream starts at `first`, its answer to that first heartbeat drained.
fn synced(t0: Instant, depth: usize, first: u64) -> ReliableReader<u64> {
    let mut r = reader(depth);
    r.handle_heartbeat(t0, first, first - 1);
    assert!(r.poll_output().is_some());
    r
}

fn deliveries(r: &mut ReliableReader<u64>) -> Vec<Delivery<u64>> {
    std::iter::from_fn(|| r.poll_deliver()).collect()
}

fn samples(seqs: impl IntoIterator<Item = u64>) -> Vec<Delivery<u64>> {
    seqs.into_iter()
        .map(|seq| Delivery::Sample {
            seq,
            sample: seq * 10,
        })
        .collect()
}

/// The seqs an AckNack asks for.
fn asked(ack: &AckNack) -> Vec<u64> {
    ack.asked().collect()
}

fn writer(depth: usize) -> ReliableWriter<u32, u64> {
    ReliableWriter::new(WriterConfig {
        depth,
        max_bytes: 1 << 20,
        heartbeat_period: 20 * MS,
        idle_heartbeat_period: 1000 * MS,
        // The fixed-period tests below assume no faster heartbeats while blocked.
        blocked_heartbeat_period: 20 * MS,
        reader_liveness: Some(1000 * MS),
        late_joiners: 0,
    })
}

fn outputs(w: &mut ReliableWriter<u32, u64>) -> Vec<WriterOutput<u32, u64>> {
    std::iter::from_fn(|| w.poll_output()).collect()
}

fn write_n(w: &mut ReliableWriter<u32, u64>, now: Instant, seqs: std::ops::RangeInclusive<u64>) {
    for seq in seqs {
        w.write(now, seq, seq * 10, 100).unwrap();
    }
}

fn heartbeat(reader: u32, first: u64, last: u64) -> WriterOutput<u32, u64> {
    WriterOutput::Heartbeat {
        reader,
        first,
        last,
    }
}

#[test]
fn in_order_samples_are_delivered_and_acknowledged_only_once_taken() {
    let t0 = Instant::now();
    let mut r = synced(t0, 8, 1);
    for seq in 1..=3 {
        r.handle_sample(t0, seq, seq * 10);
    }
    assert_eq!(r.poll_output(), None, "no hole, nothing to say");
    r.handle_heartbeat(t0, 1, 3);
    let ack = r.poll_output().unwrap();
    assert_eq!((ack.acked, asked(&ack)), (1, vec![]), "nothing taken yet");
    assert_eq!(deliveries(&mut r), samples(1..=3));
    r.handle_heartbeat(t0, 1, 3);
    assert_eq!(r.poll_output().unwrap().acked, 4);
    assert_eq!(r.stats().delivered, 3);
}

#[test]
fn a_hole_is_nacked_at_once_then_every_retry_until_repaired() {
    let t0 = Instant::now();
    let mut r = synced(t0, 8, 1);
    r.handle_sample(t0, 1, 10);
    r.handle_sample(t0, 4, 40);
    let nack = r.poll_output().unwrap();
    assert_eq!((nack.acked, asked(&nack)), (1, vec![2, 3]));
    r.handle_sample(t0 + MS, 5, 50);
    assert_eq!(r.poll_output(), None, "no new hole, no new nack");
    assert_eq!(deliveries(&mut r), samples([1]));
    assert_eq!(r.poll_timeout(), Some(t0 + 20 * MS));
    r.handle_timeout(t0 + 20 * MS);
    let retry = r.poll_output().unwrap();
    assert_eq!((retry.acked, asked(&retry)), (2, vec![2, 3]));
    r.handle_sample(t0 + 30 * MS, 3, 30);
    r.handle_sample(t0 + 30 * MS, 2, 20);
    assert_eq!(deliveries(&mut r), samples(2..=5));
    r.handle_timeout(t0 + 40 * MS);
    assert_eq!(r.poll_output(), None);
    assert_eq!(r.poll_timeout(), None);
    assert_eq!(r.stats().nacks, 2);
}

#[test]
fn the_retry_time_follows_the_measured_round_trip() {
    let t0 = Instant::now();
    let mut r = synced(t0, 64, 1);
    r.handle_sample(t0, 2, 20);
    assert_eq!(asked(&r.poll_output().unwrap()), vec![1]);
    assert_eq!(r.poll_timeout(), Some(t0 + 20 * MS), "nothing measured yet");
    r.handle_sample(t0 + 2 * MS, 1, 10);
    assert_eq!(r.poll_timeout(), None);
    let t1 = t0 + 10 * MS;
    r.handle_sample(t1, 4, 40);
    assert_eq!(asked(&r.poll_output().unwrap()), vec![3]);
    assert_eq!(
        r.poll_timeout(),
        Some(t1 + 6 * MS),
        "2 ms round trip + 4 x 1 ms deviation"
    );
    r.handle_heartbeat(t1 + 3 * MS, 1, 4);
    assert_eq!(
        asked(&r.poll_output().unwrap()),
        Vec::<u64>::new(),
        "asked 3 ms ago: not yet"
    );
    r.handle_timeout(t1 + 6 * MS);
    assert_eq!(asked(&r.poll_output().unwrap()), vec![3]);
}

#[test]
fn a_repeat_answered_twice_measures_the_round_trip_it_missed() {
    let t0 = Instant::now();
    let mut r = synced(t0, 64, 1);
    // One measured round trip of 1 ms: the retry time is 1 + 4 x 0.5 = 3 ms.
    r.handle_sample(t0, 2, 20);
    assert_eq!(asked(&r.poll_output().unwrap()), vec![1]);
    r.handle_sample(t0 + MS, 1, 10);
    let t1 = t0 + 10 * MS;
    r.handle_sample(t1, 4, 40);
    assert_eq!(asked(&r.poll_output().unwrap()), vec![3]);
    assert_eq!(r.poll_timeout(), Some(t1 + 3 * MS));
    // The answer takes 8 ms: the request is repeated after 3, and both are answered.
    r.handle_timeout(t1 + 3 * MS);
    assert_eq!(asked(&r.poll_output().unwrap()), vec![3]);
    r.handle_sample(t1 + 8 * MS, 3, 30);
    assert_eq!(
        r.stats().early_retries,
        0,
        "one answer could be to either request"
    );
    r.handle_sample(t1 + 9 * MS, 3, 30);
    assert_eq!(
        r.stats().early_retries,
        1,
        "the second copy shows the repeat was early"
    );
    // 8 ms measured: smoothed 1.875 ms, deviation 2.125 ms, retry 10.375 ms.
    let t2 = t1 + 20 * MS;
    r.handle_sample(t2, 6, 60);
    assert_eq!(asked(&r.poll_output().unwrap()), vec![5]);
    assert_eq!(r.poll_timeout(), Some(t2 + Duration::from_micros(10_375)));
    // A repeat answered once (the first request was lost) measures nothing.
    r.handle_timeout(t2 + Duration::from_micros(10_375));
    assert_eq!(asked(&r.poll_output().unwrap()), vec![5]);
    r.handle_sample(t2 + 11 * MS, 5, 50);
    let t3 = t2 + 30 * MS;
    r.handle_sample(t3, 8, 80);
    assert_eq!(asked(&r.poll_output().unwrap()), vec![7]);
    assert_eq!(r.poll_timeout(), Some(t3 + Duration::from_micros(10_375)));
    assert_eq!(r.stats().early_retries, 1);
}

#[test]
fn duplicates_old_and_far_samples_are_dropped_and_counted() {
    let t0 = Instant::now();
    let mut r = synced(t0, 4, 1);
    r.handle_sample(t0, 1, 10);
    r.handle_sample(t0, 1, 10);
    assert_eq!(deliveries(&mut r), samples([1]));
    r.handle_sample(t0, 1, 10);
    r.handle_sample(t0, 3, 30);
    r.handle_sample(t0, 3, 30);
    r.handle_sample(t0, 6, 60);
    let stats = r.stats();
    assert_eq!((stats.duplicates, stats.out_of_window), (3, 1));
    assert_eq!(r.buffered(), 1);
    let nack = r.poll_output().unwrap();
    assert_eq!(
        asked(&nack),
        vec![2, 4, 5],
        "unsent requests merged, within the window"
    );
    assert_eq!(r.poll_output(), None);
}

#[test]
fn a_lost_run_is_reported_once_merged_and_in_stream_order() {
    let t0 = Instant::now();
    let mut r = synced(t0, 16, 1);
    for seq in [1, 2, 6, 13] {
        r.handle_sample(t0, seq, seq * 10);
    }
    r.handle_gap(3, 5);
    r.handle_gap(5, 8);
    let mut expected = samples(1..=2);
    expected.push(Delivery::Lost { from: 3, to: 6 });
    expected.extend(samples([6]));
    assert_eq!(deliveries(&mut r), expected, "6 arrived: it ends the run");
    assert_eq!(deliveries(&mut r), vec![], "7 is lost but 8 may come: wait");
    let t1 = t0 + 20 * MS;
    r.handle_heartbeat(t1, 10, 13);
    let ack = r.poll_output().unwrap();
    assert_eq!((ack.acked, asked(&ack)), (10, vec![10, 11, 12]));
    r.handle_sample(t1, 10, 100);
    let mut expected = vec![Delivery::Lost { from: 7, to: 10 }];
    expected.extend(samples([10]));
    assert_eq!(deliveries(&mut r), expected, "gap and heartbeat merged");
    let stats = r.stats();
    assert_eq!((stats.lost, stats.lost_reports), (6, 2));
    r.handle_heartbeat(t1, 10, 13);
    let ack = r.poll_output().unwrap();
    assert_eq!(
        (ack.acked, asked(&ack)),
        (11, vec![]),
        "asked for less than a retry ago"
    );
    r.handle_heartbeat(t1 + 20 * MS, 10, 13);
    let ack = r.poll_output().unwrap();
    assert_eq!((ack.acked, asked(&ack)), (11, vec![11, 12]));
}

#[test]
fn a_run_up_to_a_drained_writer_is_reported_without_waiting() {
    let t0 = Instant::now();
    let mut r = synced(t0, 16, 1);
    r.handle_gap(1, 4);
    assert_eq!(deliveries(&mut r), vec![], "4 may be lost too: wait");
    r.handle_heartbeat(t0, 1, 5);
    assert_eq!(deliveries(&mut r), vec![]);
    r.handle_heartbeat(t0, 6, 5);
    assert_eq!(deliveries(&mut r), vec![Delivery::Lost { from: 1, to: 6 }]);
}

#[test]
fn a_late_joiner_starts_at_its_first_heartbeat_and_asks_for_nothing_older() {
    let t0 = Instant::now();
    let mut r = reader(8);
    r.handle_sample(t0, 1001, 10010);
    r.handle_sample(t0, 999, 9990);
    assert_eq!(deliveries(&mut r), vec![], "not started");
    assert_eq!(
        r.poll_output(),
        None,
        "asks nothing before the start is known"
    );
    r.handle_heartbeat(t0, 1000, 1001);
    let ack = r.poll_output().unwrap();
    assert_eq!((ack.acked, asked(&ack)), (1000, vec![1000]));
    r.handle_sample(t0, 1000, 10000);
    assert_eq!(deliveries(&mut r), samples(1000..=1001));
    assert!(r.is_synced());
}

#[test]
fn a_slow_consumer_gets_a_catch_up_ack_after_taking_half() {
    let t0 = Instant::now();
    let mut r = synced(t0, 16, 1);
    for seq in 1..=8 {
        r.handle_sample(t0, seq, seq * 10);
    }
    r.handle_heartbeat(t0, 1, 8);
    assert_eq!(r.poll_output().unwrap().acked, 1);
    for _ in 0..3 {
        r.poll_deliver().unwrap();
        assert_eq!(r.poll_output(), None);
    }
    r.poll_deliver().unwrap();
    assert_eq!(r.poll_output().unwrap().acked, 5, "half of 8 taken");
    deliveries(&mut r);
    assert_eq!(r.poll_output(), None, "one catch-up per heartbeat");
}

#[test]
fn nonsense_from_the_writer_changes_nothing() {
    let t0 = Instant::now();
    let mut r = synced(t0, 8, 1);
    r.handle_heartbeat(t0, 10, 5);
    r.handle_gap(9, 3);
    assert_eq!(r.stats().invalid, 2);
    r.handle_gap(u64::MAX - 1, u64::MAX);
    r.handle_sample(t0, u64::MAX, 0);
    assert_eq!(r.buffered(), 0);
    r.handle_heartbeat(t0, 1, u64::MAX);
    let nack = r.poll_output().unwrap();
    assert_eq!(
        asked(&nack),
        (1..=8).collect::<Vec<_>>(),
        "the window, no further"
    );
    r.handle_heartbeat(t0, u64::MAX, u64::MAX);
    r.handle_sample(t0, u64::MAX, 7);
    assert_eq!(
        deliveries(&mut r),
        vec![
            Delivery::Lost {
                from: 1,
                to: u64::MAX
            },
            Delivery::Sample {
                seq: u64::MAX,
                sample: 7
            }
        ]
    );
    assert_eq!(deliveries(&mut r), vec![]);
}

#[test]
fn a_new_reader_is_greeted_and_owed_only_new_samples() {
    let t0 = Instant::now();
    let mut w = writer(4);
    write_n(&mut w, t0, 1..=5);
    assert_eq!(w.history_len(), 0, "no reader: nothing kept");
    assert!(w.add_reader(t0, 7));
    assert!(!w.add_reader(t0, 7));
    assert_eq!(outputs(&mut w), vec![heartbeat(7, 6, 5)]);
    write_n(&mut w, t0, 6..=6);
    assert_eq!(w.history_len(), 1);
    assert_eq!(w.acked(7), Some(6));
}

#[test]
fn the_window_closes_at_depth_and_acks_reopen_it() {
    let t0 = Instant::now();
    let mut w = writer(4);
    w.add_reader(t0, 1);
    w.add_reader(t0, 2);
    outputs(&mut w);
    write_n(&mut w, t0, 1..=3);
    assert!(w.window_open());
    write_n(&mut w, t0, 4..=4);
    assert!(!w.window_open());
    assert_eq!(w.stats().window_full, 1);
    w.handle_acknack(t0, 1, 5, &[]);
    assert!(!w.window_open(), "reader 2 still holds them");
    w.handle_acknack(t0, 2, 3, &[]);
    assert!(w.window_open());
    assert_eq!(w.history_len(), 2, "3 and 4");
    assert!(w.remove_reader(2));
    assert_eq!(w.history_len(), 0);
}

#[test]
fn nacks_are_answered_with_resends_once_and_gaps_for_what_is_gone() {
    let t0 = Instant::now();
    let mut w = writer(4);
    w.add_reader(t0, 1);
    write_n(&mut w, t0, 1..=4);
    outputs(&mut w);
    w.handle_acknack(t0, 1, 2, &[0b1010]);
    w.handle_acknack(t0, 1, 2, &[0b1010]);
    let resend = |seq| WriterOutput::Resend {
        reader: 1,
        seq,
        sample: seq * 10,
    };
    assert_eq!(
        outputs(&mut w),
        vec![resend(3), heartbeat(1, 2, 4)],
        "5 was never written; a heartbeat follows the repairs"
    );
    assert_eq!(w.stats().invalid_feedback, 2);
    // The ack left 2..=4 in the history: writing two more, past the closed window, evicts 2.
    write_n(&mut w, t0, 5..=6);
    let gap = WriterOutput::Gap {
        reader: 1,
        from: 2,
        to: 3,
    };
    assert_eq!(outputs(&mut w), vec![gap.clone(), heartbeat(1, 3, 6)]);
    assert_eq!(w.stats().evicted_unacked, 1);
    w.handle_acknack(t0, 1, 2, &[0b111]);
    assert_eq!(
        outputs(&mut w),
        vec![gap, resend(3), resend(4), heartbeat(1, 3, 6)]
    );
}

#[test]
fn heartbeats_follow_writes_within_a_period_and_idle_otherwise() {
    let t0 = Instant::now();
    let mut w = writer(64);
    w.add_reader(t0, 1);
    outputs(&mut w);
    assert_eq!(w.poll_timeout(), Some(t0 + 20 * MS), "not heard from yet");
    w.handle_acknack(t0 + MS, 1, 1, &[]);
    w.handle_timeout(t0 + 20 * MS);
    assert_eq!(outputs(&mut w), vec![]);
    assert_eq!(w.poll_timeout(), Some(t0 + 1000 * MS));
    write_n(&mut w, t0 + 100 * MS, 1..=1);
    assert_eq!(w.poll_timeout(), Some(t0 + 120 * MS));
    write_n(&mut w, t0 + 110 * MS, 2..=2);
    assert_eq!(w.poll_timeout(), Some(t0 + 120 * MS), "never postponed");
    w.handle_timeout(t0 + 120 * MS);
    assert_eq!(outputs(&mut w), vec![heartbeat(1, 1, 2)]);
    w.handle_acknack(t0 + 121 * MS, 1, 3, &[]);
    w.handle_timeout(t0 + 140 * MS);
    assert_eq!(
        outputs(&mut w),
        vec![],
        "caught up: no more periodic heartbeats"
    );
    w.handle_timeout(t0 + 1000 * MS);
    assert_eq!(outputs(&mut w), vec![heartbeat(1, 3, 2)]);
    // A quarter of the window written at once asks for acknowledgements right away.
    write_n(&mut w, t0 + 1001 * MS, 3..=18);
    assert_eq!(outputs(&mut w), vec![heartbeat(1, 3, 18)]);
    assert_eq!(w.stats().heartbeats, 4);
}

#[test]
fn skipped_and_stale_writes() {
    let t0 = Instant::now();
    let mut w = writer(8);
    w.add_reader(t0, 1);
    outputs(&mut w);
    write_n(&mut w, t0, 1..=1);
    w.write(t0, 5, 50, 1).unwrap();
    assert_eq!(
        w.write(t0, 5, 50, 1),
        Err(WriteError::NotAfterLast { seq: 5, last: 5 })
    );
    assert_eq!(
        outputs(&mut w)[0],
        WriterOutput::Gap {
            reader: 1,
            from: 2,
            to: 5
        }
    );
    assert_eq!(w.stats().stale_writes, 1);
}

#[test]
fn the_byte_budget_bounds_the_history_and_the_window() {
    let t0 = Instant::now();
    let mut w = ReliableWriter::<u32, u64>::new(WriterConfig {
        depth: 100,
        max_bytes: 1000,
        ..WriterConfig::default()
    });
    w.add_reader(t0, 1);
    for seq in 1..=3 {
        assert!(w.window_open());
        w.write(t0, seq, seq, 400).unwrap();
    }
    assert!(!w.window_open());
    assert_eq!(w.history_bytes(), 1200, "the budget plus the newest");
    w.write(t0, 4, 4, 400).unwrap();
    assert_eq!((w.history_len(), w.stats().evicted_unacked), (3, 1));
}

#[test]
fn hostile_feedback_is_clamped_and_counted() {
    let t0 = Instant::now();
    let mut w = writer(8);
    w.add_reader(t0, 1);
    write_n(&mut w, t0, 1..=4);
    outputs(&mut w);
    w.handle_acknack(t0, 9, 1, &[0xFF]);
    assert_eq!(w.stats().unknown_reader, 1);
    w.handle_acknack(t0, 1, u64::MAX - 3, &[0xFF; 200]);
    w.handle_acknack(t0, 1, u64::MAX, &[0xFF; 64]);
    assert_eq!(w.acked(1), Some(5));
    assert_eq!(w.history_len(), 0);
    assert!(
        outputs(&mut w)
            .iter()
            .all(|o| matches!(o, WriterOutput::Heartbeat { .. }))
    );
    w.handle_acknack(t0, 1, 0, &[0xFF; 64]);
    assert_eq!(outputs(&mut w), vec![], "all settled already");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Whatever a writer is told, its memory stays bounded and it never panics.
    #[test]
    fn the_writer_survives_any_feedback(
        ops in proptest::collection::vec(
            (0u8..4, any::<u64>(), proptest::collection::vec(any::<u8>(), 0..80)), 0..60)
    ) {
        let t0 = Instant::now();
        let mut w = writer(8);
        w.add_reader(t0, 1);
        w.add_reader(t0, 2);
        let mut next = 1;
        for (i, (op, value, bitmap)) in ops.into_iter().enumerate() {
            let now = t0 + MS * i as u32;
            match op {
                0 => {
                    w.write(now, next, next, 10).unwrap();
                    next += 1;
                }
                1 => w.handle_acknack(now, (value % 3) as u32, value, &bitmap),
                2 => w.handle_acknack(now, 1, value % (next + 2), &bitmap),
                _ => w.handle_timeout(now + 30 * MS),
            }
            prop_assert!(w.history_len() <= 8);
            for out in std::iter::from_fn(|| w.poll_output()) {
                if let WriterOutput::Heartbeat { first, last, .. } = out {
                    prop_assert!(first <= last + 1);
                }
            }
        }
    }

    /// Whatever a reader is told, it holds at most `depth` samples, hands out ascending
    /// seqs, and never panics.
    #[test]
    fn the_reader_survives_any_input(
        ops in proptest::collection::vec((0u8..5, any::<u64>(), any::<u64>()), 0..80)
    ) {
        let t0 = Instant::now();
        let mut r = reader(8);
        let mut last_out = None;
        for (i, (op, a, b)) in ops.into_iter().enumerate() {
            let now = t0 + MS * i as u32;
            let (a, b) = if i % 2 == 0 { (a % 64, b % 64) } else { (a, b) };
            match op {
                0 | 1 => r.handle_sample(now, a, a),
                2 => r.handle_heartbeat(now, a.min(b), a.max(b)),
                3 => r.handle_gap(a.min(b), a.max(b)),
                _ => r.handle_timeout(now + 20 * MS),
            }
            prop_assert!(r.buffered() <= 8);
            while let Some(d) = r.poll_deliver() {
                let at = match d {
                    Delivery::Sample { seq, .. } => seq,
                    Delivery::Lost { from, to } => {
                        prop_assert!(from < to);
                        from
                    }
                };
                prop_assert!(last_out.is_none_or(|l| at > l), "{:?} after {:?}", at, last_out);
                last_out = Some(at);
            }
            while r.poll_output().is_some() {}
        }
    }
}

#[test]
fn a_blocked_writer_heartbeats_quickly_then_backs_off_until_acknowledged() {
    let t0 = Instant::now();
    let mut w = ReliableWriter::<u32, u64>::new(WriterConfig {
        depth: 4,
        max_bytes: 1 << 20,
        heartbeat_period: 20 * MS,
        idle_heartbeat_period: 1000 * MS,
        blocked_heartbeat_period: MS,
        reader_liveness: None,
        late_joiners: 0,
    });
    w.add_reader(t0, 1);
    outputs(&mut w);
    write_n(&mut w, t0, 1..=4);
    assert!(!w.window_open());
    outputs(&mut w);
    // Heartbeats come after 1, 2, 4, 8, 16, 20, 20 ms while nothing is acknowledged.
    let mut now = t0;
    let mut gaps = Vec::new();
    for _ in 0..7 {
        let due = w.poll_timeout().expect("a heartbeat is armed");
        gaps.push((due - now).as_millis());
        now = due;
        w.handle_timeout(now);
        let beats = outputs(&mut w);
        assert!(
            beats
                .iter()
                .any(|o| matches!(o, WriterOutput::Heartbeat { reader: 1, .. })),
            "{beats:?}"
        );
    }
    assert_eq!(gaps, [1, 2, 4, 8, 16, 20, 20]);
    // Progress starts the back-off again; an open window goes back to the normal period.
    w.handle_acknack(now, 1, 3, &[]);
    assert!(w.window_open());
    w.write(now, 5, 5, 1).unwrap();
    assert!(w.window_open());
    w.write(now, 6, 6, 1).unwrap();
    assert!(!w.window_open());
    outputs(&mut w);
    let due = w.poll_timeout().unwrap();
    assert_eq!((due - now).as_millis(), 1);
}

#[test]
fn a_sample_arriving_in_pieces_is_not_asked_for_while_its_pieces_keep_coming() {
    let t0 = Instant::now();
    let mut r = synced(t0, 16, 1);
    r.handle_sample(t0, 1, 10);
    // Pieces of 3 arrive: 2 is missing and asked for at once, 3 is not asked for.
    r.handle_partial(t0, 3);
    let ack = r.poll_output().expect("the hole before the partial sample");
    assert_eq!((ack.acked, asked(&ack)), (1, vec![2]));
    // 2 comes; a heartbeat's answer still leaves 3 to its pieces.
    r.handle_sample(t0 + MS, 2, 20);
    r.handle_heartbeat(t0 + 2 * MS, 1, 3);
    let ack = r.poll_output().unwrap();
    assert!(asked(&ack).is_empty(), "{ack:?}");
    // More pieces keep it fresh; once they stop for the partial timeout, it is asked for.
    r.handle_partial(t0 + 50 * MS, 3);
    // The first look, a timeout after the first piece, finds it fresh and looks again when
    // it would be stale.
    assert_eq!(r.poll_timeout(), Some(t0 + 100 * MS));
    r.handle_timeout(t0 + 100 * MS);
    assert!(r.poll_output().is_none());
    assert_eq!(r.poll_timeout(), Some(t0 + 150 * MS));
    r.handle_timeout(t0 + 149 * MS);
    assert!(r.poll_output().is_none());
    r.handle_timeout(t0 + 150 * MS);
    let ack = r.poll_output().expect("asked for as a whole");
    assert_eq!(asked(&ack), vec![3]);
    // The whole sample completes it.
    r.handle_sample(t0 + 151 * MS, 3, 30);
    assert_eq!(deliveries(&mut r), samples(1..=3));
    while r.poll_output().is_some() {}
    // Pieces of samples already had, or beyond the window, change nothing.
    r.handle_partial(t0 + 152 * MS, 2);
    r.handle_partial(t0 + 152 * MS, 40);
    assert!(r.poll_output().is_none());
    assert_eq!(r.poll_timeout(), None);
}

#[test]
fn a_reader_that_stops_answering_leaves_the_window_and_joins_again_later() {
    let t0 = Instant::now();
    let mut w = writer(4);
    w.add_reader(t0, 1);
    w.add_reader(t0, 2);
    write_n(&mut w, t0, 1..=4);
    // Reader 1 acknowledges everything; reader 2 is silent: the window stays closed.
    w.handle_acknack(t0 + MS, 1, 5, &[]);
    assert!(!w.window_open());
    for k in 1..=49 {
        let now = t0 + 20 * MS * k;
        w.handle_timeout(now);
        outputs(&mut w);
        assert!(!w.window_open(), "still held at {:?}", now - t0);
    }
    assert_eq!(w.poll_silenced(), None);
    // One second without an answer while behind: silenced, and the window opens.
    let now = t0 + 1000 * MS;
    w.handle_timeout(now);
    assert_eq!(w.poll_silenced(), Some(2));
    assert!(w.is_silent(2));
    assert!(w.window_open(), "the silent reader holds nothing");
    assert_eq!(w.stats().silenced, 1);
    // The writer goes on; reader 1 keeps up.
    write_n(&mut w, now, 5..=12);
    w.handle_acknack(now + MS, 1, 13, &[]);
    assert!(w.window_open());
    outputs(&mut w);
    // Reader 2 answers at last: it is back, and its next heartbeat tells it what is gone.
    w.handle_acknack(now + 2 * MS, 2, 1, &[]);
    assert!(!w.is_silent(2));
    let out = outputs(&mut w);
    assert!(
        out.iter()
            .any(|o| matches!(o, WriterOutput::Heartbeat { reader: 2, first, .. } if *first > 1)),
        "the returning reader learns that 1.. are gone: {out:?}"
    );
}

#[test]
fn a_reader_that_is_caught_up_and_idle_is_never_silenced() {
    let t0 = Instant::now();
    let mut w = writer(4);
    w.add_reader(t0, 1);
    write_n(&mut w, t0, 1..=2);
    w.handle_acknack(t0 + MS, 1, 3, &[]);
    // Ten quiet seconds (only idle heartbeats, which it need not answer: it has everything).
    for s in 1..=10 {
        w.handle_timeout(t0 + 1000 * MS * s);
        outputs(&mut w);
    }
    assert_eq!(w.poll_silenced(), None);
    // A write after the quiet: the liveness counts from that write, not from its last
    // acknowledgement ten seconds ago.
    let now = t0 + 10_500 * MS;
    write_n(&mut w, now, 3..=3);
    w.handle_timeout(now + 500 * MS);
    assert_eq!(w.poll_silenced(), None);
    assert!(!w.is_silent(1));
}

#[test]
fn a_resumed_stream_reports_what_it_missed_since() {
    let t0 = Instant::now();
    let mut r = reader(8);
    // The stream had been followed up to 11 (10 delivered); the writer, back after an
    // outage, starts this reader at 40.
    r.resume_at(11);
    r.handle_heartbeat(t0, 40, 41);
    r.handle_sample(t0, 40, 400);
    r.handle_sample(t0, 41, 410);
    assert_eq!(
        deliveries(&mut r),
        vec![
            Delivery::Lost { from: 11, to: 40 },
            Delivery::Sample {
                seq: 40,
                sample: 400
            },
            Delivery::Sample {
                seq: 41,
                sample: 410
            },
        ]
    );
}

#[test]
fn a_late_joiner_is_owed_the_kept_samples_and_gets_them_resent() {
    let t0 = Instant::now();
    let mut w = ReliableWriter::<u32, u64>::new(WriterConfig {
        late_joiners: 3,
        ..WriterConfig::default()
    });
    write_n(&mut w, t0, 1..=5);
    w.add_reader(t0, 1);
    assert_eq!(outputs(&mut w), vec![heartbeat(1, 3, 5)]);
    // It asks for 3, 4 and 5 (bits 0..3 from 3).
    w.handle_acknack(t0 + MS, 1, 3, &[0b0000_0111]);
    let out = outputs(&mut w);
    let resent: Vec<u64> = out
        .iter()
        .filter_map(|o| match o {
            WriterOutput::Resend { seq, .. } => Some(*seq),
            _ => None,
        })
        .collect();
    assert_eq!(resent, vec![3, 4, 5], "{out:?}");
    assert!(w.window_open(), "kept samples never close the window");
}

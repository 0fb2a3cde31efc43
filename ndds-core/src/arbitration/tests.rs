//! The arbiter's rules, one scenario per test, in virtual time.

use std::time::{Duration, Instant};

use proptest::prelude::*;

use super::*;
use crate::wire::Guid;

const MS: Duration = Duration::from_millis(1);

fn writer(n: u64) -> Guid {
    Guid {
        participant: n,
        entity: 1,
    }
}

/// A sample from producer `n` with `strength`, persistence `persist_ms` and source time `t_ms`.
fn incoming(n: u64, strength: i32, persist_ms: u64, t_ms: u64) -> Incoming {
    Incoming {
        writer: writer(n),
        seq: t_ms,
        strength,
        persistence: MS * persist_ms as u32,
        source_ns: t_ms * 1_000_000,
    }
}

fn drain(arbiter: &mut Arbiter<u64>) -> Vec<Output<u64>> {
    std::iter::from_fn(|| arbiter.poll_output()).collect()
}

fn delivered(outputs: &[Output<u64>]) -> Vec<u64> {
    outputs
        .iter()
        .filter_map(|o| match o {
            Output::Deliver { sample, .. } => Some(*sample),
            Output::Notify(_) => None,
        })
        .collect()
}

#[test]
fn the_stronger_producer_wins_and_the_weaker_takes_over_after_persistence() {
    let t0 = Instant::now();
    let mut a = Arbiter::new(Rules::default(), t0);
    // A (strength 10, persistence 100 ms) and B (strength 5) both publish every 10 ms.
    for i in 0..10u64 {
        let now = t0 + MS * (10 * i as u32);
        a.handle_sample(now, incoming(1, 10, 100, i * 10), 100 + i);
        a.handle_sample(now, incoming(2, 5, 100, i * 10), 200 + i);
    }
    let out = drain(&mut a);
    assert!(delivered(&out).iter().all(|s| *s < 200), "only A: {out:?}");
    assert_eq!(a.stats().weaker, 10);
    // A falls silent after t = 90 ms; B is refused until A's last sample is 100 ms old.
    a.handle_sample(t0 + MS * 150, incoming(2, 5, 100, 150), 215);
    assert!(delivered(&drain(&mut a)).is_empty());
    a.handle_sample(t0 + MS * 190, incoming(2, 5, 100, 190), 219);
    let out = drain(&mut a);
    assert_eq!(
        out,
        vec![Output::Deliver {
            sample: 219,
            status: SampleStatus::TookOver {
                previous: writer(1)
            }
        }]
    );
    assert_eq!(a.in_charge(), Some(writer(2)));
    // A returns: stronger, so it wins at once.
    a.handle_sample(t0 + MS * 200, incoming(1, 10, 100, 200), 120);
    a.handle_sample(t0 + MS * 200, incoming(2, 5, 100, 200), 220);
    assert_eq!(delivered(&drain(&mut a)), vec![120]);
}

#[test]
fn a_weaker_producer_takes_over_at_its_first_sample_once_the_persistence_has_run_out() {
    let t0 = Instant::now();
    let mut a = Arbiter::new(Rules::default(), t0);
    // A (strength 10, persistence 200 ms) writes once at 0 and falls silent. Its clock is an
    // hour ahead: the persistence counts from the arrival here, not from the source time.
    let strong = Incoming {
        source_ns: 3_600_000 * 1_000_000,
        ..incoming(1, 10, 200, 0)
    };
    a.handle_sample(t0, strong, 0);
    assert_eq!(delivered(&drain(&mut a)), vec![0]);
    // B (strength 5) writes every 7 ms from 4 ms: at 4, 11, ..., 193, 200, 207, ...
    let mut first_accepted = None;
    for t_ms in (4..=300).step_by(7) {
        a.handle_sample(
            t0 + MS * t_ms,
            incoming(2, 5, 200, u64::from(t_ms)),
            1000 + u64::from(t_ms),
        );
        let out = drain(&mut a);
        if first_accepted.is_none() && !out.is_empty() {
            first_accepted = Some((t_ms, out));
        }
    }
    // Refused up to 193 ms; the sample arriving exactly when the persistence ends is taken,
    // so the takeover comes within the persistence plus one period of B.
    let (t_ms, out) = first_accepted.expect("B takes over");
    assert_eq!(t_ms, 200);
    assert_eq!(
        out,
        vec![Output::Deliver {
            sample: 1200,
            status: SampleStatus::TookOver {
                previous: writer(1)
            }
        }]
    );
    assert_eq!(a.stats().weaker, 28, "every B sample before 200 ms");
    assert_eq!(a.in_charge(), Some(writer(2)));
}

#[test]
fn equal_strengths_share_and_a_lost_producer_releases_at_once() {
    let t0 = Instant::now();
    let mut a = Arbiter::new(Rules::default(), t0);
    a.handle_sample(t0, incoming(1, 5, 10_000, 0), 1);
    a.handle_sample(t0 + MS, incoming(2, 5, 10_000, 1), 2);
    assert_eq!(
        delivered(&drain(&mut a)),
        vec![1, 2],
        "equal strength is accepted"
    );
    // 3 is stronger and in charge; 2 is weaker and its persistence is long.
    a.handle_sample(t0 + MS * 2, incoming(3, 9, 10_000, 2), 3);
    a.handle_sample(t0 + MS * 3, incoming(2, 5, 10_000, 3), 4);
    assert_eq!(delivered(&drain(&mut a)), vec![3]);
    a.handle_writer_lost(writer(3));
    assert_eq!(
        drain(&mut a),
        vec![Output::Notify(Notification::ProducerLost {
            writer: writer(3),
            was_current: true
        })]
    );
    a.handle_sample(t0 + MS * 4, incoming(2, 5, 10_000, 4), 5);
    assert_eq!(
        delivered(&drain(&mut a)),
        vec![5],
        "no wait for persistence"
    );
}

#[test]
fn old_and_duplicate_samples_of_the_producer_in_charge_are_refused() {
    let t0 = Instant::now();
    let mut a = Arbiter::new(Rules::default(), t0);
    a.handle_sample(t0, incoming(1, 0, 0, 50), 1);
    a.handle_sample(t0 + MS, incoming(1, 0, 0, 50), 2);
    a.handle_sample(t0 + MS, incoming(1, 0, 0, 40), 3);
    a.handle_sample(t0 + MS, incoming(1, 0, 0, 60), 4);
    let out = drain(&mut a);
    assert_eq!(delivered(&out), vec![1, 4]);
    assert_eq!(a.stats().old_data, 2);
    assert!(out.contains(&Output::Notify(Notification::OldData {
        writer: writer(1),
        seq: 40
    })));
    // Another producer's numbers are not compared: an earlier one from 2 is fine.
    a.handle_sample(t0 + MS * 2, incoming(2, 0, 0, 10), 5);
    assert_eq!(delivered(&drain(&mut a)), vec![5]);
}

#[test]
fn old_data_is_judged_by_sequence_number_not_by_the_producers_clock() {
    let t0 = Instant::now();
    let mut a = Arbiter::new(Rules::default(), t0);
    // The producer's clock steps back an hour between its samples 1 and 2: both are new.
    let first = Incoming {
        source_ns: 7_200_000 * 1_000_000,
        ..incoming(1, 0, 0, 1)
    };
    let stepped_back = Incoming {
        source_ns: 3_600_000 * 1_000_000,
        ..incoming(1, 0, 0, 2)
    };
    a.handle_sample(t0, first, 1);
    a.handle_sample(t0 + MS, stepped_back, 2);
    // One stamped far in the future does not make the next genuine sample old.
    let future = Incoming {
        source_ns: u64::MAX,
        ..incoming(1, 0, 0, 3)
    };
    a.handle_sample(t0 + MS * 2, future, 3);
    a.handle_sample(t0 + MS * 3, incoming(1, 0, 0, 4), 4);
    assert_eq!(delivered(&drain(&mut a)), vec![1, 2, 3, 4]);
    assert_eq!(a.stats().old_data, 0);
}

#[test]
fn minimum_separation_delivers_the_newest_at_the_end_of_each_window() {
    let t0 = Instant::now();
    let rules = Rules {
        min_separation: MS * 100,
        deadline: None,
        every_producer: false,
    };
    let mut a = Arbiter::new(rules, t0);
    for i in 0..25u64 {
        let now = t0 + MS * (10 * i as u32);
        if a.poll_timeout().is_some_and(|t| t <= now) {
            a.handle_timeout(now);
        }
        a.handle_sample(now, incoming(1, 0, 0, i * 10 + 1), i);
    }
    a.handle_timeout(t0 + MS * 300);
    // Deliveries at 0, 100, 200 ms (the newest held when each window ends: the sample of
    // 90 ms, then of 190 ms) and at 300 ms (the last one held).
    assert_eq!(delivered(&drain(&mut a)), vec![0, 9, 19, 24]);
    assert_eq!(a.stats().superseded, 25 - 4);
    assert_eq!(a.poll_timeout(), None, "nothing held, no deadline");
}

#[test]
fn a_takeover_inside_a_window_keeps_its_status() {
    let t0 = Instant::now();
    let rules = Rules {
        min_separation: MS * 100,
        deadline: None,
        every_producer: false,
    };
    let mut a = Arbiter::new(rules, t0);
    a.handle_sample(t0, incoming(1, 1, 0, 0), 1);
    a.handle_sample(t0 + MS * 10, incoming(2, 9, 0, 10), 2);
    a.handle_sample(t0 + MS * 20, incoming(2, 9, 0, 20), 3);
    a.handle_timeout(t0 + MS * 100);
    let out = drain(&mut a);
    assert_eq!(
        out.last(),
        Some(&Output::Deliver {
            sample: 3,
            status: SampleStatus::TookOver {
                previous: writer(1)
            }
        })
    );
}

#[test]
fn deadlines_repeat_while_silent_and_say_never_received_before_the_first_sample() {
    let t0 = Instant::now();
    let rules = Rules {
        min_separation: Duration::ZERO,
        deadline: Some(MS * 50),
        every_producer: false,
    };
    let mut a = Arbiter::new(rules, t0);
    assert_eq!(a.poll_timeout(), Some(t0 + MS * 50));
    a.handle_timeout(t0 + MS * 50);
    a.handle_timeout(t0 + MS * 100);
    assert_eq!(
        drain(&mut a),
        vec![
            Output::Notify(Notification::NeverReceived { waited: MS * 50 }),
            Output::Notify(Notification::NeverReceived { waited: MS * 100 }),
        ]
    );
    a.handle_sample(t0 + MS * 120, incoming(1, 0, 0, 120), 1);
    assert_eq!(
        a.poll_timeout(),
        Some(t0 + MS * 170),
        "re-armed by the sample"
    );
    a.handle_timeout(t0 + MS * 169);
    assert_eq!(delivered(&drain(&mut a)), vec![1]);
    a.handle_timeout(t0 + MS * 170);
    a.handle_timeout(t0 + MS * 220);
    assert_eq!(
        drain(&mut a),
        vec![
            Output::Notify(Notification::NoNewData {
                silent_for: MS * 50
            }),
            Output::Notify(Notification::NoNewData {
                silent_for: MS * 100
            }),
        ]
    );
    // A long stall gives one notification, not a burst.
    a.handle_timeout(t0 + MS * 1000);
    assert_eq!(drain(&mut a).len(), 1);
    assert_eq!(a.poll_timeout(), Some(t0 + MS * 1050));
    assert_eq!(a.stats().deadline_misses, 5);
}

proptest! {
    /// Random traffic from three producers: never a panic, deliveries at least a window apart,
    /// and every accepted sample delivered, superseded, or the one still held.
    #[test]
    fn random_traffic_keeps_the_invariants(
        events in proptest::collection::vec((0u64..3, 0i32..3, 0u64..50, 0u64..40, any::<bool>()), 1..200),
        separation_ms in 0u64..30,
        deadline_ms in proptest::option::of(1u64..100),
    ) {
        let t0 = Instant::now();
        let rules = Rules {
            min_separation: MS * separation_ms as u32,
            deadline: deadline_ms.map(|d| MS * d as u32),
            every_producer: false,
        };
        let mut a = Arbiter::new(rules, t0);
        let mut now = t0;
        let mut last_delivery: Option<Instant> = None;
        let mut clock = [0u64; 3];
        for (n, strength, persist, step, lose) in events {
            now += MS * step as u32;
            while let Some(due) = a.poll_timeout() {
                if due > now { break; }
                a.handle_timeout(due);
                check(&mut a, due, &mut last_delivery, rules)?;
            }
            clock[n as usize] += step % 7;
            if lose {
                a.handle_writer_lost(writer(n));
            } else {
                a.handle_sample(now, incoming(n, strength, persist, clock[n as usize]), n);
            }
            check(&mut a, now, &mut last_delivery, rules)?;
        }
        let s = a.stats();
        prop_assert!(s.delivered + s.superseded <= s.accepted);
        prop_assert!(s.accepted - s.delivered - s.superseded <= 1, "at most one held");
    }
}

fn check(
    a: &mut Arbiter<u64>,
    now: Instant,
    last_delivery: &mut Option<Instant>,
    rules: Rules,
) -> Result<(), TestCaseError> {
    for output in drain(a) {
        if let Output::Deliver { .. } = output {
            if let Some(previous) = *last_delivery {
                prop_assert!(now.duration_since(previous) >= rules.min_separation);
            }
            *last_delivery = Some(now);
        }
    }
    Ok(())
}

#[test]
fn a_lost_producers_late_sample_is_delivered_without_putting_it_back_in_charge() {
    let t0 = Instant::now();
    let mut a = Arbiter::new(Rules::default(), t0);
    a.handle_sample(t0, incoming(1, 10, 10_000, 1), 101);
    a.handle_writer_lost(writer(1));
    // Its last sample was still on the way when the news came.
    a.handle_sample(t0 + MS, incoming(1, 10, 10_000, 2), 102);
    // A weaker producer takes over at once, not after the lost one's 10 s persistence.
    a.handle_sample(t0 + MS * 2, incoming(2, 5, 100, 3), 201);
    assert_eq!(delivered(&drain(&mut a)), vec![101, 102, 201]);
    // Matched again, the strong producer is in charge with its persistence again.
    a.handle_sample(t0 + MS * 3, incoming(1, 10, 10_000, 4), 104);
    a.handle_writer_back(writer(1));
    a.handle_sample(t0 + MS * 4, incoming(2, 5, 100, 5), 202);
    assert_eq!(delivered(&drain(&mut a)), vec![104]);
    assert_eq!(a.stats().weaker, 1);
}

#[test]
fn a_sample_at_the_end_of_a_window_whose_timer_has_not_run_replaces_the_held_one() {
    let t0 = Instant::now();
    let rules = Rules {
        min_separation: MS * 100,
        deadline: None,
        every_producer: false,
    };
    let mut a = Arbiter::new(rules, t0);
    a.handle_sample(t0, incoming(1, 0, 0, 1), 1);
    a.handle_sample(t0 + MS * 50, incoming(1, 0, 0, 2), 2);
    // The window ended at 100 ms; its timer is late, and seq 3 arrives first.
    a.handle_sample(t0 + MS * 100, incoming(1, 0, 0, 3), 3);
    a.handle_timeout(t0 + MS * 101);
    assert_eq!(delivered(&drain(&mut a)), vec![1, 3]);
    assert_eq!(a.stats().superseded, 1);
}

#[test]
fn every_producer_delivers_all_samples_of_all_producers_without_arbitration() {
    let t0 = Instant::now();
    let rules = Rules {
        min_separation: MS * 100,
        deadline: Some(MS * 50),
        every_producer: true,
    };
    let mut a = Arbiter::new(rules, t0);
    // A strong producer, a weak one interleaved, and a repeated seq: all delivered, fresh.
    a.handle_sample(t0, incoming(1, 9, 1000, 1), 1);
    a.handle_sample(t0 + MS, incoming(2, 1, 0, 1), 2);
    a.handle_sample(t0 + MS * 2, incoming(1, 9, 1000, 2), 3);
    a.handle_sample(t0 + MS * 3, incoming(2, 1, 0, 1), 4);
    let out = drain(&mut a);
    assert_eq!(delivered(&out), vec![1, 2, 3, 4]);
    assert!(out.iter().all(|o| matches!(
        o,
        Output::Deliver {
            status: SampleStatus::Fresh,
            ..
        }
    )));
    assert_eq!(a.stats().weaker, 0);
    assert_eq!(a.stats().superseded, 0);
    assert_eq!(a.in_charge(), None);
    // The deadline still runs from the last sample.
    assert_eq!(a.poll_timeout(), Some(t0 + MS * 53));
}

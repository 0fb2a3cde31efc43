//! Ports between tasks (threads here, through a real daemon and the data plane): send /
//! receive / reply with replies out of order, timeouts, a second owner, format checks.

mod common;

use std::sync::Arc;
use std::time::{Duration, Instant};

use ndds_client::ports::{PortError, PortOwner, PortUser, Restrictions, Usage};

const WAIT: Duration = Duration::from_secs(10);

fn participant(dir: &std::path::Path, name: &str) -> ndds_client::Participant {
    common::participant(&common::unique_config(dir, name))
}

#[test]
fn replies_given_later_and_out_of_order_reach_each_blocked_sender() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "ports");
    let owner = PortOwner::<u32, String>::declare(&p, "arm.cmd", "arm-server").unwrap();
    let users: Vec<Arc<PortUser<u32, String>>> = (0..3)
        .map(|i| Arc::new(PortUser::declare(&p, "arm.cmd", &format!("client{i}")).unwrap()))
        .collect();
    let senders: Vec<_> = users
        .iter()
        .enumerate()
        .map(|(i, user)| {
            let user = Arc::clone(user);
            std::thread::spawn(move || user.send(&(i as u32 * 10), WAIT))
        })
        .collect();
    // Take all three requests before replying to any, then reply in reverse order.
    let mut pending = Vec::new();
    for _ in 0..3 {
        pending.push(owner.receive(WAIT).unwrap());
    }
    let mut senders_seen: Vec<String> =
        pending.iter().map(|(_, h)| h.sender().to_owned()).collect();
    senders_seen.sort();
    assert_eq!(senders_seen, ["client0", "client1", "client2"]);
    for (value, handle) in pending.into_iter().rev() {
        let text = format!("{} got {value}", handle.sender());
        handle.reply(&text).unwrap();
    }
    for (i, sender) in senders.into_iter().enumerate() {
        let reply = sender.join().unwrap().unwrap();
        assert_eq!(reply, format!("client{i} got {}", i * 10));
    }

    // Several threads sending through one user handle each get their own reply.
    let user = Arc::clone(&users[0]);
    let threads: Vec<_> = (0..4)
        .map(|k| {
            let user = Arc::clone(&user);
            std::thread::spawn(move || (k, user.send(&k, WAIT)))
        })
        .collect();
    let mut handles = Vec::new();
    for _ in 0..4 {
        handles.push(owner.receive(WAIT).unwrap());
    }
    handles.sort_by_key(|(v, _)| std::cmp::Reverse(*v));
    for (v, h) in handles {
        h.reply(&format!("echo {v}")).unwrap();
    }
    for t in threads {
        let (k, reply) = t.join().unwrap();
        assert_eq!(reply.unwrap(), format!("echo {k}"));
    }
}

#[test]
fn threads_of_a_new_user_that_wait_for_the_owner_together_all_find_it() {
    // Before the fix one thread took the owner's declaration off the queue and the others
    // slept until their deadline, then timed out with the owner known.
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "ports-waiting");
    let user = Arc::new(PortUser::<u32, u32>::declare(&p, "arm.late", "client").unwrap());
    let started = Instant::now();
    let threads: Vec<_> = (0..4)
        .map(|k| {
            let user = Arc::clone(&user);
            std::thread::spawn(move || (k, user.send(&k, WAIT)))
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let owner = PortOwner::<u32, u32>::declare(&p, "arm.late", "arm-server").unwrap();
    for _ in 0..4 {
        let (value, handle) = owner.receive(WAIT).unwrap();
        handle.reply(&(value + 100)).unwrap();
    }
    for t in threads {
        let (k, reply) = t.join().unwrap();
        assert_eq!(reply.unwrap(), k + 100);
    }
    assert!(
        started.elapsed() < WAIT,
        "every sender found the owner well before its deadline: {:?}",
        started.elapsed()
    );
}

#[test]
fn without_an_owner_or_a_reply_a_send_times_out_naming_the_port() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "timeout");
    let user = PortUser::<u32, u32>::declare(&p, "gripper", "planner").unwrap();
    match user.send(&1, Duration::from_millis(300)) {
        Err(PortError::Timeout {
            port, task, owner, ..
        }) => {
            assert_eq!(
                (port.as_str(), task.as_str(), owner),
                ("gripper", "planner", None)
            );
        }
        other => panic!("expected a timeout, got {other:?}"),
    }
    // An owner that takes the request and never replies: the sender's timeout names it.
    let owner = PortOwner::<u32, u32>::declare(&p, "gripper", "gripper-driver").unwrap();
    let started = Instant::now();
    let sender = std::thread::spawn(move || user.send(&2, Duration::from_secs(2)));
    let (_request, _never_replied) = owner.receive(WAIT).unwrap();
    let err = sender.join().unwrap().unwrap_err();
    assert!(started.elapsed() >= Duration::from_secs(2));
    let text = err.to_string();
    assert!(
        text.contains("port `gripper`") && text.contains("gripper-driver"),
        "{text}"
    );
    // And a receive with nothing to receive.
    let err = owner.receive(Duration::from_millis(100)).unwrap_err();
    assert!(
        matches!(
            err,
            PortError::Timeout {
                operation: "receive",
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn a_second_owner_is_reported_to_both_owners_and_to_users() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "owners");
    let first = PortOwner::<u32, u32>::declare(&p, "camera", "vision-a").unwrap();
    let second = PortOwner::<u32, u32>::declare(&p, "camera", "vision-b").unwrap();
    let user = PortUser::<u32, u32>::declare(&p, "camera", "tracker").unwrap();
    for (owner, me, other) in [
        (&first, "vision-a", "vision-b"),
        (&second, "vision-b", "vision-a"),
    ] {
        match owner.receive(WAIT) {
            Err(PortError::SecondOwner {
                port,
                first,
                second,
            }) => {
                assert_eq!((port.as_str(), first.as_str()), ("camera", me));
                assert!(second.starts_with(other), "{second}");
            }
            other => panic!("expected a second-owner error, got {other:?}"),
        }
    }
    assert!(common::eventually(WAIT, || matches!(
        user.send(&1, Duration::from_millis(100)),
        Err(PortError::SecondOwner { .. })
    )));
}

#[test]
fn different_message_formats_are_refused_naming_both_sides() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "formats");
    let _owner = PortOwner::<u32, String>::declare(&p, "joints", "servo").unwrap();
    let user = PortUser::<(f64, f64), String>::declare(&p, "joints", "teleop").unwrap();
    let err = user.send(&(1.0, 2.0), WAIT).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, PortError::Format { .. }), "{text}");
    assert!(
        text.contains("port `joints`") && text.contains("`teleop`") && text.contains("`servo`"),
        "{text}"
    );
    assert!(matches!(
        PortUser::<u32, u32>::declare(&p, "a/b", "x"),
        Err(PortError::BadName(_))
    ));
}

#[test]
fn described_messages_match_the_typed_side_and_need_their_descriptions() {
    use ndds_client::TypeDescription;
    use ndds_client::ports::Encoded;
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "described");
    // A user whose types are described at run time (as ndds-python's are) talks to a typed
    // owner: the same fingerprints, the same bytes.
    let owner = PortOwner::<(u32, String), f64>::declare(&p, "scale", "typed_owner").unwrap();
    let user = PortUser::<Encoded, Encoded>::declare_described(
        &p,
        "scale",
        "described_user",
        &[Usage::Send],
        &TypeDescription::of::<(u32, String)>(),
        &TypeDescription::of::<f64>(),
    )
    .unwrap();
    let server = std::thread::spawn(move || {
        let (request, reply) = owner.receive(WAIT).unwrap();
        reply.reply(&(f64::from(request.0) * 2.0)).unwrap();
        request
    });
    let request = postcard::to_stdvec(&(21u32, "x".to_owned())).unwrap();
    let answer = user.send(&Encoded(request), WAIT).unwrap();
    assert_eq!(postcard::from_bytes::<f64>(&answer.0).unwrap(), 42.0);
    assert_eq!(server.join().unwrap(), (21, "x".to_owned()));
    // The typed constructors refuse `Encoded` (it has no Rust type to trace), naming the port.
    let err = PortUser::<Encoded, Encoded>::declare(&p, "raw", "x")
        .err()
        .unwrap();
    assert!(matches!(err, PortError::Undescribed { .. }), "{err}");
    assert!(err.to_string().contains("declare_described"), "{err}");
    let err = PortOwner::<Encoded, Encoded>::declare(&p, "raw", "x")
        .err()
        .unwrap();
    assert!(matches!(err, PortError::Undescribed { .. }), "{err}");
}

#[test]
fn an_urgent_query_is_answered_before_less_urgent_ones_that_arrived_earlier() {
    use ndds_client::ports::Responder;
    use std::sync::Mutex;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "query");
    let log = Arc::new(Mutex::new(Vec::<String>::new()));
    let mut responder = Responder::new(&p, "arm-server").unwrap();
    let routine_log = Arc::clone(&log);
    responder
        .handle("arm.status", 0, move |n: u32| {
            routine_log.lock().unwrap().push(format!("status {n}"));
            if n == 0 {
                // The first query keeps the worker busy while the others queue up.
                std::thread::sleep(Duration::from_millis(1000));
            }
            n + 100
        })
        .unwrap();
    let urgent_log = Arc::clone(&log);
    responder
        .handle("arm.stop", 10, move |n: u32| {
            urgent_log.lock().unwrap().push(format!("stop {n}"));
            n + 1000
        })
        .unwrap();
    let query_user = |port: &str, task: &str| {
        Arc::new(PortUser::<u32, u32>::declare_with(&p, port, task, &[Usage::Query]).unwrap())
    };
    let status = query_user("arm.status", "monitor");
    let stop = query_user("arm.stop", "operator");
    let query = |user: &Arc<PortUser<u32, u32>>, n: u32| {
        let user = Arc::clone(user);
        std::thread::spawn(move || user.query(&n, WAIT))
    };
    // Both users know the owner and are matched before the measured sequence.
    assert_eq!(status.query(&50, WAIT).unwrap(), 150);
    assert_eq!(stop.query(&99, WAIT).unwrap(), 1099);
    log.lock().unwrap().clear();
    let first = query(&status, 0);
    assert!(common::eventually(WAIT, || log.lock().unwrap().len() == 1));
    let routine: Vec<_> = (1..4)
        .map(|n| {
            let t = query(&status, n);
            std::thread::sleep(Duration::from_millis(30));
            t
        })
        .collect();
    let urgent = query(&stop, 7);
    assert_eq!(first.join().unwrap().unwrap(), 100);
    assert_eq!(urgent.join().unwrap().unwrap(), 1007);
    for (n, t) in routine.into_iter().enumerate() {
        assert_eq!(t.join().unwrap().unwrap(), n as u32 + 101);
    }
    assert_eq!(
        *log.lock().unwrap(),
        ["status 0", "stop 7", "status 1", "status 2", "status 3"]
    );
}

#[test]
fn waitfor_joins_three_tasks_and_each_combines_every_message() {
    use ndds_client::ports::Rendezvous;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "waitfor");
    let tasks = ["left-arm", "right-arm", "vision"];
    let threads: Vec<_> = tasks
        .iter()
        .enumerate()
        .map(|(i, task)| {
            let p = p.clone();
            let task = (*task).to_owned();
            std::thread::spawn(move || {
                let rv = Rendezvous::<u64>::join(&p, "grasp", &task, &tasks).unwrap();
                let mut results = Vec::new();
                for round in 0..3u64 {
                    // Arrive at different times each round.
                    std::thread::sleep(Duration::from_millis(20 * ((i as u64 + round) % 3)));
                    let mine = (i as u64 + 1) * 10 + round;
                    let combined = rv
                        .wait(&mine, WAIT, |all| {
                            assert_eq!(all.len(), 3, "every message is seen");
                            all.iter()
                                .map(|(t, v)| format!("{t}={v}"))
                                .collect::<Vec<_>>()
                                .join(",")
                        })
                        .unwrap_or_else(|e| panic!("{task} round {round}: {e}"));
                    results.push(combined);
                }
                results
            })
        })
        .collect();
    let results: Vec<Vec<String>> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    for round in 0..3 {
        let expected = format!(
            "left-arm={},right-arm={},vision={}",
            10 + round,
            20 + round,
            30 + round
        );
        for r in &results {
            assert_eq!(r[round], expected, "round {round}");
        }
    }

    // A task that never comes: the others time out, naming it.
    let rv = Rendezvous::<u64>::join(&p, "lonely", "a", &["a", "b"]).unwrap();
    match rv.wait(&1, Duration::from_millis(300), |_| ()) {
        Err(PortError::WaitFor {
            name,
            task,
            missing,
            ..
        }) => {
            assert_eq!(
                (name.as_str(), task.as_str(), missing),
                ("lonely", "a", vec!["b".to_owned()])
            );
        }
        other => panic!("expected a waitfor timeout, got {other:?}"),
    }
}

#[test]
fn select_takes_the_highest_priority_port_first_and_fifo_within_a_port() {
    use ndds_client::ports::{Selectable, select};

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "select");
    let low = PortOwner::<u32, u32>::declare(&p, "log", "server").unwrap();
    let mid = PortOwner::<u32, u32>::declare(&p, "status", "server").unwrap();
    let high = PortOwner::<u32, u32>::declare(&p, "estop", "server").unwrap();
    // `log` has no priority: it comes after every port with one, a negative one too.
    mid.set_priority(-5);
    high.set_priority(9);
    assert_eq!(
        [low.priority(), mid.priority(), high.priority()],
        [None, Some(-5), Some(9)]
    );
    let users: Vec<Arc<PortUser<u32, u32>>> = ["log", "status", "estop"]
        .iter()
        .map(|port| Arc::new(PortUser::declare(&p, port, "client").unwrap()))
        .collect();
    // Warm up: each user knows its owner and is matched, so later sends go out at once.
    for (user, owner) in users.iter().zip([&low, &mid, &high]) {
        let user = Arc::clone(user);
        let warm = std::thread::spawn(move || user.send(&99, WAIT));
        let (_, reply) = owner.receive(WAIT).unwrap();
        reply.reply(&99).unwrap();
        warm.join().unwrap().unwrap();
    }
    // Two requests per port, sent in low-to-high order; each waits for its reply.
    let mut senders = Vec::new();
    for (k, user) in users.iter().enumerate() {
        for n in 0..2 {
            let user = Arc::clone(user);
            let value = k as u32 * 10 + n;
            senders.push(std::thread::spawn(move || user.send(&value, WAIT)));
            std::thread::sleep(Duration::from_millis(30));
        }
    }
    let ports: [&dyn Selectable; 3] = [&low, &mid, &high];
    assert!(common::eventually(WAIT, || ports
        .iter()
        .map(|p| p.waiting())
        .sum::<usize>()
        == 6));
    let mut order = Vec::new();
    for _ in 0..6 {
        let (value, reply) = match select(&ports, WAIT).unwrap() {
            0 => low.receive(WAIT).unwrap(),
            1 => mid.receive(WAIT).unwrap(),
            _ => high.receive(WAIT).unwrap(),
        };
        order.push(value);
        reply.reply(&value).unwrap();
    }
    assert_eq!(order, [20, 21, 10, 11, 0, 1]);
    for s in senders {
        s.join().unwrap().unwrap();
    }
    assert!(matches!(
        select(&ports, Duration::from_millis(50)),
        Err(PortError::Timeout {
            operation: "select",
            ..
        })
    ));
}

#[test]
fn sendall_reaches_every_user_and_returns_on_the_first_reply() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "sendall");
    let owner = PortOwner::<u32, String>::declare(&p, "fleet", "dispatcher").unwrap();
    let users: Vec<_> = ["robot1", "robot2", "robot3"]
        .iter()
        .map(|task| {
            PortUser::<u32, String>::declare_with(&p, "fleet", task, &[Usage::ReceiveAll]).unwrap()
        })
        .collect();
    assert!(common::eventually(WAIT, || owner.users() == 3));
    let threads: Vec<_> = users
        .into_iter()
        .enumerate()
        .map(|(i, user)| {
            std::thread::spawn(move || {
                user.receive_all(WAIT, |v| {
                    std::thread::sleep(Duration::from_millis(50 * i as u64));
                    format!("robot{} has {v}", i + 1)
                })
            })
        })
        .collect();
    let replies = owner.sendall(&7, WAIT).unwrap();
    let mut answers = vec![replies.first().clone()];
    while let Some(next) = replies.next(Duration::from_secs(2)) {
        answers.push(next.unwrap());
    }
    answers.sort();
    assert_eq!(
        answers,
        [
            ("robot1".to_owned(), "robot1 has 7".to_owned()),
            ("robot2".to_owned(), "robot2 has 7".to_owned()),
            ("robot3".to_owned(), "robot3 has 7".to_owned()),
        ]
    );
    for t in threads {
        assert_eq!(t.join().unwrap().unwrap(), 7);
    }
}

fn refused(result: Result<u32, PortError>) -> (String, &'static str) {
    match result {
        Err(PortError::Refused {
            port,
            owner,
            user,
            restriction,
            ..
        }) => (format!("{port}/{owner}/{user}"), restriction),
        other => panic!("expected a refusal, got {other:?}"),
    }
}

#[test]
fn each_restriction_refuses_what_it_should_naming_the_port_and_both_sides() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "restrict");
    let short = Duration::from_secs(3);

    // User list.
    let owner = PortOwner::<u32, u32>::declare_with(
        &p,
        "cell",
        "cell-controller",
        Restrictions {
            users: vec!["planner".into()],
            ..Restrictions::default()
        },
    )
    .unwrap();
    let intruder = PortUser::<u32, u32>::declare(&p, "cell", "intruder").unwrap();
    let (who, what) = refused(intruder.send(&1, short));
    assert_eq!(
        (who.as_str(), what),
        ("cell/cell-controller/intruder", "user list")
    );
    let planner = Arc::new(PortUser::<u32, u32>::declare(&p, "cell", "planner").unwrap());
    let sender = {
        let planner = Arc::clone(&planner);
        std::thread::spawn(move || planner.send(&2, WAIT))
    };
    let (v, reply) = owner.receive(WAIT).unwrap();
    reply.reply(&(v * 2)).unwrap();
    assert_eq!(sender.join().unwrap().unwrap(), 4);
    assert!(common::eventually(WAIT, || owner
        .refusals()
        .iter()
        .any(|r| r.contains("intruder") && r.contains("user list"))));

    // Usage: the owner answers queries only (usage Response); a user declared for send is
    // refused (Send complements the owner's Receive), an operation a user did not declare is
    // refused locally, and so is an owner's operation outside its own usages.
    let queries = PortOwner::<u32, u32>::declare_with(
        &p,
        "lookup",
        "db",
        Restrictions {
            usages: vec![Usage::Response],
            ..Restrictions::default()
        },
    )
    .unwrap();
    let sender = PortUser::<u32, u32>::declare(&p, "lookup", "writer").unwrap();
    let err = sender.send(&1, short).unwrap_err();
    assert!(
        err.to_string()
            .contains("Send complements none of the owner's usages [Response]"),
        "{err}"
    );
    let (who, what) = refused(Err::<u32, _>(err));
    assert_eq!((who.as_str(), what), ("lookup/db/writer", "usage"));
    let (_, what) = refused(sender.query(&1, short));
    assert_eq!(what, "usage");
    let querier =
        PortUser::<u32, u32>::declare_with(&p, "lookup", "reader", &[Usage::Query]).unwrap();
    assert!(common::eventually(WAIT, || queries
        .present_users()
        .iter()
        .any(|u| u.starts_with("reader"))));
    assert!(
        !queries.refusals().iter().any(|r| r.contains("reader")),
        "{:?}",
        queries.refusals()
    );
    drop(querier);
    for err in [
        queries.sendall(&1, short).err().unwrap(),
        queries.callall(&1, short).err().unwrap(),
        queries.send_to("reader", &1, short).err().unwrap(),
    ] {
        assert!(
            matches!(
                &err,
                PortError::Refused {
                    restriction: "usage",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("it declared [Response]"), "{err}");
    }
    // An owner's usage is not a user's.
    let odd = PortUser::<u32, u32>::declare_with(&p, "lookup", "odd", &[Usage::SendAll]).unwrap();
    let err = odd.receive_all(short, |n| *n).unwrap_err();
    assert!(matches!(err, PortError::Refused { .. }), "{err}");

    // Maximum active users: the second user is refused while the first is active.
    let _solo = PortOwner::<u32, u32>::declare_with(
        &p,
        "tool",
        "tool-changer",
        Restrictions {
            max_users: Some(1),
            ..Restrictions::default()
        },
    )
    .unwrap();
    let first = PortUser::<u32, u32>::declare(&p, "tool", "first").unwrap();
    std::thread::sleep(Duration::from_millis(600));
    let second = PortUser::<u32, u32>::declare(&p, "tool", "second").unwrap();
    let (who, what) = refused(second.send(&1, short));
    assert_eq!(
        (who.as_str(), what),
        ("tool/tool-changer/second", "maximum active users")
    );
    drop(first);

    // Timeout: the port's 300 ms bounds a send that asked for 10 s.
    let _slow = PortOwner::<u32, u32>::declare_with(
        &p,
        "slow",
        "sleeper",
        Restrictions {
            timeout_ms: Some(300),
            ..Restrictions::default()
        },
    )
    .unwrap();
    let user = PortUser::<u32, u32>::declare(&p, "slow", "impatient").unwrap();
    let started = Instant::now();
    let err = user.send(&1, Duration::from_secs(10)).unwrap_err();
    assert!(matches!(err, PortError::Timeout { .. }), "{err}");
    assert!(
        started.elapsed() < Duration::from_secs(5),
        "{:?}",
        started.elapsed()
    );
}

#[test]
fn a_port_declared_wrong_says_what_is_wrong() {
    use ndds_client::ports::{Filter, Rendezvous, Responder};

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "misdeclared");
    let filter = |capacity| Restrictions {
        filter: Some(Filter::BoundedBuffer { capacity }),
        ..Restrictions::default()
    };
    let refused = PortOwner::<u32, ()>::declare_with(&p, "empty.buffer", "gate", filter(0));
    let err = refused.err().expect("a buffer of 0 is refused");
    assert!(
        matches!(&err, PortError::ZeroCapacity { port } if port == "empty.buffer"),
        "{err}"
    );
    let refused = PortOwner::<u32, u32>::declare_with(&p, "typed.buffer", "gate", filter(2));
    let err = refused
        .err()
        .expect("a filter with replies of u32 is refused");
    assert!(
        matches!(&err, PortError::ReplyType { port, expected: "()", got: "u32" } if port == "typed.buffer"),
        "{err}"
    );
    let refused = Rendezvous::<u32>::join(&p, "meet", "carol", &["alice", "bob"]);
    let err = refused
        .err()
        .expect("a task the rendezvous does not name is refused");
    assert!(
        matches!(&err, PortError::UnknownTask { name, task, tasks }
            if name == "meet" && task == "carol" && tasks == &["alice", "bob"]),
        "{err}"
    );
    let mut responder = Responder::new(&p, "server").unwrap();
    responder.handle("twice.query", 0, |n: u32| n).unwrap();
    let err = responder
        .handle("twice.query", 0, |n: u32| n + 1)
        .expect_err("a second handler for one port is refused");
    assert!(
        matches!(&err, PortError::Handler { port, .. } if port == "twice.query"),
        "{err}"
    );
}

#[test]
fn a_bounded_buffer_filter_makes_sends_non_blocking_until_it_is_full() {
    use ndds_client::ports::Filter;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "filter");
    let owner = PortOwner::<u32, ()>::declare_with(
        &p,
        "conveyor",
        "gate",
        Restrictions {
            filter: Some(Filter::BoundedBuffer { capacity: 3 }),
            ..Restrictions::default()
        },
    )
    .unwrap();
    // The buffer keeps the usages the owner declared (none: any).
    assert!(owner.restrictions().usages.is_empty());
    let user = PortUser::<u32, ()>::declare(&p, "conveyor", "loader").unwrap();
    // Three sends return without the owner receiving anything.
    for n in 1..=3 {
        user.send(&n, WAIT).unwrap();
    }
    // The fourth waits for room: with nobody receiving, it times out, and its sender
    // withdraws it, so the buffer never takes it.
    let err = user.send(&4, Duration::from_millis(500)).unwrap_err();
    assert!(matches!(err, PortError::Timeout { .. }), "{err}");
    assert!(common::eventually(WAIT, || owner.withdrawn() == 1));
    // The owner takes one: the room stays empty.
    let (first, reply) = owner.receive(WAIT).unwrap();
    reply.reply(&()).unwrap();
    assert_eq!(first, 1);
    {
        use ndds_client::ports::Selectable;
        assert_eq!(owner.waiting(), 2);
    }
    // One more taken: room for a new send, which returns at once; arrival order is kept.
    assert_eq!(owner.receive(WAIT).unwrap().0, 2);
    user.send(&5, WAIT).unwrap();
    let mut rest = Vec::new();
    for _ in 0..2 {
        rest.push(owner.receive(WAIT).unwrap().0);
    }
    assert_eq!(rest, [3, 5]);
    assert!(matches!(
        owner.receive(Duration::from_millis(200)),
        Err(PortError::Timeout { .. })
    ));
    // A filter that answers at once needs a reply type of ().
    let bad = PortOwner::<u32, u32>::declare_with(
        &p,
        "other",
        "gate",
        Restrictions {
            filter: Some(Filter::BoundedBuffer { capacity: 1 }),
            ..Restrictions::default()
        },
    );
    assert!(bad.is_err());
}

#[test]
fn every_primitive_has_an_async_form() {
    use ndds_client::ports::{Rendezvous, Responder};

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "async");
    let owner = Arc::new(PortOwner::<u32, u32>::declare(&p, "async.cmd", "server").unwrap());
    let user = Arc::new(
        PortUser::<u32, u32>::declare_with(
            &p,
            "async.cmd",
            "client",
            &[Usage::Send, Usage::ReceiveAll, Usage::Receive],
        )
        .unwrap(),
    );
    let mut responder = Responder::new(&p, "server").unwrap();
    responder.handle("async.query", 0, |n: u32| n * 3).unwrap();
    let asker = Arc::new(
        PortUser::<u32, u32>::declare_with(&p, "async.query", "asker", &[Usage::Query]).unwrap(),
    );
    let left =
        Arc::new(Rendezvous::<u32>::join(&p, "async.rv", "left", &["left", "right"]).unwrap());
    let right =
        Arc::new(Rendezvous::<u32>::join(&p, "async.rv", "right", &["left", "right"]).unwrap());

    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    // send / receive / reply on one single-threaded executor: neither side blocks it, so the
    // owner's future can serve the user's request while the user's future waits.
    let reply = runtime.block_on(async {
        let sent = user.send_async(7, WAIT);
        let serve = async {
            let (n, handle) = owner.receive_async(WAIT).await.unwrap();
            handle.reply(&(n + 1)).unwrap();
        };
        let (reply, ()) = tokio::join!(sent, serve);
        reply
    });
    assert_eq!(reply.unwrap(), 8);
    let queried = runtime.block_on(asker.query_async(4, WAIT)).unwrap();
    assert_eq!(queried, 12);
    let (a, b) = runtime.block_on(async {
        tokio::join!(
            left.wait_async(1, WAIT, |all| all.values().sum::<u32>()),
            right.wait_async(2, WAIT, |all| all.values().sum::<u32>())
        )
    });
    assert_eq!((a.unwrap(), b.unwrap()), (3, 3));
    assert!(common::eventually(WAIT, || owner.users() == 1));
    let (first, answered) = runtime.block_on(async {
        tokio::join!(
            owner.sendall_async(9, WAIT),
            user.receive_all_async(WAIT, |v| v * 10)
        )
    });
    assert_eq!(first.unwrap(), ("client".to_owned(), 90));
    assert_eq!(answered.unwrap(), 9);
    assert!(common::eventually(WAIT, || owner.present_users().len() == 1));
    let (all, one, answered_all, answered_one) = runtime.block_on(async {
        tokio::join!(
            owner.callall_async(5, WAIT),
            owner.send_to_async("client", 6, WAIT),
            user.receive_all_async(WAIT, |v| v + 1),
            user.receive_async(WAIT, |v| v + 2)
        )
    });
    let all = all.unwrap();
    assert_eq!(
        (all.replies, all.missing),
        (vec![("client".to_owned(), 6)], vec![])
    );
    assert_eq!(one.unwrap(), 8);
    assert_eq!((answered_all.unwrap(), answered_one.unwrap()), (5, 6));
}

#[test]
fn a_send_that_timed_out_is_never_received_later() {
    use ndds_client::ports::Responder;
    use std::sync::Mutex;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "withdraw");
    let owner = PortOwner::<u32, u32>::declare(&p, "slow.cmd", "server").unwrap();
    let user = Arc::new(PortUser::<u32, u32>::declare(&p, "slow.cmd", "client").unwrap());
    // Warm up: the user knows the owner, so the next request goes out at once.
    let warm = {
        let user = Arc::clone(&user);
        std::thread::spawn(move || user.send(&0, WAIT))
    };
    let (value, reply) = owner.receive(WAIT).unwrap();
    reply.reply(&value).unwrap();
    assert_eq!(warm.join().unwrap().unwrap(), 0);

    // The owner is busy elsewhere: the send times out, and its request is withdrawn.
    let err = user.send(&7, Duration::from_millis(300)).unwrap_err();
    assert!(matches!(err, PortError::Timeout { .. }), "{err}");
    // Once the withdrawal is there (it follows the request within the network's delay; an
    // owner that takes the request before that has it), the request is gone and counted.
    assert!(common::eventually(WAIT, || {
        use ndds_client::ports::Selectable;
        owner.waiting();
        owner.withdrawn() == 1
    }));
    assert!(matches!(
        owner.receive(Duration::from_millis(200)),
        Err(PortError::Timeout { .. })
    ));
    // The port goes on as before.
    let next = {
        let user = Arc::clone(&user);
        std::thread::spawn(move || user.send(&8, WAIT))
    };
    let (value, reply) = owner.receive(WAIT).unwrap();
    assert_eq!(value, 8);
    assert!(!reply.is_withdrawn());
    reply.reply(&80).unwrap();
    assert_eq!(next.join().unwrap().unwrap(), 80);

    // A query that times out while it waits behind a long handler is not answered later.
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut responder = Responder::new(&p, "server").unwrap();
    {
        let seen = Arc::clone(&seen);
        responder
            .handle("slow.query", 0, move |n: u32| {
                seen.lock().unwrap().push(n);
                if n == 1 {
                    std::thread::sleep(Duration::from_millis(800));
                }
                n
            })
            .unwrap();
    }
    let asker = |task: &str| {
        Arc::new(
            PortUser::<u32, u32>::declare_with(&p, "slow.query", task, &[Usage::Query]).unwrap(),
        )
    };
    let (first, second) = (asker("first"), asker("second"));
    assert_eq!(first.query(&10, WAIT).unwrap(), 10);
    assert_eq!(second.query(&20, WAIT).unwrap(), 20);
    let long = {
        let first = Arc::clone(&first);
        std::thread::spawn(move || first.query(&1, WAIT))
    };
    assert!(common::eventually(WAIT, || seen
        .lock()
        .unwrap()
        .contains(&1)));
    let err = second.query(&2, Duration::from_millis(200)).unwrap_err();
    assert!(matches!(err, PortError::Timeout { .. }), "{err}");
    assert_eq!(long.join().unwrap().unwrap(), 1);
    assert_eq!(second.query(&3, WAIT).unwrap(), 3);
    assert_eq!(
        *seen.lock().unwrap(),
        [10, 20, 1, 3],
        "query 2 was never run"
    );
}

#[test]
fn sendall_reaches_only_the_users_the_restrictions_allow() {
    use ndds_client::ports::{Broadcast, BroadcastReply, PortWire};
    use ndds_client::{ConsumerQos, ProducerQos, Reliability};

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "sendall-restricted");
    let owner = PortOwner::<u32, String>::declare_with(
        &p,
        "crew",
        "foreman",
        Restrictions {
            users: vec!["alice".into()],
            ..Restrictions::default()
        },
    )
    .unwrap();
    let member = |task: &str| {
        PortUser::<u32, String>::declare_with(&p, "crew", task, &[Usage::ReceiveAll]).unwrap()
    };
    let (alice, mallory) = (member("alice"), member("mallory"));
    // A process that bypasses its own checks: it reads the broadcast and answers first.
    let reliable = Reliability::Reliable { depth: 16 };
    let eavesdrop = p
        .consumer_with_type::<Broadcast>(
            "port/crew/all",
            Broadcast::description(),
            ConsumerQos {
                reliability: reliable,
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let forge = p
        .producer_with_type::<BroadcastReply>(
            "port/crew/all-reply",
            BroadcastReply::description(),
            ProducerQos {
                reliability: reliable,
                ..ProducerQos::default()
            },
        )
        .unwrap();
    assert!(common::eventually(WAIT, || owner.users() == 3));
    // The forged reply must reach the owner (a reliable write before the match reaches nobody).
    assert!(common::eventually(WAIT, || !forge.matched().is_empty()));
    let refused_member = std::thread::spawn(move || {
        mallory.receive_all(Duration::from_secs(3), |v| format!("mallory has {v}"))
    });
    let forger = std::thread::spawn(move || {
        let broadcast = eavesdrop.recv_timeout(WAIT).unwrap().value;
        forge
            .write(&BroadcastReply {
                owner: broadcast.owner,
                id: broadcast.id,
                task: "mallory".into(),
                user: "0000000000000bad".into(),
                payload: postcard::to_stdvec(&"forged".to_owned()).unwrap(),
            })
            .unwrap();
    });
    let allowed = std::thread::spawn(move || {
        // Late, so that the forged reply comes first.
        alice.receive_all(WAIT, |v| {
            std::thread::sleep(Duration::from_millis(300));
            format!("alice has {v}")
        })
    });
    let replies = owner.sendall(&7, WAIT).unwrap();
    assert_eq!(
        replies.first(),
        &("alice".to_owned(), "alice has 7".to_owned())
    );
    assert!(replies.next(Duration::from_millis(500)).is_none());
    assert_eq!(owner.refused_replies(), 1, "the forged reply");
    forger.join().unwrap();
    assert_eq!(allowed.join().unwrap().unwrap(), 7);
    let (who, restriction) = refused(refused_member.join().unwrap());
    assert_eq!(
        (who.as_str(), restriction),
        ("crew/foreman/mallory", "user list")
    );
}

#[test]
fn a_reply_from_a_user_that_left_just_after_is_still_taken() {
    use ndds_client::ports::{OwnerInfo, PortWire};
    use ndds_client::{ConsumerQos, Reliability};

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "sendall-leaver");
    let owner = Arc::new(
        PortOwner::<u32, u32>::declare_with(
            &p,
            "roll",
            "teacher",
            Restrictions {
                users: vec!["pupil".into()],
                ..Restrictions::default()
            },
        )
        .unwrap(),
    );
    let declarations = p
        .consumer_with_type::<OwnerInfo>(
            "port/roll/owner",
            OwnerInfo::description(),
            ConsumerQos {
                reliability: Reliability::Reliable { depth: 16 },
                ..ConsumerQos::default()
            },
        )
        .unwrap();
    let admitted = |want: usize| {
        let until = Instant::now() + WAIT;
        while let Some(left) = until.checked_duration_since(Instant::now()) {
            match declarations.recv_timeout(left) {
                Ok(s) if s.value.admitted.len() == want => return true,
                Ok(_) => {}
                Err(_) => return false,
            }
        }
        false
    };
    let pupil =
        PortUser::<u32, u32>::declare_with(&p, "roll", "pupil", &[Usage::ReceiveAll]).unwrap();
    assert!(admitted(1), "the pupil was never admitted");
    assert!(common::eventually(WAIT, || owner.users() == 1));
    // The broadcast goes out on the first poll; the owner reads replies only when polled
    // again, after it has heard that the pupil left: the reply is judged after the loss.
    let mut sendall = Box::pin(owner.sendall_async(4, WAIT));
    assert!(futures_util::FutureExt::now_or_never(sendall.as_mut()).is_none());
    std::thread::spawn(move || {
        pupil.receive_all(WAIT, |n| n * 10).unwrap();
        drop(pupil);
    })
    .join()
    .unwrap();
    assert!(admitted(0), "the owner never heard that the pupil left");
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let (who, reply) = runtime.block_on(sendall).unwrap();
    assert_eq!((who.as_str(), reply), ("pupil", 40));
    assert_eq!(owner.refused_replies(), 0);
}

#[test]
fn a_responders_port_takes_restrictions_like_any_owners() {
    use ndds_client::ports::Responder;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "responder-restricted");
    let mut responder = Responder::new(&p, "parts-db").unwrap();
    responder
        .handle_with(
            "parts.query",
            Restrictions {
                users: vec!["planner".into()],
                timeout_ms: Some(300),
                ..Restrictions::default()
            },
            |n: u32| {
                if n == 0 {
                    std::thread::sleep(Duration::from_secs(1));
                }
                n + 1
            },
        )
        .unwrap();
    let asker = |task: &str| {
        PortUser::<u32, u32>::declare_with(&p, "parts.query", task, &[Usage::Query]).unwrap()
    };
    let (who, what) = refused(asker("intruder").query(&1, Duration::from_secs(3)));
    assert_eq!(
        (who.as_str(), what),
        ("parts.query/parts-db/intruder", "user list")
    );
    let planner = asker("planner");
    assert_eq!(planner.query(&1, WAIT).unwrap(), 2);
    // The port's timeout bounds a query, whatever its caller allowed.
    let started = Instant::now();
    let err = planner.query(&0, WAIT).unwrap_err();
    assert!(matches!(err, PortError::Timeout { .. }), "{err}");
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "{:?}",
        started.elapsed()
    );
}

#[test]
fn a_replacement_takes_over_the_port_of_a_hung_owner() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "takeover");
    let hung = PortOwner::<u32, u32>::declare(&p, "gripper", "grip-server").unwrap();
    let user = Arc::new(PortUser::<u32, u32>::declare(&p, "gripper", "planner").unwrap());
    // The owner still announces itself but never receives: the user's sends time out.
    let err = user.send(&1, Duration::from_millis(500)).unwrap_err();
    assert!(
        matches!(&err, PortError::Timeout { owner: Some(o), .. } if o == "grip-server"),
        "{err}"
    );
    // A replacement under another name, in the same process.
    let new = PortOwner::<u32, u32>::take_over(
        &p,
        "gripper",
        "grip-server-2",
        Restrictions::default(),
        WAIT,
    )
    .unwrap();
    assert_eq!((hung.claim(), new.claim()), (0, 1));
    // The old owner is told, and serves no more; the replacement sees no conflict.
    assert!(common::eventually(WAIT, || hung
        .superseded_by()
        .is_some_and(|by| by.starts_with("grip-server-2"))));
    assert!(matches!(
        hung.receive(Duration::from_millis(100)),
        Err(PortError::Superseded { .. })
    ));
    assert_eq!(new.conflict(), None);
    // Users send to the replacement.
    let sender = {
        let user = Arc::clone(&user);
        std::thread::spawn(move || user.send(&2, WAIT))
    };
    let (value, reply) = new.receive(WAIT).unwrap();
    assert_eq!(value, 2);
    reply.reply(&20).unwrap();
    assert_eq!(sender.join().unwrap().unwrap(), 20);
    // Two declared owners of one claim are still a conflict, reported as before.
    let rival = PortOwner::<u32, u32>::declare(&p, "gripper", "rival").unwrap();
    assert_eq!(rival.claim(), 0);
    assert!(common::eventually(WAIT, || hung.conflict().is_some()));
    assert_eq!(
        new.conflict(),
        None,
        "a lower claim does not contest the port"
    );
    // A second takeover claims above every claim it heard.
    let third = PortOwner::<u32, u32>::take_over(
        &p,
        "gripper",
        "grip-server-3",
        Restrictions::default(),
        WAIT,
    )
    .unwrap();
    assert_eq!(third.claim(), 2);
    assert!(common::eventually(WAIT, || new.superseded_by().is_some()));
}

#[test]
fn a_request_held_by_a_replaced_owner_is_run_once_by_its_replacement() {
    use ndds_client::ports::Selectable;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "takeover-inflight");
    let hung = PortOwner::<u32, u32>::declare(&p, "feeder", "feed-server").unwrap();
    let user = Arc::new(PortUser::<u32, u32>::declare(&p, "feeder", "line").unwrap());
    // A request reaches the hung owner, which never receives it.
    let sender = {
        let user = Arc::clone(&user);
        std::thread::spawn(move || user.send(&5, WAIT))
    };
    assert!(common::eventually(WAIT, || hung.waiting() == 1));
    let new = PortOwner::<u32, u32>::take_over(
        &p,
        "feeder",
        "feed-server-2",
        Restrictions::default(),
        WAIT,
    )
    .unwrap();
    // The sender learns of the replacement and sends the request again, to it: it is run
    // there once (the copy addressed to the replaced owner is dropped).
    let (value, reply) = new.receive(WAIT).unwrap();
    assert_eq!(value, 5);
    reply.reply(&50).unwrap();
    assert_eq!(sender.join().unwrap().unwrap(), 50);
    let again = new.receive(Duration::from_millis(300));
    assert!(matches!(again, Err(PortError::Timeout { .. })), "{again:?}");
    assert!(new.misaddressed() >= 1, "the copy for the replaced owner");
    // The replaced owner let go of the requests topic: it does not hold its users'
    // flow-control window, so more requests than its queue and the window (256 each) pass.
    let server = std::thread::spawn(move || {
        for _ in 0..600 {
            let (n, reply) = new.receive(WAIT).unwrap();
            reply.reply(&(n + 1)).unwrap();
        }
        new
    });
    for n in 0..600 {
        assert_eq!(user.send(&n, WAIT).unwrap(), n + 1);
    }
    let new = server.join().unwrap();
    assert_eq!(new.misaddressed(), 1);
    // Nor does it keep the request it held (its sender went to the replacement).
    assert_eq!(hung.waiting(), 0);
    assert!(matches!(
        hung.receive(Duration::from_millis(100)),
        Err(PortError::Superseded { .. })
    ));
}

#[test]
fn an_owner_sends_to_one_user_and_queries_them_all_with_callall() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "owner-to-users");
    let parent = PortOwner::<u32, u32>::declare(&p, "children", "parent").unwrap();
    let child = |task: &str, usages: &[Usage]| {
        Arc::new(PortUser::<u32, u32>::declare_with(&p, "children", task, usages).unwrap())
    };
    let left = child("left", &[Usage::Receive, Usage::ReceiveAll]);
    let right = child("right", &[Usage::ReceiveAll]);
    let _quiet = child("quiet", &[Usage::ReceiveAll]);
    assert!(
        common::eventually(WAIT, || parent.present_users().len() == 3),
        "{:?}",
        parent.present_users()
    );
    assert_eq!(
        parent.present_users(),
        [
            "left [Receive, ReceiveAll]",
            "quiet [ReceiveAll]",
            "right [ReceiveAll]"
        ]
    );

    // To one user: it answers through `receive`.
    let answering = {
        let left = Arc::clone(&left);
        std::thread::spawn(move || left.receive(WAIT, |n| n * 10))
    };
    assert_eq!(parent.send_to("left", &3, WAIT).unwrap(), 30);
    assert_eq!(answering.join().unwrap().unwrap(), 3);
    // A user that does not take such messages is named as such, with the users there are.
    let err = parent
        .send_to("right", &1, Duration::from_millis(300))
        .unwrap_err();
    assert!(
        matches!(&err, PortError::NoSuchUser { user, usage: "Receive or Response", present, .. }
            if user == "right" && present.len() == 3),
        "{err}"
    );
    assert!(err.to_string().contains("right [ReceiveAll]"), "{err}");
    // Nor may a user receive what it did not declare.
    let err = right
        .receive(Duration::from_millis(10), |n| *n)
        .unwrap_err();
    assert!(
        matches!(
            err,
            PortError::Refused {
                restriction: "usage",
                ..
            }
        ),
        "{err}"
    );

    // To all: every user asked answers, or is named as missing.
    let answers = [(&left, 1), (&right, 2)].map(|(user, k)| {
        let user = Arc::clone(user);
        std::thread::spawn(move || user.receive_all(WAIT, move |n| n + k))
    });
    let all = parent.callall(&100, Duration::from_secs(3)).unwrap();
    let mut replies = all.replies.clone();
    replies.sort();
    assert_eq!(
        replies,
        [("left".to_owned(), 101), ("right".to_owned(), 102)]
    );
    assert_eq!(all.missing, ["quiet"]);
    for answer in answers {
        assert_eq!(answer.join().unwrap().unwrap(), 100);
    }

    // Calls of one owner overlap: each gets its own replies.
    let to_left = {
        let left = Arc::clone(&left);
        std::thread::spawn(move || {
            (
                left.receive(WAIT, |n| n + 1000),
                left.receive_all(WAIT, |n| n + 1),
            )
        })
    };
    let to_right = {
        let right = Arc::clone(&right);
        std::thread::spawn(move || right.receive_all(WAIT, |n| n + 2))
    };
    std::thread::scope(|s| {
        let one = s.spawn(|| parent.send_to("left", &7, WAIT));
        let all = parent.callall(&8, Duration::from_secs(3)).unwrap();
        assert_eq!(one.join().unwrap().unwrap(), 1007);
        let mut replies = all.replies;
        replies.sort();
        assert_eq!(replies, [("left".to_owned(), 9), ("right".to_owned(), 10)]);
    });
    let (one, all) = to_left.join().unwrap();
    assert_eq!((one.unwrap(), all.unwrap()), (7, 8));
    assert_eq!(to_right.join().unwrap().unwrap(), 8);
}

#[test]
fn a_tightly_coupled_port_busy_waits_and_still_keeps_its_timeouts() {
    use ndds_client::ports::ProcessClass;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "tight");
    let class = ProcessClass::Tight { spin_us: 2000 };
    let child = PortOwner::<u32, u32>::declare_with(
        &p,
        "beam.child",
        "child",
        Restrictions {
            class,
            ..Restrictions::default()
        },
    )
    .unwrap();
    assert_eq!(child.restrictions().class.spin(), Duration::from_millis(2));
    let parent = PortUser::<u32, u32>::declare(&p, "beam.child", "parent").unwrap();
    std::thread::scope(|s| {
        let slave = s.spawn(|| {
            for _ in 0..50 {
                let (n, reply) = child.receive(WAIT).unwrap();
                reply.reply(&(n * 2)).unwrap();
            }
        });
        for n in 0..50 {
            assert_eq!(parent.send(&n, WAIT).unwrap(), n * 2);
        }
        slave.join().unwrap();
    });
    // Spinning ends; the deadlines are kept as on any port.
    let started = Instant::now();
    let err = parent.send(&1, Duration::from_millis(200)).unwrap_err();
    assert!(matches!(err, PortError::Timeout { .. }), "{err}");
    assert!(started.elapsed() >= Duration::from_millis(200));
    assert!(common::eventually(WAIT, || {
        use ndds_client::ports::Selectable;
        child.waiting();
        child.withdrawn() == 1
    }));
    let err = child.receive(Duration::from_millis(100)).unwrap_err();
    assert!(matches!(err, PortError::Timeout { .. }), "{err}");
}

#[test]
fn a_filter_of_the_owners_module_passes_answers_and_refuses_requests() {
    use ndds_client::ports::{Filter, RequestFilter, Verdict};

    /// Zero is answered at once; above the limit is refused; the rest reaches the owner
    /// doubled. Its module changes the limit through the port FILTER.
    struct Guard {
        limit: u32,
    }
    impl RequestFilter<u32, u32> for Guard {
        type Message = u32;
        fn request(&mut self, sender: &str, n: u32) -> Verdict<u32, u32> {
            match n {
                0 => Verdict::Answer(0),
                13 => panic!("unlucky {sender}"),
                n if n > self.limit => {
                    Verdict::Refuse(format!("{n} is above the limit {}", self.limit))
                }
                n => Verdict::Pass(n * 2),
            }
        }
        fn message(&mut self, limit: u32) {
            self.limit = limit;
        }
    }

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "filtered");
    let (owner, filter) = PortOwner::<u32, u32>::declare_filtered(
        &p,
        "dose",
        "pump",
        Restrictions::default(),
        Guard { limit: 20 },
    )
    .unwrap();
    assert_eq!(owner.restrictions().filter, Some(Filter::Task));
    let user = Arc::new(PortUser::<u32, u32>::declare(&p, "dose", "nurse").unwrap());
    let served = std::sync::atomic::AtomicU32::new(0);
    std::thread::scope(|s| {
        let server = s.spawn(|| {
            while let Ok((n, reply)) = owner.receive(Duration::from_secs(2)) {
                served.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                reply.reply(&(n + 1)).unwrap();
            }
        });
        // Answered by the filter: the owner never sees it.
        assert_eq!(user.send(&0, WAIT).unwrap(), 0);
        // Passed on, changed: the owner gets 10.
        assert_eq!(user.send(&5, WAIT).unwrap(), 11);
        // Refused: the filter's exception reaches the sender with its reason.
        let err = user.send(&50, WAIT).unwrap_err();
        assert!(
            matches!(&err, PortError::Refused { restriction: "filter", detail, owner, .. }
                if detail == "50 is above the limit 20" && owner == "pump"),
            "{err}"
        );
        // The module raises the limit through FILTER: taken before the next request.
        assert!(filter.send(100));
        assert_eq!(user.send(&50, WAIT).unwrap(), 101);
        // A filter that panics refuses the request and goes on.
        let err = user.send(&13, WAIT).unwrap_err();
        assert!(
            matches!(&err, PortError::Refused { restriction: "filter", detail, .. }
                if detail.contains("panicked")),
            "{err}"
        );
        assert_eq!(user.send(&7, WAIT).unwrap(), 15);
        server.join().unwrap();
    });
    assert_eq!(served.load(std::sync::atomic::Ordering::Relaxed), 3);
    // The restriction alone, without the filter's code, is refused.
    let err = PortOwner::<u32, u32>::declare_with(
        &p,
        "dose2",
        "pump",
        Restrictions {
            filter: Some(Filter::Task),
            ..Restrictions::default()
        },
    )
    .err()
    .unwrap();
    assert!(matches!(err, PortError::FilterCode { .. }), "{err}");
}

#[test]
fn a_filter_at_the_users_end_answers_from_its_cache_passes_the_rest_and_refuses() {
    use ndds_client::ports::{RequestFilter, Verdict};
    use std::collections::HashMap;

    /// Answers a position asked before from its cache; refuses joints above the limit its
    /// module sets through FILTER; passes the rest to the owner.
    struct Cache {
        known: HashMap<u32, u32>,
        limit: u32,
    }
    impl RequestFilter<u32, u32> for Cache {
        type Message = (u32, u32); // (joint, position) learnt, or (u32::MAX, limit)
        fn request(&mut self, _sender: &str, joint: u32) -> Verdict<u32, u32> {
            if joint > self.limit {
                return Verdict::Refuse(format!("joint {joint} is above {}", self.limit));
            }
            match self.known.get(&joint) {
                Some(position) => Verdict::Answer(*position),
                None => Verdict::Pass(joint),
            }
        }
        fn message(&mut self, (joint, value): (u32, u32)) {
            if joint == u32::MAX {
                self.limit = value;
            } else {
                self.known.insert(joint, value);
            }
        }
    }

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "user-filter");
    let owner = PortOwner::<u32, u32>::declare(&p, "joints", "arm").unwrap();
    let (user, filter) = PortUser::<u32, u32>::declare_filtered(
        &p,
        "joints",
        "planner",
        &[Usage::Send],
        Cache {
            known: HashMap::new(),
            limit: 6,
        },
    )
    .unwrap();
    let served = std::sync::atomic::AtomicU32::new(0);
    std::thread::scope(|s| {
        let server = s.spawn(|| {
            while let Ok((joint, reply)) = owner.receive(Duration::from_secs(2)) {
                served.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                reply.reply(&(joint * 100)).unwrap();
            }
        });
        // Passed to the owner; the module teaches the cache the answer.
        assert_eq!(user.send(&3, WAIT).unwrap(), 300);
        assert!(filter.send((3, 300)));
        // Now answered at this end: the owner does not see it.
        assert_eq!(user.send(&3, WAIT).unwrap(), 300);
        // Refused at this end, naming the filter.
        let err = user.send(&7, WAIT).unwrap_err();
        assert!(
            matches!(&err, PortError::Refused { restriction: "filter", detail, .. } if detail == "joint 7 is above 6"),
            "{err}"
        );
        // The module raises the limit: passed again.
        assert!(filter.send((u32::MAX, 10)));
        assert_eq!(user.send(&7, WAIT).unwrap(), 700);
        server.join().unwrap();
    });
    assert_eq!(served.load(std::sync::atomic::Ordering::Relaxed), 2);
}

#[test]
fn an_async_send_dropped_before_its_reply_withdraws_its_request() {
    use ndds_client::ports::Selectable;

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "withdraw-async");
    let owner = PortOwner::<u32, u32>::declare(&p, "slow.async", "server").unwrap();
    let user = Arc::new(PortUser::<u32, u32>::declare(&p, "slow.async", "client").unwrap());
    // Warm up: the user knows the owner, so the next request goes out at once.
    let warm = {
        let user = Arc::clone(&user);
        std::thread::spawn(move || user.send(&0, WAIT))
    };
    let (value, reply) = owner.receive(WAIT).unwrap();
    reply.reply(&value).unwrap();
    assert_eq!(warm.join().unwrap().unwrap(), 0);
    // The caller's executor gives up on the send (a `select!` elsewhere won): the future is
    // dropped with its request out and unanswered.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let gave_up = runtime.block_on(async {
        tokio::time::timeout(Duration::from_millis(300), user.send_async(7, WAIT)).await
    });
    assert!(gave_up.is_err(), "the owner never replied");
    assert!(common::eventually(WAIT, || {
        owner.waiting();
        owner.withdrawn() == 1
    }));
    assert!(matches!(
        owner.receive(Duration::from_millis(200)),
        Err(PortError::Timeout { .. })
    ));
}

#[test]
fn users_are_checked_against_the_usages_of_the_owners_filter() {
    use ndds_client::ports::{RequestFilter, Verdict};

    /// Answers queries itself (`USAGE=RESPONSE`): the port's users must query.
    struct Clock;
    impl RequestFilter<u32, u32> for Clock {
        type Message = ();
        fn request(&mut self, _sender: &str, n: u32) -> Verdict<u32, u32> {
            Verdict::Answer(n + 1)
        }
        fn usages(&self) -> Vec<Usage> {
            vec![Usage::Response]
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "filter-usages");
    let (owner, _filter) = PortOwner::<u32, u32>::declare_filtered(
        &p,
        "tick",
        "clock",
        Restrictions {
            usages: vec![Usage::Receive],
            ..Restrictions::default()
        },
        Clock,
    )
    .unwrap();
    assert_eq!(owner.restrictions().usages, [Usage::Response]);
    let querier =
        PortUser::<u32, u32>::declare_with(&p, "tick", "reader", &[Usage::Query]).unwrap();
    assert_eq!(querier.query(&41, WAIT).unwrap(), 42);
    let sender = PortUser::<u32, u32>::declare(&p, "tick", "writer").unwrap();
    let err = sender.send(&1, WAIT).unwrap_err();
    assert!(
        err.to_string()
            .contains("Send complements none of the owner's usages [Response]"),
        "{err}"
    );
}

#[test]
fn the_bounded_buffer_is_a_library_filter_any_owner_can_splice_in() {
    use ndds_client::ports::{BoundedBuffer, Filter};

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "library-buffer");
    // Written with the public filter API, so it also serves a port whose replies are not ().
    let (owner, _filter) = PortOwner::<u32, u32>::declare_filtered(
        &p,
        "belt",
        "gate",
        Restrictions::default(),
        BoundedBuffer::answering(2, || 0),
    )
    .unwrap();
    // Users see the restriction it declares, and deal with its usages.
    assert_eq!(
        owner.restrictions().filter,
        Some(Filter::BoundedBuffer { capacity: 2 })
    );
    assert_eq!(owner.restrictions().usages, [Usage::Receive]);
    let user = PortUser::<u32, u32>::declare_with(&p, "belt", "loader", &[Usage::Send]).unwrap();
    // Two sends are answered by the buffer at once; the owner has received nothing.
    assert_eq!(user.send(&1, WAIT).unwrap(), 0);
    assert_eq!(user.send(&2, WAIT).unwrap(), 0);
    // The third waits for room, times out and is withdrawn before the buffer takes it.
    let err = user.send(&3, Duration::from_millis(300)).unwrap_err();
    assert!(matches!(err, PortError::Timeout { .. }), "{err}");
    assert!(common::eventually(WAIT, || owner.withdrawn() == 1));
    // The owner's reply to a request the buffer answered is not sent (nobody waits for it).
    let (first, reply) = owner.receive(WAIT).unwrap();
    assert_eq!(first, 1);
    reply.reply(&99).unwrap();
    // Room again: the next send is answered by the buffer, not by the owner.
    assert_eq!(user.send(&4, WAIT).unwrap(), 0);
    let rest: Vec<u32> = (0..2).map(|_| owner.receive(WAIT).unwrap().0).collect();
    assert_eq!(rest, [2, 4]);
    // A user that asks for an answer from the owner (a query) is refused by the buffer's usages.
    let asker = PortUser::<u32, u32>::declare_with(&p, "belt", "asker", &[Usage::Query]).unwrap();
    let err = asker.query(&5, Duration::from_secs(2)).unwrap_err();
    assert!(
        matches!(
            &err,
            PortError::Refused {
                restriction: "usage",
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn a_users_filter_that_accepts_sends_on_without_waiting_for_the_owner() {
    use ndds_client::ports::{RequestFilter, Verdict};

    /// Log-and-go: every request goes to the owner, and the sender goes on at once.
    struct Forward;
    impl RequestFilter<u32, u32> for Forward {
        type Message = ();
        fn request(&mut self, _sender: &str, request: u32) -> Verdict<u32, u32> {
            Verdict::Accept(request + 1000, 0)
        }
    }

    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "user-accept");
    let owner = PortOwner::<u32, u32>::declare(&p, "log", "logger").unwrap();
    let (user, _filter) =
        PortUser::<u32, u32>::declare_filtered(&p, "log", "robot", &[Usage::Send], Forward)
            .unwrap();
    // Nobody receives yet: the sends return at once all the same.
    for n in 1..=3 {
        assert_eq!(user.send(&n, WAIT).unwrap(), 0);
    }
    let got: Vec<u32> = (0..3)
        .map(|_| {
            let (n, reply) = owner.receive(WAIT).unwrap();
            reply.reply(&n).unwrap(); // reaches nobody, harmlessly
            n
        })
        .collect();
    assert_eq!(got, [1001, 1002, 1003]);
}

#[test]
fn a_message_taken_while_the_owner_is_in_question_is_answered_by_the_next_receive() {
    let dir = tempfile::tempdir().unwrap();
    let p = participant(dir.path(), "held");
    let parent = Arc::new(PortOwner::<u32, u32>::declare(&p, "held", "parent").unwrap());
    let child = Arc::new(
        PortUser::<u32, u32>::declare_with(&p, "held", "child", &[Usage::Receive]).unwrap(),
    );
    assert!(common::eventually(WAIT, || parent.present_users().len() == 1));
    // The user waits for a message; a second owner comes, and makes the port's owner
    // uncertain just as the parent's message arrives: the user takes it, cannot answer it,
    // and must not lose it.
    let waiting = {
        let child = Arc::clone(&child);
        std::thread::spawn(move || child.receive(WAIT, |n| n * 2))
    };
    std::thread::sleep(Duration::from_millis(200)); // it waits on the topic now
    let second = PortOwner::<u32, u32>::declare(&p, "held", "usurper").unwrap();
    let watcher =
        PortUser::<u32, u32>::declare_with(&p, "held", "watcher", &[Usage::Receive]).unwrap();
    assert!(common::eventually(WAIT, || matches!(
        watcher.receive(Duration::from_millis(10), |n| *n),
        Err(PortError::SecondOwner { .. })
    )));
    let sending = {
        let parent = Arc::clone(&parent);
        std::thread::spawn(move || parent.send_to("child", &5, Duration::from_secs(20)))
    };
    let taken = waiting.join().unwrap();
    assert!(
        matches!(taken, Err(PortError::SecondOwner { .. })),
        "{taken:?}"
    );
    drop(second);
    // The owner is clear again: the kept message is answered.
    let mut answered = None;
    let deadline = Instant::now() + WAIT;
    while answered.is_none() && Instant::now() < deadline {
        answered = child.receive(Duration::from_millis(500), |n| n * 2).ok();
    }
    assert_eq!(answered, Some(5));
    assert_eq!(sending.join().unwrap().unwrap(), 10);
}

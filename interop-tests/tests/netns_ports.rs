//! Ports across hosts simulated with network namespaces (needs root, `ip` and `nft`): an owner
//! on one host replies out of order to senders blocked on two other hosts, and a `waitfor`
//! rendezvous joins three tasks in three processes on three hosts.

mod support;

use std::time::Duration;

use interop_tests::netns::Cluster;
use support::{exclusive, node};

const WAIT: Duration = Duration::from_secs(30);

#[test]
fn an_owner_replies_out_of_order_to_senders_blocked_on_other_hosts() {
    let _turn = exclusive();
    let cluster = Cluster::new(3);
    let owner = node(
        &cluster,
        0,
        &[
            "port",
            "own",
            "--port",
            "arm",
            "--task",
            "arm-server",
            "--hold",
            "2",
        ],
    );
    let first = node(
        &cluster,
        1,
        &[
            "port", "send", "--port", "arm", "--task", "left", "--value", "1",
        ],
    );
    // The second request surely arrives second.
    owner.event("received", WAIT).expect("the first request");
    let second = node(
        &cluster,
        2,
        &[
            "port", "send", "--port", "arm", "--task", "right", "--value", "2",
        ],
    );
    owner.event("received", WAIT).expect("the second request");
    // Replies go out in reverse order: the second sender is answered first.
    let replied = owner.event("replied", WAIT).expect("a reply");
    assert_eq!(replied["to"], "right");
    for (sender, expected) in [
        (&second, "right got 2 from arm-server"),
        (&first, "left got 1 from arm-server"),
    ] {
        let reply = sender.event("reply", WAIT).expect("the sender's reply");
        assert_eq!(reply["reply"], expected);
    }
}

#[test]
fn waitfor_joins_three_processes_on_three_hosts() {
    let _turn = exclusive();
    let cluster = Cluster::new(3);
    let tasks = "planner,left-arm,right-arm";
    let nodes: Vec<_> = ["planner", "left-arm", "right-arm"]
        .iter()
        .enumerate()
        .map(|(host, task)| {
            let value = ((host + 1) * 100).to_string();
            node(
                &cluster,
                host,
                &[
                    "port", "waitfor", "--port", "grasp", "--task", task, "--tasks", tasks,
                    "--value", &value, "--rounds", "3",
                ],
            )
        })
        .collect();
    for round in 0..3u64 {
        let expected = format!(
            "left-arm={},planner={},right-arm={}",
            200 + round,
            100 + round,
            300 + round
        );
        for node in &nodes {
            let line = node.event("combined", WAIT).expect("a combined result");
            assert_eq!(line["round"], round);
            assert_eq!(
                line["all"],
                expected.as_str(),
                "every message, every process"
            );
        }
    }
}

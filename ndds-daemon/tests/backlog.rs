//! A burst of match events larger than a client's outbox: the client that reads is never
//! disconnected and ends with the current state of every pair; one that reads nothing is
//! dropped after the slow-client time. And the graph of a large table, answered in pages.

use std::net::{Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ndds_core::discovery::{DiscoveryConfig, Engine, Via};
use ndds_core::ipc::{ClientMessage, DaemonMessage, EndpointDecl, Hello, IPC_VERSION, Role};
use ndds_core::types::TypeDescription;
use ndds_core::wire::{
    self, Announce, ConsumerQosWire, EndpointInfo, EndpointQos, Guid, Locator, Message, NodeInfo,
    ProducerQosWire, Withdraw,
};
use ndds_daemon::connection::ClientLink;
use ndds_daemon::driver::{Counters, Driver, GRAPH_PAGE, Input};
use ndds_daemon::local::PeerCred;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

const TOPIC: &str = "arm/joints";
const PARTICIPANT: u64 = 0x77;
const REMOTE: Locator = Locator {
    addr: [127, 0, 0, 9],
    port: 7999,
};
/// The outbox of the test client: far smaller than the burst.
const OUTBOX: usize = 8;
const BURST: u64 = 500;

fn producer(participant: u64) -> EndpointInfo {
    let type_desc = TypeDescription::of::<f64>();
    EndpointInfo {
        guid: Guid {
            participant,
            entity: 1,
        },
        topic: TOPIC.into(),
        fingerprint: type_desc.fingerprint(),
        type_desc,
        qos: EndpointQos::Producer(ProducerQosWire::default()),
        locator: REMOTE,
        pid: 9,
        process: "remote".into(),
    }
}

fn datagram(message: &Message) -> Vec<u8> {
    let mut out = Vec::new();
    wire::encode(0, 0xBEEF, message, &mut out).unwrap();
    out
}

async fn setup() -> (
    Driver,
    mpsc::Receiver<DaemonMessage>,
    CancellationToken,
    Arc<Counters>,
) {
    let socket = tokio::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))
        .await
        .unwrap();
    let port = socket.local_addr().unwrap().port();
    let config = DiscoveryConfig::new(
        0,
        Locator {
            addr: [127, 0, 0, 1],
            port,
        },
    );
    let engine = Engine::new(config, Instant::now()).unwrap();
    let counters = Arc::new(Counters::default());
    // No group: nothing is sent off this host.
    let mut driver = Driver::new(engine, Arc::new(socket), None, Vec::new(), counters.clone());
    let (outbox, inbox) = mpsc::channel(OUTBOX);
    let cancel = CancellationToken::new();
    let cred = PeerCred {
        uid: 0,
        gid: 0,
        pid: std::process::id(),
    };
    driver.on_input(Input::Opened {
        client: 1,
        link: ClientLink {
            outbox,
            cancel: cancel.clone(),
        },
        cred,
    });
    let hello = Hello {
        ipc_version: IPC_VERSION,
        participant: PARTICIPANT,
        pid: std::process::id(),
        name: "backlog-test".into(),
        role: Role::Client,
    };
    driver.on_input(Input::Frame {
        client: 1,
        message: ClientMessage::Hello(hello),
    });
    let type_desc = TypeDescription::of::<f64>();
    let decl = EndpointDecl {
        entity: 5,
        topic: TOPIC.into(),
        fingerprint: type_desc.fingerprint(),
        type_desc,
        qos: EndpointQos::Consumer(ConsumerQosWire::default()),
        locator: Locator {
            addr: [127, 0, 0, 1],
            port: 9,
        },
    };
    driver.on_input(Input::Frame {
        client: 1,
        message: ClientMessage::Declare(decl),
    });
    driver.flush().await;
    (driver, inbox, cancel, counters)
}

fn announce_burst(driver: &mut Driver) {
    announce(driver, BURST);
}

/// The remote node that announces the test's producers.
fn remote_node() -> NodeInfo {
    NodeInfo {
        hostname: "remote".into(),
        pid: 9,
        unicast: REMOTE,
        lease_ms: 30_000,
        announce_period_ms: 1000,
        version: String::new(),
    }
}

fn announce(driver: &mut Driver, count: u64) {
    let node = remote_node();
    let endpoints: Vec<EndpointInfo> = (1..=count).map(|p| producer(0x1000 + p)).collect();
    for chunk in endpoints.chunks(100) {
        let announce = Message::Announce(Announce {
            node: node.clone(),
            endpoints: chunk.to_vec(),
            withdrawn: vec![],
        });
        driver.on_input(Input::Datagram {
            from: SocketAddr::V4(REMOTE.into()),
            via: Via::Unicast,
            bytes: datagram(&announce),
        });
    }
}

#[tokio::test]
async fn a_burst_larger_than_the_outbox_reaches_a_client_that_reads() {
    let (mut driver, mut inbox, cancel, counters) = setup().await;
    assert!(matches!(
        inbox.recv().await,
        Some(DaemonMessage::Welcome(_))
    ));
    assert!(matches!(
        inbox.recv().await,
        Some(DaemonMessage::Declared {
            entity: 5,
            result: Ok(())
        })
    ));
    announce_burst(&mut driver);
    driver.flush().await;
    // While the burst waits, 100 of its producers are withdrawn again.
    let gone: Vec<Guid> = (1..=100).map(|p| producer(0x1000 + p).guid).collect();
    driver.on_input(Input::Datagram {
        from: SocketAddr::V4(REMOTE.into()),
        via: Via::Unicast,
        bytes: datagram(&Message::Withdraw(Withdraw {
            endpoints: gone.clone(),
        })),
    });
    driver.flush().await;
    assert!(
        !cancel.is_cancelled(),
        "the client was dropped by the burst"
    );
    assert!(driver.backlog_pairs() > 0, "the burst waits in the backlog");

    let mut matched = std::collections::BTreeMap::new();
    let mut frames = 0;
    loop {
        while let Ok(message) = inbox.try_recv() {
            frames += 1;
            match message {
                DaemonMessage::Matched { local: 5, remote } => {
                    matched.insert(remote.guid, true);
                }
                DaemonMessage::Unmatched { local: 5, remote } => {
                    matched.insert(remote, false);
                }
                other => panic!("unexpected {other:?}"),
            }
        }
        driver.flush().await;
        if inbox.is_empty() {
            break;
        }
    }
    let now_matched: Vec<&Guid> = matched
        .iter()
        .filter(|(_, m)| **m)
        .map(|(g, _)| g)
        .collect();
    assert_eq!(now_matched.len(), (BURST - 100) as usize);
    assert!(gone.iter().all(|g| matched.get(g) != Some(&true)));
    // Coalesced: no more frames than the outbox held plus one per pair.
    assert!(frames <= OUTBOX + BURST as usize, "{frames} frames");
    // Every pair that waited was counted out as it went.
    assert_eq!(driver.backlog_pairs(), 0);
    assert!(!cancel.is_cancelled());
    assert_eq!(
        counters
            .slow_clients
            .load(std::sync::atomic::Ordering::Relaxed),
        0
    );
}

#[tokio::test]
async fn a_client_that_reads_nothing_is_dropped_after_the_slow_client_time() {
    let (mut driver, _inbox, cancel, counters) = setup().await;
    driver.set_slow_client(Duration::from_millis(50));
    announce_burst(&mut driver);
    driver.flush().await;
    assert!(!cancel.is_cancelled(), "not yet: it may still read");
    assert!(driver.backlog_pairs() > 0);
    tokio::time::sleep(Duration::from_millis(80)).await;
    driver.flush().await;
    assert!(
        cancel.is_cancelled(),
        "dropped once it read nothing for the slow-client time"
    );
    assert_eq!(driver.backlog_pairs(), 0, "its backlog went with it");
    assert_eq!(
        counters
            .slow_clients
            .load(std::sync::atomic::Ordering::Relaxed),
        1
    );
    // Its consumer is withdrawn: the graph has no local endpoint left.
    assert!(
        driver
            .graph()
            .endpoints
            .iter()
            .all(|e| e.node != driver.graph().local.node)
    );
}

#[tokio::test]
async fn backlogs_past_the_daemons_bound_cost_the_biggest_one_its_connection() {
    for (bound, dropped) in [(BURST as usize, false), (BURST as usize / 5, true)] {
        let (mut driver, _inbox, cancel, counters) = setup().await;
        driver.set_max_backlog_pairs(bound);
        announce_burst(&mut driver);
        driver.flush().await;
        // Long before the slow-client time (10 s): only the bound can have dropped it.
        assert_eq!(cancel.is_cancelled(), dropped, "bound {bound}");
        // A dropped client's pairs leave the count with it; a kept one's still wait.
        assert_eq!(driver.backlog_pairs() == 0, dropped, "bound {bound}");
        assert_eq!(
            counters
                .slow_clients
                .load(std::sync::atomic::Ordering::Relaxed),
            u64::from(dropped),
            "bound {bound}"
        );
    }
}

#[tokio::test]
async fn the_graph_of_a_large_table_comes_in_bounded_pages() {
    let (mut driver, _inbox, _cancel, _counters) = setup().await;
    let remote = 2 * GRAPH_PAGE as u64 + 300;
    announce(&mut driver, remote);
    driver.flush().await;
    let mut seen = Vec::new();
    let mut after = None;
    let mut pages = 0;
    loop {
        let (page, next) = driver.graph_page(after);
        pages += 1;
        assert!(!page.endpoints.is_empty() && page.endpoints.len() <= GRAPH_PAGE);
        let frame = ndds_core::ipc::encode_body(&DaemonMessage::Graph {
            request: 1,
            graph: page.clone(),
            next,
        })
        .expect("every page fits a frame");
        assert!(frame.len() < ndds_core::ipc::MAX_FRAME);
        seen.extend(page.endpoints.iter().map(|e| e.info.guid));
        match next {
            Some(last) => {
                assert_eq!(Some(&last), seen.last());
                after = Some(last);
            }
            None => break,
        }
    }
    // The remote producers and the local consumer, each once, in guid order.
    assert_eq!(pages, 3);
    assert_eq!(seen.len() as u64, remote + 1);
    assert!(seen.windows(2).all(|w| w[0] < w[1]));
    assert_eq!(driver.graph().endpoints.len() as u64, remote + 1);
}

/// One step of the coalescing property below.
#[derive(Debug, Clone)]
enum Step {
    /// Remote producer `n` announced (again), of a compatible type or not.
    Announce { n: u64, compatible: bool },
    /// Remote producer `n` withdrawn.
    Withdraw { n: u64 },
    /// The client reads up to this many frames.
    Read(usize),
}

fn step() -> impl proptest::strategy::Strategy<Value = Step> {
    use proptest::prelude::*;
    prop_oneof![
        (0..6u64, any::<bool>()).prop_map(|(n, compatible)| Step::Announce { n, compatible }),
        (0..6u64).prop_map(|n| Step::Withdraw { n }),
        (0..4usize).prop_map(Step::Read),
    ]
}

/// What the client knows of a pair from the last message about it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Seen {
    Matched,
    Incompatible,
    Unmatched,
}

fn apply(seen: &mut std::collections::BTreeMap<Guid, Seen>, message: DaemonMessage) {
    match message {
        DaemonMessage::Matched { local: 5, remote } => {
            seen.insert(remote.guid, Seen::Matched);
        }
        DaemonMessage::Incompatible { local: 5, remote } => {
            seen.insert(remote.guid, Seen::Incompatible);
        }
        DaemonMessage::Unmatched { local: 5, remote } => {
            seen.insert(remote, Seen::Unmatched);
        }
        other => panic!("unexpected {other:?}"),
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// Whatever happens to pairs while a client's outbox is full, and however little it reads
    /// in between, once it has read everything its view of every pair is the engine's: the
    /// backlog coalesces transitions and never loses the last one.
    #[test]
    fn a_client_that_reads_slowly_ends_with_the_engines_state_of_every_pair(
        steps in proptest::collection::vec(step(), 1..120),
    ) {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        runtime.block_on(async {
            let (mut driver, mut inbox, cancel, _counters) = setup().await;
            assert!(matches!(inbox.recv().await, Some(DaemonMessage::Welcome(_))));
            assert!(matches!(
                inbox.recv().await,
                Some(DaemonMessage::Declared { entity: 5, result: Ok(()) })
            ));
            // Fill the outbox with a burst of other producers first, so the steps below start
            // behind a backlog and go on filling it.
            announce(&mut driver, 40);
            driver.flush().await;
            let node = remote_node();
            let mut seen = std::collections::BTreeMap::new();
            // The engine's truth: producer n present, and whether its type is compatible.
            let mut truth: std::collections::BTreeMap<Guid, bool> =
                (1..=40).map(|p| (producer(0x1000 + p).guid, true)).collect();
            for step in steps {
                match step {
                    Step::Announce { n, compatible } => {
                        let mut info = producer(0x5000 + n);
                        if !compatible {
                            info.type_desc = TypeDescription::of::<u32>();
                            info.fingerprint = info.type_desc.fingerprint();
                        }
                        truth.insert(info.guid, compatible);
                        let message = Message::Announce(Announce {
                            node: node.clone(),
                            endpoints: vec![info],
                            withdrawn: vec![],
                        });
                        driver.on_input(Input::Datagram {
                            from: SocketAddr::V4(REMOTE.into()),
                            via: Via::Unicast,
                            bytes: datagram(&message),
                        });
                    }
                    Step::Withdraw { n } => {
                        let guid = producer(0x5000 + n).guid;
                        truth.remove(&guid);
                        driver.on_input(Input::Datagram {
                            from: SocketAddr::V4(REMOTE.into()),
                            via: Via::Unicast,
                            bytes: datagram(&Message::Withdraw(Withdraw {
                                endpoints: vec![guid],
                            })),
                        });
                    }
                    Step::Read(frames) => {
                        for _ in 0..frames {
                            match inbox.try_recv() {
                                Ok(message) => apply(&mut seen, message),
                                Err(_) => break,
                            }
                        }
                    }
                }
                driver.flush().await;
            }
            // Read everything that is left.
            loop {
                while let Ok(message) = inbox.try_recv() {
                    apply(&mut seen, message);
                }
                driver.flush().await;
                if inbox.is_empty() {
                    break;
                }
            }
            assert!(!cancel.is_cancelled(), "a client that reads is never dropped");
            assert_eq!(driver.backlog_pairs(), 0);
            for (guid, state) in &seen {
                let expected = match truth.get(guid) {
                    Some(true) => Seen::Matched,
                    Some(false) => Seen::Incompatible,
                    None => Seen::Unmatched,
                };
                assert_eq!(*state, expected, "pair with {guid}");
            }
            for (guid, compatible) in &truth {
                let expected = if *compatible { Seen::Matched } else { Seen::Incompatible };
                assert_eq!(seen.get(guid), Some(&expected), "pair with {guid} never told");
            }
        });
    }
}

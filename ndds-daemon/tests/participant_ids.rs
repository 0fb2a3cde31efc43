//! Participant ids are the daemon's to give: a client that asks for none gets one, in a domain
//! with permissions one of the daemon's identity (other daemons believe only that daemon about
//! its endpoints), and a client that names an id of another identity is refused with a
//! message that says what to do.

use std::net::Ipv4Addr;
use std::sync::Arc;
use std::time::Instant;

use ndds_core::discovery::{DiscoveryConfig, Engine};
use ndds_core::ipc::{ClientMessage, DaemonMessage, Hello, IPC_VERSION, Role};
use ndds_core::security::{Guard, Identity, Permissions, node_id_for, owns_node_id};
use ndds_core::wire::Locator;
use ndds_daemon::connection::ClientLink;
use ndds_daemon::driver::{Counters, Driver, Input};
use ndds_daemon::local::PeerCred;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

async fn driver(identity: Option<&Identity>) -> Driver {
    let socket = tokio::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))
        .await
        .unwrap();
    let port = socket.local_addr().unwrap().port();
    let mut config = DiscoveryConfig::new(
        0,
        Locator {
            addr: [127, 0, 0, 1],
            port,
        },
    );
    if let Some(identity) = identity {
        config.node_id = Some(node_id_for(&identity.public(), 77));
    }
    let mut engine = Engine::new(config, Instant::now()).unwrap();
    if let Some(identity) = identity {
        engine.guard_with(Guard {
            identity: identity.clone(),
            permissions: Arc::new(Permissions {
                serial: 1,
                domain: None,
                not_before: 0,
                not_after: u64::MAX,
                subjects: Vec::new(),
            }),
            valid_until: None,
        });
    }
    // No group: nothing is sent off this host.
    Driver::new(
        engine,
        Arc::new(socket),
        None,
        Vec::new(),
        Arc::new(Counters::default()),
    )
}

/// Opens client `client` and says `Hello` with `participant`; the daemon's answer.
fn hello(driver: &mut Driver, client: u64, participant: u64) -> DaemonMessage {
    let (outbox, mut inbox) = mpsc::channel(8);
    driver.on_input(Input::Opened {
        client,
        link: ClientLink {
            outbox,
            cancel: CancellationToken::new(),
        },
        cred: PeerCred {
            uid: 0,
            gid: 0,
            pid: std::process::id(),
        },
    });
    driver.on_input(Input::Frame {
        client,
        message: ClientMessage::Hello(Hello {
            ipc_version: IPC_VERSION,
            participant,
            pid: std::process::id(),
            name: "participant-ids-test".into(),
            role: Role::Client,
        }),
    });
    inbox.try_recv().expect("an answer to Hello")
}

fn welcomed(answer: DaemonMessage) -> u64 {
    match answer {
        DaemonMessage::Welcome(welcome) => welcome.participant,
        other => panic!("not welcomed: {other:?}"),
    }
}

#[tokio::test]
async fn the_daemon_chooses_ids_of_its_identity_and_refuses_others() {
    let identity = Identity::from_secret([3; 32]);
    let mut driver = driver(Some(&identity)).await;
    let mut given = std::collections::HashSet::new();
    for client in 1..=20 {
        let id = welcomed(hello(&mut driver, client, 0));
        assert!(owns_node_id(&identity.public(), id), "{id:016x}");
        assert!(given.insert(id), "{id:016x} given twice");
    }
    // A client coming back after a restart of this daemon keeps its id.
    let earlier = node_id_for(&identity.public(), 12345);
    assert_eq!(welcomed(hello(&mut driver, 30, earlier)), earlier);
    // An id in use, or of another identity, is refused, and the reason says what to do.
    let in_use = hello(&mut driver, 31, earlier);
    assert!(
        matches!(&in_use, DaemonMessage::Refused { reason } if reason.contains("in use")),
        "{in_use:?}"
    );
    let other = node_id_for(&Identity::from_secret([4; 32]).public(), 1);
    let foreign = hello(&mut driver, 32, other);
    let DaemonMessage::Refused { reason } = &foreign else {
        panic!("a foreign id was let in: {foreign:?}");
    };
    assert!(
        reason.contains("not one of this daemon's identity") && reason.contains("reconnect"),
        "{reason}"
    );
}

#[tokio::test]
async fn without_permissions_any_id_not_in_use_goes() {
    let mut driver = driver(None).await;
    let chosen = welcomed(hello(&mut driver, 1, 0));
    assert_ne!(chosen, 0);
    assert_eq!(welcomed(hello(&mut driver, 2, 0x77)), 0x77);
    assert!(matches!(
        hello(&mut driver, 3, 0x77),
        DaemonMessage::Refused { .. }
    ));
}

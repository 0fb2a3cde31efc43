//! The discovery engine driven by a script of operations: what arrives at a daemon's
//! discovery sockets decides which nodes and endpoints it believes, so this is where a
//! datagram's meaning is fuzzed, not only its syntax.
//!
//! ```text
//! input := flags { op }
//! flags  bit 0: the domain has a key (the engine opens every datagram)
//!        bit 1: the key file says AES-256-GCM (else ChaCha20-Poly1305)
//!        bit 2: remote senders seal integrity-only (else encrypted)
//!        bit 3: multicast off, host 1 is the engine's configured peer
//!        bit 4: permissions: the engine signs and checks signatures, and enforces a
//!               document where host 1 may do everything, host 2 read `status/*`, host 3
//!               nothing (no subject)
//! op := RAW      u16 len | datagram          from host (first byte % 4), via (bit 7)
//!     | FRAMED   u16 len | sel kind body      header built here: sender node sel % 4
//!     | SEALED   u16 len | sel kind body      as FRAMED, then sealed with that sender's key
//!     | TIME     u16 len | u16 ms             advance virtual time, run the timers
//!     | LOCALS   u16 len | byte               declare or withdraw one local endpoint
//!     | CLOSE    u16 len |                    the engine says goodbye
//! ```
//!
//! Sender `sel % 4 == 3` is the engine's own node id (its own datagrams looped back). With
//! bit 6 of `sel`, FRAMED and SEALED datagrams are signed by the identity of host
//! `1 + (sel >> 4) % 3` before sealing (its own, or another's), numbered in order or, with
//! bit 3, with an older number (a replay). A sealed sender keeps one [`Sealer`] per (node, session) so that counters grow as a real
//! sender's do; `sel / 4 % 4` picks the session.

use std::collections::HashMap;
use std::net::{SocketAddr, SocketAddrV4};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ndds_core::discovery::{DiscoveryConfig, Engine, Via};
use ndds_core::seal::{SealMode, SealSetup, Sealer};
use ndds_core::security::{Guard, Identity, Pattern, Permissions, Subject};
use ndds_core::types::TypeDescription;
use ndds_core::wire::{
    ConsumerQosWire, EndpointInfo, EndpointQos, Guid, Header, MessageKind, ProducerQosWire,
    Reliability,
};
use serde::{Deserialize, Serialize};

use crate::Input;
use crate::fixture::{self, DOMAIN};

/// Operation codes.
pub mod op {
    /// A datagram as it is.
    pub const RAW: u8 = 0;
    /// A body behind a header built by the harness.
    pub const FRAMED: u8 = 1;
    /// A body behind a header, sealed with the fixture key.
    pub const SEALED: u8 = 2;
    /// Time passes.
    pub const TIME: u8 = 3;
    /// A local endpoint comes or goes.
    pub const LOCALS: u8 = 4;
    /// The engine closes.
    pub const CLOSE: u8 = 5;
}

/// Flag bits of the first byte.
pub mod flag {
    /// The domain has a key.
    pub const KEYED: u8 = 1;
    /// AES-256-GCM rather than ChaCha20-Poly1305.
    pub const AES: u8 = 2;
    /// Remote senders seal integrity-only.
    pub const INTEGRITY_ONLY: u8 = 4;
    /// Multicast off; host 1 is a configured peer.
    pub const UNICAST: u8 = 8;
    /// Identities, signatures and a permissions document.
    pub const GUARDED: u8 = 16;
}

/// The node id of host `index`: fixed, or (`guarded`) one of its identity's, as a domain with
/// permissions requires.
pub fn node_id(index: u8, guarded: bool) -> u64 {
    if guarded {
        return ndds_core::security::node_id_for(&identity(index).public(), u64::from(index));
    }
    match index {
        0 => 0x1000,
        i => REMOTE_NODES[usize::from(i - 1) % REMOTE_NODES.len()],
    }
}

/// The configuration of host `index` in a domain with permissions (its node id its
/// identity's).
pub fn guarded_config(index: u8, unicast_only: bool) -> DiscoveryConfig {
    let mut config = config(index, unicast_only);
    config.node_id = Some(node_id(index, true));
    config
}

/// The identity of host `index` (0 is the engine under test).
pub fn identity(index: u8) -> Identity {
    Identity::from_secret([index.wrapping_add(0x10); 32])
}

/// The permissions document of a guarded engine: hosts 0 and 1 may do everything, host 2 read
/// `status/*`, host 3 is no subject.
pub fn permissions() -> Arc<Permissions> {
    let all = vec![Pattern::new("*").expect("a pattern")];
    let subject = |name: &str, index: u8, publish: Vec<Pattern>, subscribe: Vec<Pattern>| Subject {
        name: name.to_owned(),
        key: identity(index).public(),
        publish,
        subscribe,
        own: all.clone(),
        use_: Vec::new(),
    };
    Arc::new(Permissions {
        serial: 1,
        domain: None,
        not_before: 0,
        not_after: u64::MAX,
        subjects: vec![
            subject("self", 0, all.clone(), all.clone()),
            subject("arm", 1, all.clone(), all.clone()),
            subject(
                "viewer",
                2,
                Vec::new(),
                vec![Pattern::new("status/*").expect("a pattern")],
            ),
        ],
    })
}

/// The guard of host `index`.
pub fn guard(index: u8) -> Guard {
    Guard {
        identity: identity(index),
        permissions: permissions(),
        valid_until: None,
    }
}

/// Node ids of the remote hosts 1, 2 and 3 (host 0 is the engine under test).
pub const REMOTE_NODES: [u64; 3] = [0x1001, 0x1002, 0x1003];
/// Participant id of the engine's own endpoints.
pub const LOCAL_PARTICIPANT: u64 = 0xA0;

/// The participant id of host `index`'s client: fixed (0xA0 for the engine under test, 0xB0
/// for the others), or (`guarded`) one of its identity's, as a domain with permissions
/// requires.
pub fn participant(index: u8, guarded: bool) -> u64 {
    match (guarded, index) {
        (true, _) => {
            ndds_core::security::node_id_for(&identity(index).public(), 0x100 + u64::from(index))
        }
        (false, 0) => LOCAL_PARTICIPANT,
        (false, _) => 0xB0,
    }
}
/// The topic every fixture endpoint uses.
pub const TOPIC: &str = "fuzz/pose";

/// The sample type of [`TOPIC`].
#[derive(Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub x: f64,
    /// Position.
    pub y: f64,
    /// What it is.
    pub label: Option<String>,
}

/// The configuration of host `index`, seeded so that its jitter replays.
pub fn config(index: u8, unicast_only: bool) -> DiscoveryConfig {
    let mut config = DiscoveryConfig::new(DOMAIN, fixture::locator(index));
    config.seed = u64::from(index) + 1;
    config.node_id = Some(node_id(index, false));
    config.hostname = format!("host{index}");
    if unicast_only {
        config.multicast = false;
        config.peers = vec![fixture::locator(if index == 0 { 1 } else { 0 })];
    }
    config
}

/// A producer (`producer`) or consumer of [`TOPIC`], entity `entity` of `participant`, which
/// receives (or sends) data at host `host`'s data socket.
pub fn endpoint(participant: u64, entity: u32, producer: bool, host: u8) -> EndpointInfo {
    let type_desc = TypeDescription::of::<Pose>();
    let reliability = Reliability::Reliable { depth: 16 };
    let qos = if producer {
        EndpointQos::Producer(ProducerQosWire {
            strength: 1,
            persistence_us: 1000,
            reliability,
        })
    } else {
        EndpointQos::Consumer(ConsumerQosWire {
            reliability,
            ..ConsumerQosWire::default()
        })
    };
    EndpointInfo {
        guid: Guid {
            participant,
            entity,
        },
        topic: TOPIC.to_owned(),
        fingerprint: type_desc.fingerprint(),
        type_desc,
        qos,
        locator: fixture::data_addr(host).into(),
        pid: 100 + u32::from(host),
        process: format!("proc{host}"),
    }
}

/// The seal setup of a host of a keyed domain.
pub fn seal_setup(flags: u8, session: u64) -> SealSetup {
    SealSetup {
        keyring: fixture::keyring(fixture::cipher(u8::from(flags & flag::AES != 0))),
        mode: seal_mode(flags),
        session,
        require_encryption: false,
    }
}

fn seal_mode(flags: u8) -> SealMode {
    if flags & flag::INTEGRITY_ONLY != 0 {
        SealMode::IntegrityOnly
    } else {
        SealMode::Encrypt
    }
}

/// The harness: the engine, virtual time, and the remote senders' sealers.
struct Harness {
    engine: Engine,
    flags: u8,
    now: Instant,
    sealers: HashMap<(u64, u8), Sealer>,
    /// The number of the last signed datagram the harness made.
    signed: u64,
}

/// Runs one script (see the module docs).
pub fn run(data: &[u8]) {
    let mut input = Input::new(data);
    let flags = input.u8();
    let now = Instant::now();
    let config = if flags & flag::GUARDED != 0 {
        guarded_config(0, flags & flag::UNICAST != 0)
    } else {
        config(0, flags & flag::UNICAST != 0)
    };
    let Ok(mut engine) = Engine::new(config, now) else {
        panic!("the fixture configuration is valid");
    };
    if flags & flag::KEYED != 0 {
        engine.seal_with(seal_setup(flags, 1));
    }
    if flags & flag::GUARDED != 0 {
        engine.guard_with(guard(0));
    }
    let mut harness = Harness {
        engine,
        flags,
        now,
        sealers: HashMap::new(),
        signed: 0,
    };
    harness.drain();
    while !input.is_empty() {
        let code = input.u8();
        let mut chunk = Input::new(input.chunk());
        harness.step(code, &mut chunk);
        harness.drain();
    }
}

impl Harness {
    fn step(&mut self, code: u8, chunk: &mut Input<'_>) {
        match code % 6 {
            op::RAW => {
                let sel = chunk.u8();
                let from = SocketAddr::V4(fixture::locator(1 + sel % 4).into());
                let via = if sel & 0x80 != 0 {
                    Via::Unicast
                } else {
                    Via::Multicast
                };
                self.engine
                    .handle_datagram(self.now, from, via, chunk.rest());
            }
            op::FRAMED | op::SEALED => {
                let sel = chunk.u8();
                let kind = MessageKind::ALL[usize::from(chunk.u8()) % MessageKind::ALL.len()];
                let node = self.sender(sel);
                let mut datagram = Vec::new();
                Header {
                    kind,
                    domain: DOMAIN,
                    sender: node,
                }
                .emit(&mut datagram);
                datagram.extend_from_slice(chunk.rest());
                if sel & 0x40 != 0 {
                    // Numbered in order, or (bit 3) again with an older number: a replay.
                    self.signed += 1;
                    let count = if sel & 0x08 != 0 {
                        self.signed / 2
                    } else {
                        self.signed
                    };
                    let signer = identity(1 + (sel >> 4) % 3);
                    let Ok(signed) = ndds_core::wire::signed::wrap(&datagram, &signer, count)
                    else {
                        return;
                    };
                    datagram = signed;
                }
                if code % 6 == op::SEALED {
                    let session = sel / 4 % 4;
                    let flags = self.flags;
                    let sealer = self.sealers.entry((node, session)).or_insert_with(|| {
                        let setup = seal_setup(flags, u64::from(session) + 1);
                        Sealer::new(&setup.keyring, DOMAIN, node, setup.session, setup.mode)
                    });
                    if sealer.seal(&mut datagram).is_err() {
                        return;
                    }
                }
                let host = 1 + sel % 4;
                let from = SocketAddr::V4(SocketAddrV4::from(fixture::locator(host)));
                let via = if sel & 0x80 != 0 {
                    Via::Unicast
                } else {
                    Via::Multicast
                };
                self.engine.handle_datagram(self.now, from, via, &datagram);
            }
            op::TIME => {
                self.now += Duration::from_millis(u64::from(chunk.u16()));
                self.engine.handle_timeout(self.now);
            }
            op::LOCALS => {
                let byte = chunk.u8();
                let entity = u32::from(byte >> 2 & 7) + 1;
                let guarded = self.flags & flag::GUARDED != 0;
                let info = endpoint(participant(0, guarded), entity, byte & 1 != 0, 0);
                if byte & 2 != 0 {
                    self.engine.remove_locals(&[info.guid]);
                } else {
                    let _ = self.engine.add_local(self.now, info);
                }
            }
            _ => self.engine.close(),
        }
    }

    /// The node id a selector names: a remote host, or the engine itself.
    fn sender(&self, sel: u8) -> u64 {
        match sel % 4 {
            3 => self.engine.node_id(),
            i => node_id(i + 1, self.flags & flag::GUARDED != 0),
        }
    }

    /// Takes everything the engine has to say, and checks what must hold of it.
    fn drain(&mut self) {
        while let Some(transmit) = self.engine.poll_transmit() {
            assert!(
                transmit.payload.len() <= ndds_core::wire::MAX_DATAGRAM,
                "the engine sent a datagram larger than MAX_DATAGRAM"
            );
        }
        while self.engine.poll_event().is_some() {}
        if let Some(deadline) = self.engine.poll_timeout() {
            // A timer in the past is run at once by a driver: it must not stay due forever.
            if deadline <= self.now {
                self.engine.handle_timeout(self.now);
                while self.engine.poll_transmit().is_some() {}
                while self.engine.poll_event().is_some() {}
            }
        }
    }
}

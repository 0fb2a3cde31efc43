//! A participant's data plane ([`ParticipantCore`]) driven by a script of operations. The
//! participant under test (`LOCAL`) has two consumers and two producers, all matched with
//! endpoints of one peer participant (`PEER`) at host 1's data socket, so that datagrams
//! under the peer's id and from its address are believed and reach reliability,
//! reassembly, arbitration and repair.
//!
//! ```text
//! input := flags { op }
//! flags  bit 0: the domain has a key (datagrams below are sealed with the peer's key)
//!        bit 1: AES-256-GCM (else ChaCha20-Poly1305)
//!        bit 2: the peer seals integrity-only
//! op := RAW       u16 len | sel datagram        from the peer's address (sel bit 0: a
//!                                               stranger's); delivered as it is
//!     | DATA      u16 len | sel submessages     Data prefix built here: writer 1 or 4
//!                                               (sel bit 3), readers by sel bits 0-2
//!     | FEEDBACK  u16 len | sel submessages     Feedback prefix built here, echoing the
//!                                               token of LOCAL's data (sel bit 0: token 0)
//!     | TIME      u16 len | u16 ms              advance virtual time, run the timers
//!     | WRITE     u16 len | sel u16 size        producer 1 or 4 (sel bit 0) writes a sample
//!     | TAKEN     u16 len | n                   the application took n samples of consumer 2
//!     | MATCH     u16 len | sel                 discovery changes its mind (see `rematch`)
//! ```
//!
//! With a key, DATA and FEEDBACK are sealed with the peer's sealer, and so is RAW unless
//! sel bit 1 is set.

use std::net::SocketAddrV4;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use bytes::BytesMut;
use ndds_core::arbitration::Rules;
use ndds_core::participant::{
    ConsumerSpec, CoreConfig, MatchedConsumer, ParticipantCore, ProducerSpec,
};
use ndds_core::reliability::{ReaderConfig, WriterConfig};
use ndds_core::seal::{Opener, SealSetup, Sealer};
use ndds_core::wire::data::DataDatagram;
use ndds_core::wire::{Guid, Header, MessageKind};

use crate::Input;
use crate::fixture::{self, DOMAIN};

/// Operation codes.
pub mod op {
    /// A datagram as it is.
    pub const RAW: u8 = 0;
    /// Submessages behind a `Data` prefix built by the harness.
    pub const DATA: u8 = 1;
    /// Submessages behind a `Feedback` prefix built by the harness.
    pub const FEEDBACK: u8 = 2;
    /// Time passes.
    pub const TIME: u8 = 3;
    /// A local producer writes.
    pub const WRITE: u8 = 4;
    /// The application takes samples.
    pub const TAKEN: u8 = 5;
    /// Discovery changes the matches.
    pub const MATCH: u8 = 6;
    /// How many codes there are.
    pub const COUNT: u8 = 7;
}

/// Flag bits of the first byte.
pub mod flag {
    /// The domain has a key.
    pub const KEYED: u8 = 1;
    /// AES-256-GCM rather than ChaCha20-Poly1305.
    pub const AES: u8 = 2;
    /// The peer seals integrity-only.
    pub const INTEGRITY_ONLY: u8 = 4;
}

/// The participant under test.
pub const LOCAL: u64 = 0xA0;
/// The participant it is matched with.
pub const PEER: u64 = 0xB0;
/// Largest datagram either side sends (small, so samples of a few KiB are fragmented).
pub const MTU: usize = 1200;
/// Producer entities: reliable, best effort. The same numbers on both sides.
pub const PRODUCERS: [u32; 2] = [1, 4];
/// Consumer entities: reliable (matched with producer 1), best effort (with producer 4).
pub const CONSUMERS: [u32; 2] = [2, 3];

/// The data plane of `participant` (LOCAL or PEER) with the fixture's endpoints, matched
/// with the other participant's at host `other`'s data socket.
pub fn core(
    participant: u64,
    other: u64,
    other_addr: SocketAddrV4,
    now: Instant,
) -> ParticipantCore {
    let mut core = ParticipantCore::new(CoreConfig {
        domain: DOMAIN,
        participant,
        max_datagram: MTU,
        max_sample: 1 << 16,
        secret: [participant as u8; 32],
    });
    let reliable = WriterConfig {
        depth: 8,
        ..WriterConfig::default()
    };
    core.add_producer(PRODUCERS[0], producer(Some(reliable)));
    core.add_producer(PRODUCERS[1], producer(None));
    core.add_consumer(
        now,
        CONSUMERS[0],
        ConsumerSpec {
            rules: Rules::default(),
            reliable: Some(ReaderConfig::default()),
            credit: Some(4),
        },
    );
    core.add_consumer(
        now,
        CONSUMERS[1],
        ConsumerSpec {
            rules: Rules::default(),
            reliable: None,
            credit: None,
        },
    );
    for (producer, consumer) in PRODUCERS.into_iter().zip(CONSUMERS) {
        let matched = MatchedConsumer {
            guid: Guid {
                participant: other,
                entity: consumer,
            },
            locator: other_addr,
            reliable: producer == PRODUCERS[0],
        };
        core.set_producer_matched(now, producer, &[matched]);
        let writer = Guid {
            participant: other,
            entity: producer,
        };
        core.set_consumer_matched(now, consumer, [(writer, other_addr)]);
    }
    core
}

fn producer(reliable: Option<WriterConfig>) -> ProducerSpec {
    ProducerSpec {
        strength: 0,
        persistence_us: 0,
        late_joiners: if reliable.is_some() { 4 } else { 1 },
        reliable,
        refuse_when_full: false,
        batching: None,
    }
}

/// The seal setup of LOCAL (session 1) or PEER (session 2) in a keyed domain.
pub fn seal_setup(flags: u8, session: u64) -> SealSetup {
    SealSetup {
        keyring: fixture::keyring(fixture::cipher(u8::from(flags & flag::AES != 0))),
        mode: if flags & flag::INTEGRITY_ONLY != 0 {
            ndds_core::seal::SealMode::IntegrityOnly
        } else {
            ndds_core::seal::SealMode::Encrypt
        },
        session,
        require_encryption: false,
    }
}

/// The participant under test, virtual time, and the peer's side of the keys.
pub struct Harness {
    core: ParticipantCore,
    /// Virtual time.
    pub now: Instant,
    /// Seals what the harness builds, as the peer would (keyed domains only).
    sealer: Option<Sealer>,
    /// Opens what LOCAL sends, to learn its address token (keyed domains only).
    opener: Option<Opener>,
    /// The address token of LOCAL's data for PEER, once seen.
    token: u64,
    /// What LOCAL sent since the last [`Harness::take_sent`], when kept.
    sent: Vec<(SocketAddrV4, Vec<u8>)>,
    keep_sent: bool,
}

impl Harness {
    /// A harness for `flags` (see the module docs).
    pub fn new(flags: u8, now: Instant) -> Self {
        let mut core = core(LOCAL, PEER, fixture::data_addr(1), now);
        let (sealer, opener) = if flags & flag::KEYED != 0 {
            core.seal_with(seal_setup(flags, 1));
            let peer = seal_setup(flags, 2);
            let sealer = Sealer::new(&peer.keyring, DOMAIN, PEER, peer.session, peer.mode);
            let opener = Opener::new(peer.keyring, DOMAIN, false);
            (Some(sealer), Some(opener))
        } else {
            (None, None)
        };
        let mut harness = Harness {
            core,
            now,
            sealer,
            opener,
            token: 0,
            sent: Vec::new(),
            keep_sent: false,
        };
        harness.drain();
        harness
    }

    /// Keeps what LOCAL sends for [`Harness::take_sent`] (the seed generator delivers it to
    /// a real peer).
    pub fn keep_sent(&mut self) {
        self.keep_sent = true;
    }

    /// What LOCAL sent since the last call.
    pub fn take_sent(&mut self) -> Vec<(SocketAddrV4, Vec<u8>)> {
        std::mem::take(&mut self.sent)
    }

    /// Runs one operation and takes what it caused.
    pub fn step(&mut self, code: u8, chunk: &[u8]) {
        let mut chunk = Input::new(chunk);
        match code % op::COUNT {
            op::RAW => {
                let sel = chunk.u8();
                let from = fixture::data_addr(1 + (sel & 1));
                let mut datagram = chunk.rest().to_vec();
                if sel & 2 == 0 {
                    self.seal(&mut datagram);
                }
                self.deliver(from, datagram);
            }
            op::DATA => {
                let sel = chunk.u8();
                let writer = PRODUCERS[usize::from(sel >> 3 & 1)];
                let readers: Vec<u32> = [CONSUMERS[0], CONSUMERS[1], 99]
                    .into_iter()
                    .enumerate()
                    .filter(|(i, _)| sel & (1 << i) != 0)
                    .map(|(_, entity)| entity)
                    .collect();
                let mut datagram = header(MessageKind::Data);
                push_varint(&mut datagram, LOCAL);
                push_varint(&mut datagram, u64::from(writer));
                datagram.extend_from_slice(&u64::from(sel).to_le_bytes());
                push_varint(&mut datagram, readers.len() as u64);
                for reader in readers {
                    push_varint(&mut datagram, u64::from(reader));
                }
                datagram.extend_from_slice(chunk.rest());
                self.seal(&mut datagram);
                self.deliver(fixture::data_addr(1), datagram);
            }
            op::FEEDBACK => {
                let sel = chunk.u8();
                let token = if sel & 1 == 0 { self.token } else { 0 };
                let mut datagram = header(MessageKind::Feedback);
                push_varint(&mut datagram, LOCAL);
                datagram.extend_from_slice(&token.to_le_bytes());
                datagram.extend_from_slice(chunk.rest());
                self.seal(&mut datagram);
                self.deliver(fixture::data_addr(1), datagram);
            }
            op::TIME => {
                self.now += Duration::from_millis(u64::from(chunk.u16()));
                self.core.handle_timeout(self.now);
            }
            op::WRITE => {
                let sel = chunk.u8();
                let size = usize::from(chunk.u16() % 8192);
                let payload = Arc::new(vec![sel; size]);
                let entity = PRODUCERS[usize::from(sel & 1)];
                let _ = self.core.write(self.now, 1, entity, &payload);
            }
            op::TAKEN => {
                let taken = usize::from(chunk.u8());
                self.core.taken(self.now, CONSUMERS[0], taken);
            }
            _ => self.rematch(chunk.u8()),
        }
        self.drain();
    }

    /// Discovery's news: a match withdrawn, restored, or a writer lost.
    fn rematch(&mut self, sel: u8) {
        let index = usize::from(sel & 1);
        let writer = Guid {
            participant: PEER,
            entity: PRODUCERS[index],
        };
        let reader = Guid {
            participant: PEER,
            entity: CONSUMERS[index],
        };
        let peer_addr = fixture::data_addr(1);
        match sel >> 1 & 3 {
            0 => self.core.producer_lost(self.now, CONSUMERS[index], writer),
            1 => self
                .core
                .set_consumer_matched(self.now, CONSUMERS[index], [(writer, peer_addr)]),
            2 => self
                .core
                .set_producer_matched(self.now, PRODUCERS[index], &[]),
            _ => {
                let matched = MatchedConsumer {
                    guid: reader,
                    locator: peer_addr,
                    reliable: index == 0,
                };
                self.core
                    .set_producer_matched(self.now, PRODUCERS[index], &[matched]);
            }
        }
    }

    fn seal(&mut self, datagram: &mut Vec<u8>) {
        if let Some(sealer) = &mut self.sealer {
            // A datagram shorter than a header stays as it is (and is dropped as truncated).
            let _ = sealer.seal(datagram);
        }
    }

    fn deliver(&mut self, from: SocketAddrV4, datagram: Vec<u8>) {
        let received = SystemTime::UNIX_EPOCH + Duration::from_secs(1_700_000_000);
        self.core
            .handle_datagram(self.now, received, from, BytesMut::from(&datagram[..]));
    }

    /// Takes every transmit and event; learns LOCAL's address token from its data.
    fn drain(&mut self) {
        while let Some(transmit) = self.core.poll_transmit() {
            let mut bytes = [transmit.head(), transmit.tail()].concat();
            assert!(
                bytes.len() <= MTU,
                "a datagram of {} bytes exceeds max_datagram",
                bytes.len()
            );
            if self.keep_sent {
                self.sent.push((transmit.to, bytes.clone()));
            }
            self.learn_token(&mut bytes);
            self.core.recycle(transmit);
        }
        while self.core.poll_event().is_some() {}
    }

    fn learn_token(&mut self, bytes: &mut [u8]) {
        let plain: &[u8] = match &mut self.opener {
            Some(opener) => match opener.open(self.now, bytes) {
                Ok(plain) => plain,
                Err(_) => return,
            },
            None => bytes,
        };
        if let Ok(data) = DataDatagram::parse(plain, DOMAIN)
            && data.reader_participant == PEER
            && data.token != 0
        {
            self.token = data.token;
        }
    }
}

fn header(kind: MessageKind) -> Vec<u8> {
    let mut datagram = Vec::new();
    Header {
        kind,
        domain: DOMAIN,
        sender: PEER,
    }
    .emit(&mut datagram);
    datagram
}

/// Appends `value` as a postcard varint.
pub fn push_varint(out: &mut Vec<u8>, mut value: u64) {
    while value >= 0x80 {
        out.push(value as u8 | 0x80);
        value >>= 7;
    }
    out.push(value as u8);
}

/// Runs one script (see the module docs).
pub fn run(data: &[u8]) {
    let mut input = Input::new(data);
    let flags = input.u8();
    let mut harness = Harness::new(flags, Instant::now());
    while !input.is_empty() {
        let code = input.u8();
        let chunk = input.chunk();
        harness.step(code, chunk);
    }
}

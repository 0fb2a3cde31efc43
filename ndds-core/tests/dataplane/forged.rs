//! Forged traffic: a sample, a heartbeat, a gap and a piece of a large sample aimed at a
//! reliable consumer, an AckNack and a NackFrag aimed at its reliable producer, sent by an
//! attacker either under an id discovery never matched or under the matched peer's id from
//! the attacker's own address. Each is dropped and counted (`CoreStats::{unmatched_sender, wrong_address}`,
//! `ConsumerCounters::admission`), nothing is sent to the attacker, and the genuine stream,
//! over a lossy link that needs every repair, is unharmed. Feedback forged with the reader's
//! own address (which only a spoofing attacker can send) lacks the address token the
//! producer's data carries: its acknowledgements move nothing, and the repairs it asks for
//! stay within 3 times its bytes.

use ndds_core::participant::Event;
use ndds_core::wire::data::{Addressing, FLAG_RELIABLE, Fragment, Gap, Heartbeat, Sample};
use ndds_core::wire::feedback::{AckNack, NackFrag, encode_feedback};
use ndds_core::wire::{DataSub, DataWriter, FeedbackSub, SampleMeta};

use crate::sim::{
    App, DOMAIN, Link, MTU, SimNet, WriterApp, exactly, guid, locator, outsider, participant_id,
    payload, tag,
};
use crate::{MS, reliable_consumer, reliable_producer};

const PRODUCER: (usize, u32) = (0, 1);
const CONSUMER: (usize, u32) = (1, 2);
/// Samples of the genuine stream.
const TOTAL: u64 = 300;
/// A participant id discovery never heard of.
const STRANGER: u64 = 0x0BAD_0BAD;

/// Whose id the attacker uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Disguise {
    /// An id never matched.
    Stranger,
    /// The matched peer's id (the producer's towards the consumer, the consumer's towards
    /// the producer).
    Peer,
}

fn data(sender: u64, writer: u32, sub: &DataSub<'_>) -> Vec<u8> {
    let mut datagram = DataWriter::new();
    let readers = [CONSUMER.1];
    datagram.begin(
        DOMAIN,
        sender,
        &Addressing {
            reader_participant: participant_id(CONSUMER.0),
            writer,
            token: 0,
            readers: &readers,
        },
    );
    assert!(datagram.push(sub, MTU));
    datagram.bytes().to_vec()
}

fn feedback(sender: u64, sub: FeedbackSub<'_>) -> Vec<u8> {
    let mut datagram = Vec::new();
    encode_feedback(
        DOMAIN,
        sender,
        participant_id(PRODUCER.0),
        0,
        &[sub],
        &mut datagram,
    )
    .expect("encodes");
    datagram
}

/// The six forged datagrams: four for the consumer's host, two for the producer's.
fn forgeries(disguise: Disguise) -> (Vec<Vec<u8>>, Vec<Vec<u8>>) {
    let (data_sender, feedback_sender) = match disguise {
        Disguise::Stranger => (STRANGER, STRANGER),
        Disguise::Peer => (participant_id(PRODUCER.0), participant_id(CONSUMER.0)),
    };
    let far = 1 << 40;
    // Believed, it would take the topic over for good and make every genuine sample old.
    let bytes = payload(tag(PRODUCER.0, PRODUCER.1), far, 64);
    let sample = DataSub::Sample(Sample {
        meta: SampleMeta {
            seq: far,
            timestamp_ns: u64::MAX / 2,
            strength: i32::MAX,
            persistence_us: far,
            flags: FLAG_RELIABLE,
        },
        payload: &bytes,
    });
    // Believed, it would silence the stream, or report it all lost.
    let heartbeat = DataSub::Heartbeat(Heartbeat {
        first: 1 << 63,
        last: 1 << 63,
    });
    let gap = DataSub::Gap(Gap { from: 1, to: far });
    // The first of three pieces of a large sample: believed, the missing two would be asked
    // for, of the attacker's address; taken into reassembly under the peer's id, it would
    // become part of the genuine sample of its seq (seq 2 is large).
    let chunk = [0x5a; 1000];
    let piece = DataSub::Fragment(Fragment {
        meta: SampleMeta {
            seq: 2,
            timestamp_ns: 1,
            strength: 0,
            persistence_us: 0,
            flags: FLAG_RELIABLE,
        },
        total_len: 3000,
        frag_size: 1000,
        index: 0,
        chunk: &chunk,
    });
    let to_consumer = [&sample, &heartbeat, &gap, &piece]
        .into_iter()
        .map(|sub| data(data_sender, PRODUCER.1, sub))
        .collect();
    // Believed, it would settle every sample the reader has not got yet.
    let acknack = FeedbackSub::AckNack(AckNack {
        reader: CONSUMER.1,
        writer: PRODUCER.1,
        acked: far,
        missing: &[],
    });
    // Believed, it would have pieces resent (seq 2 is a large sample).
    let nackfrag = FeedbackSub::NackFrag(NackFrag {
        reader: CONSUMER.1,
        writer: PRODUCER.1,
        seq: 2,
        base: 0,
        missing: &[0xff],
    });
    let to_producer = [acknack, nackfrag]
        .into_iter()
        .map(|sub| feedback(feedback_sender, sub))
        .collect();
    (to_consumer, to_producer)
}

/// The reliable producer and consumer, matched, and a writer of `total` samples every 2 ms
/// whose even ones are 3000 bytes (three pieces); returns the writer's index.
fn stream(seed: u64, total: u64) -> (SimNet, usize) {
    let mut net = SimNet::new(seed, 2);
    net.add_producer(PRODUCER.0, PRODUCER.1, reliable_producer(64));
    net.add_consumer(
        CONSUMER.0,
        CONSUMER.1,
        reliable_consumer(Some(64)),
        App::Eager,
    );
    net.connect(PRODUCER, CONSUMER);
    let mut writer = WriterApp::new(PRODUCER.0, PRODUCER.1, total, 2 * MS, 500);
    writer.sizes = vec![500, 3_000];
    let writer = net.add_writer(writer);
    (net, writer)
}

/// The genuine stream over 20 % loss with the attacker's six datagrams every 20 ms while
/// it flows; returns how many rounds were sent.
fn attacked(seed: u64, disguise: Disguise) -> (SimNet, u64) {
    let (mut net, writer) = stream(seed, TOTAL);
    net.set_link(PRODUCER.0, CONSUMER.0, Link::lossy(0.2));
    let (to_consumer, to_producer) = forgeries(disguise);
    let mut rounds = 0;
    while !net.writers[writer].finished() {
        for datagram in &to_consumer {
            net.inject(outsider(), CONSUMER.0, datagram.clone());
        }
        for datagram in &to_producer {
            net.inject(outsider(), PRODUCER.0, datagram.clone());
        }
        rounds += 1;
        net.run_for(20 * MS);
    }
    // Past the time a sample from an unknown sender is held for a match that never comes.
    let done = net.run_until(net.at_ms(10_000), |n| {
        n.consumer(CONSUMER.0, CONSUMER.1).got.len() as u64 == TOTAL
    });
    assert!(done, "{:?}", net.stats);
    net.run_for(2_100 * MS);
    (net, rounds)
}

/// The genuine stream arrived whole, and nobody answered the attacker.
fn assert_unharmed(net: &SimNet) {
    let log = net.consumer(CONSUMER.0, CONSUMER.1);
    assert_eq!(
        exactly(&log.seqs_from(guid(PRODUCER.0, PRODUCER.1)), 1, TOTAL),
        Ok(())
    );
    assert!(
        log.got
            .iter()
            .all(|g| g.intact && g.writer == guid(PRODUCER.0, PRODUCER.1))
    );
    assert_eq!(log.notable(), vec![]);
    let counters = net.nodes[CONSUMER.0]
        .core
        .consumer_counters(CONSUMER.1)
        .expect("declared");
    assert_eq!(counters.arbiter.old_data, 0);
    assert_eq!(counters.arbiter.delivered, TOTAL);
    assert_eq!(net.outsiders, vec![]);
    assert!(
        !net.nodes[PRODUCER.0]
            .producer_events
            .iter()
            .any(|(_, e)| matches!(e, Event::ReaderSilenced { .. }))
    );
}

#[test]
fn forged_traffic_from_an_unmatched_sender_is_dropped_and_counted() {
    let (net, rounds) = attacked(41, Disguise::Stranger);
    assert_unharmed(&net);
    // The consumer held the sample, heartbeat and gap a moment for a match, then dropped
    // them; and the piece once (its copies are duplicates to reassembly, which holds it
    // without asking anyone for the rest). The producer holds no feedback.
    let consumer = net.nodes[CONSUMER.0].core.stats();
    assert_eq!(consumer.unmatched_sender, 3 * rounds + 1, "{consumer:?}");
    assert_eq!(consumer.wrong_address, 0);
    let counters = net.nodes[CONSUMER.0]
        .core
        .consumer_counters(CONSUMER.1)
        .expect("declared");
    assert_eq!(counters.admission.unmatched, 3 * rounds + 1);
    assert_eq!(counters.admission.released, 0);
    let producer = net.nodes[PRODUCER.0].core.stats();
    assert_eq!(producer.unmatched_sender, 2 * rounds, "{producer:?}");
    assert_eq!(producer.wrong_address, 0);
}

#[test]
fn forged_traffic_under_a_matched_id_from_another_address_is_dropped_and_counted() {
    let (net, rounds) = attacked(42, Disguise::Peer);
    assert_unharmed(&net);
    let consumer = net.nodes[CONSUMER.0].core.stats();
    assert_eq!(consumer.wrong_address, 4 * rounds, "{consumer:?}");
    assert_eq!(consumer.unmatched_sender, 0);
    let counters = net.nodes[CONSUMER.0]
        .core
        .consumer_counters(CONSUMER.1)
        .expect("declared");
    assert_eq!(counters.admission.wrong_address, 4 * rounds);
    let producer = net.nodes[PRODUCER.0].core.stats();
    assert_eq!(producer.wrong_address, 2 * rounds, "{producer:?}");
    assert_eq!(producer.unmatched_sender, 0);
}

/// Feedback under the reader's id *and* from the reader's own address, without the token
/// (what a host that forges source addresses can send, never having seen the data): a flood
/// of piece requests for the newest large sample gets at most 3 times its bytes back, and
/// an AckNack settling everything is ignored, so the stream that follows over a lossy link
/// still arrives whole, without a sample reported lost.
#[test]
fn feedback_from_the_readers_address_without_its_token_moves_nothing_and_is_not_amplified() {
    const FIRST: u64 = 10;
    const FLOOD: usize = 200;
    // Samples 1..=10: 10 is the newest large one.
    let (mut net, writer) = stream(43, FIRST);
    let done = net.run_until(net.at_ms(5_000), |n| {
        n.consumer(CONSUMER.0, CONSUMER.1).got.len() as u64 == FIRST
            && n.nodes[PRODUCER.0].core.unacknowledged(PRODUCER.1) == 0
    });
    assert!(done, "{:?}", net.stats);

    let consumer_id = participant_id(CONSUMER.0);
    let nackfrag = feedback(
        consumer_id,
        FeedbackSub::NackFrag(NackFrag {
            reader: CONSUMER.1,
            writer: PRODUCER.1,
            seq: FIRST,
            base: 0,
            missing: &[0xff; 64],
        }),
    );
    let acknack = feedback(
        consumer_id,
        FeedbackSub::AckNack(AckNack {
            reader: CONSUMER.1,
            writer: PRODUCER.1,
            acked: 1 << 40,
            missing: &[],
        }),
    );
    let before = net.nodes[PRODUCER.0].core.stats();
    let mut flood_bytes = 0;
    for _ in 0..FLOOD {
        for datagram in [&nackfrag, &acknack] {
            flood_bytes += datagram.len() as u64;
            net.inject(locator(CONSUMER.0), PRODUCER.0, datagram.clone());
        }
    }
    // Shorter than the idle heartbeat period: what the producer sends now answers the flood.
    net.run_for(100 * MS);
    let after = net.nodes[PRODUCER.0].core.stats();
    let answered = after.transmit_bytes - before.transmit_bytes;
    assert!(
        answered <= 3 * flood_bytes,
        "{answered} B sent for {flood_bytes} B of unvalidated feedback"
    );
    eprintln!("{answered} B sent for {flood_bytes} B of unvalidated feedback");
    // The flood asked for 512 pieces per request; the sample has 3.
    assert!(answered > 0, "the allowance lets some pieces through");
    assert_eq!(
        after.unvalidated_feedback - before.unvalidated_feedback,
        2 * FLOOD as u64,
        "{after:?}"
    );
    assert!(after.pieces_withheld > before.pieces_withheld, "{after:?}");
    assert_eq!(after.wrong_address, 0);
    assert_eq!(after.unmatched_sender, 0);

    // Had the AckNack been believed, the writer would think everything settled and the
    // consumer would see samples lost over the lossy link that follows.
    net.set_link(PRODUCER.0, CONSUMER.0, Link::lossy(0.2));
    net.writers[writer].total = 3 * FIRST;
    let done = net.run_until(net.at_ms(10_000), |n| {
        n.consumer(CONSUMER.0, CONSUMER.1).got.len() as u64 == 3 * FIRST
    });
    assert!(done, "{:?}", net.stats);
    let log = net.consumer(CONSUMER.0, CONSUMER.1);
    assert_eq!(
        exactly(&log.seqs_from(guid(PRODUCER.0, PRODUCER.1)), 1, 3 * FIRST),
        Ok(())
    );
    assert_eq!(log.notable(), vec![]);
    assert_eq!(net.outsiders, vec![]);
}

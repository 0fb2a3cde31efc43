//! What the simulated applications write and how what they got is checked: payloads that
//! carry their writer's tag and seq, and reliable streams seen as samples and lost runs.

use std::time::Duration;

use ndds_core::arbitration::Notification;
use ndds_core::wire::Guid;

use super::apps::ConsumerLog;
use super::participant_id;

/// Bytes of a payload's self-check header (tag and seq).
pub const PAYLOAD_HEADER: usize = 16;

/// The encoded sample a writer writes: tag, seq, then a pattern derived from both, so a
/// corrupted, truncated or mixed-up sample shows.
pub fn payload(tag: u64, seq: u64, size: usize) -> Vec<u8> {
    let size = size.max(PAYLOAD_HEADER);
    let mut bytes = Vec::with_capacity(size);
    bytes.extend_from_slice(&tag.to_le_bytes());
    bytes.extend_from_slice(&seq.to_le_bytes());
    bytes.extend((PAYLOAD_HEADER..size).map(|i| pattern(tag, seq, i)));
    bytes
}

fn pattern(tag: u64, seq: u64, i: usize) -> u8 {
    (tag.wrapping_mul(131) ^ seq.wrapping_mul(31) ^ i as u64) as u8
}

/// The tag and seq a payload says it carries, if it is intact.
pub fn check_payload(bytes: &[u8]) -> Option<(u64, u64)> {
    let tag = u64::from_le_bytes(bytes.get(0..8)?.try_into().ok()?);
    let seq = u64::from_le_bytes(bytes.get(8..16)?.try_into().ok()?);
    let intact = bytes
        .iter()
        .enumerate()
        .skip(PAYLOAD_HEADER)
        .all(|(i, b)| *b == pattern(tag, seq, i));
    intact.then_some((tag, seq))
}

/// The tag the writers of endpoint `entity` of node `node` put in their payloads.
pub fn tag(node: usize, entity: u32) -> u64 {
    (node as u64) << 32 | u64::from(entity)
}

/// The payload tag of a writer, from its id.
pub fn tag_of(writer: Guid) -> u64 {
    let node = writer.participant.wrapping_sub(participant_id(0));
    tag(node as usize, writer.entity)
}

/// Checks that `seqs` is exactly `first..=last` in order.
pub fn exactly(seqs: &[u64], first: u64, last: u64) -> Result<(), String> {
    let expected: Vec<u64> = (first..=last).collect();
    if seqs == expected {
        return Ok(());
    }
    let dup = seqs.windows(2).find(|w| w[1] <= w[0]);
    let missing: Vec<u64> = expected
        .iter()
        .filter(|s| !seqs.contains(s))
        .take(10)
        .copied()
        .collect();
    Err(format!(
        "{} seqs, expected {}..={last}: first out of order {dup:?}, first missing {missing:?}",
        seqs.len(),
        first
    ))
}

/// Checks that a reliable stream as the consumer saw it ([`stream_of`]) covers
/// `first..=last` exactly once, in order, with samples and lost runs; returns the lost runs.
pub fn covers(stream: &[Item], first: u64, last: u64) -> Result<Vec<(u64, u64)>, String> {
    let mut expected = first;
    let mut lost = Vec::new();
    for (i, item) in stream.iter().enumerate() {
        match *item {
            Item::Sample(seq) => {
                if seq != expected {
                    return Err(format!("item {i}: sample {seq}, expected {expected}"));
                }
                expected += 1;
            }
            Item::Lost(from, to) => {
                if from != expected || to <= from {
                    return Err(format!("item {i}: lost {from}..{to}, expected {expected}"));
                }
                lost.push((from, to));
                expected = to;
            }
        }
    }
    if expected != last + 1 {
        return Err(format!("stream ends before {expected}, expected {last}"));
    }
    Ok(lost)
}

/// One step of a reliable stream as a consumer saw it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Item {
    /// A sample.
    Sample(u64),
    /// Seqs `from..to` reported lost.
    Lost(u64, u64),
}

/// The samples of `writer` the application took and the lost runs reported, in the order
/// the core handed them out: by virtual time, and within one instant a lost run `from..to`
/// before the sample `to` that follows it.
pub fn stream_of(log: &ConsumerLog, writer: Guid) -> Vec<Item> {
    // Samples and notifications are logged apart; a run keyed by its first seq sorts
    // between the samples before it and the sample that follows it.
    let mut items: Vec<(Duration, u64, Item)> = log
        .got
        .iter()
        .filter(|g| g.writer == writer)
        .map(|g| (g.delivered, g.seq, Item::Sample(g.seq)))
        .collect();
    for (at, n) in &log.notifications {
        if let Notification::SamplesLost {
            writer: w,
            from,
            to,
        } = n
            && *w == writer
        {
            items.push((*at, *from, Item::Lost(*from, *to)));
        }
    }
    items.sort_by_key(|(at, seq, _)| (*at, *seq));
    items.into_iter().map(|(_, _, item)| item).collect()
}

//! The endpoint table: every known endpoint (local and remote), indexed by topic, and the
//! matching rules between them.
//!
//! Matching: a producer and a consumer match when their topic names are equal, their type
//! fingerprints are equal, and the producer offers reliability if the consumer requests it;
//! otherwise, on one topic, they are *incompatible* (see [`incompatibility`]). Events are
//! produced only for the local side of a pair; a pair of two local endpoints produces an event
//! for each, the consumer's first.
//!
//! Cost: each side of a topic keeps its local and remote endpoints apart, so adding or removing
//! a remote endpoint visits only the local endpoints of the opposite side: a burst of `n`
//! remote endpoints on one topic costs `n` times the (few) local ones, never `n²`. The table
//! also keeps the estimated bytes each owner's entries hold ([`entry_cost`]), for the engine's
//! memory bound.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::Arc;
use std::time::Instant;

use super::event::Event;
use crate::security::Refusal;
use crate::wire::{EndpointInfo, EndpointKind, EndpointQos, Guid, Reliability};

/// Why a producer and a consumer of one topic do not match.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Incompatibility {
    /// Their type fingerprints differ.
    Type,
    /// The consumer requests reliability and the producer offers best effort only.
    Reliability,
}

/// Why `a` and `b` (a producer and a consumer of one topic, in either order) do not match, or
/// `None` when they do.
pub fn incompatibility(a: &EndpointInfo, b: &EndpointInfo) -> Option<Incompatibility> {
    if a.fingerprint != b.fingerprint {
        return Some(Incompatibility::Type);
    }
    let (producer, consumer) = match (&a.qos, &b.qos) {
        (EndpointQos::Producer(p), EndpointQos::Consumer(c))
        | (EndpointQos::Consumer(c), EndpointQos::Producer(p)) => (p, c),
        _ => return None,
    };
    let wants_reliable = matches!(consumer.reliability, Reliability::Reliable { .. });
    let offers_reliable = matches!(producer.reliability, Reliability::Reliable { .. });
    (wants_reliable && !offers_reliable).then_some(Incompatibility::Reliability)
}

/// Who owns an endpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Origin {
    /// A client of this node.
    Local,
    /// A remote node (by node id).
    Remote(u64),
}

/// One endpoint entry.
#[derive(Clone, Debug)]
pub struct Entry {
    /// What was declared or announced.
    pub info: EndpointInfo,
    /// Owner.
    pub origin: Origin,
    /// When a remote entry decays unless refreshed (`None` for local entries).
    pub expires: Option<Instant>,
    /// Why the permissions document does not let this (remote) endpoint match anything;
    /// `None`: no document, or it allows it.
    pub refused: Option<Arc<Refusal>>,
}

/// Bytes an entry is estimated to hold beyond its encoded size: the entry in its hash map
/// (whose capacity doubles), its keys in four ordered indexes, and the allocator's share.
/// Measured: a daemon holding 29 400 small remote endpoints this way grew by 35 MiB for 32 MiB
/// accounted (`interop-tests/tests/netns_flood.rs`).
const ENTRY_OVERHEAD: usize = 1024;

/// The estimated memory held by an entry of `info`: twice its encoded size (decoded strings
/// and layout nodes are larger than their bytes on the wire) plus the indexes' share.
pub fn entry_cost(info: &EndpointInfo) -> usize {
    let size = postcard::ser_flavors::Size::default();
    let encoded = postcard::serialize_with_flavor(info, size).unwrap_or(crate::wire::MAX_DATAGRAM);
    ENTRY_OVERHEAD + 2 * encoded
}

/// One side (producers or consumers) of a topic: local and remote endpoints apart.
#[derive(Debug, Default)]
struct Side {
    local: BTreeSet<Guid>,
    remote: BTreeSet<Guid>,
}

impl Side {
    fn of(&mut self, origin: Origin) -> &mut BTreeSet<Guid> {
        match origin {
            Origin::Local => &mut self.local,
            Origin::Remote(_) => &mut self.remote,
        }
    }

    /// The endpoints an endpoint of `origin` pairs with on this side: all of them for a local
    /// one, the local ones for a remote one (a remote pair concerns no client here).
    fn partners(&self, origin: Origin) -> impl Iterator<Item = &Guid> {
        let remote = match origin {
            Origin::Local => Some(&self.remote),
            Origin::Remote(_) => None,
        };
        self.local.iter().chain(remote.into_iter().flatten())
    }

    fn is_empty(&self) -> bool {
        self.local.is_empty() && self.remote.is_empty()
    }
}

/// The endpoints of one topic, by kind, so matching visits only the opposite kind.
#[derive(Debug, Default)]
struct TopicEntry {
    producers: Side,
    consumers: Side,
}

impl TopicEntry {
    fn side(&mut self, kind: EndpointKind) -> &mut Side {
        match kind {
            EndpointKind::Producer => &mut self.producers,
            EndpointKind::Consumer => &mut self.consumers,
        }
    }

    fn opposite(&self, kind: EndpointKind) -> &Side {
        match kind {
            EndpointKind::Producer => &self.consumers,
            EndpointKind::Consumer => &self.producers,
        }
    }

    fn is_empty(&self) -> bool {
        self.producers.is_empty() && self.consumers.is_empty()
    }
}

/// All endpoints, in guid order (for listing them a page at a time), indexed by topic (for
/// matching), by owner (for forgetting a node) and by expiry (for decay), so no operation
/// scans the whole table.
#[derive(Debug, Default)]
pub struct Table {
    entries: BTreeMap<Guid, Entry>,
    by_topic: HashMap<String, TopicEntry>,
    by_origin: HashMap<Origin, BTreeSet<Guid>>,
    by_expiry: BTreeSet<(Instant, Guid)>,
    /// Estimated bytes held by each owner's entries ([`entry_cost`]).
    bytes: HashMap<Origin, usize>,
}

impl Table {
    /// The entry for `guid`.
    pub fn get(&self, guid: &Guid) -> Option<&Entry> {
        self.entries.get(guid)
    }

    /// Gives an existing entry its (possibly new) owner and expiry, without match events: the
    /// endpoint itself did not change.
    /// Moving between a local and a remote owner is not a move: remove and insert instead.
    pub fn move_to(&mut self, guid: &Guid, origin: Origin, expires: Instant) {
        let Some(entry) = self.entries.get_mut(guid) else {
            return;
        };
        debug_assert_eq!(
            entry.origin == Origin::Local,
            origin == Origin::Local,
            "an entry changes between local and remote only by removal"
        );
        let cost = entry_cost(&entry.info);
        unindex(&mut self.by_origin, &mut self.by_expiry, entry);
        uncharge(&mut self.bytes, entry.origin, cost);
        entry.origin = origin;
        entry.expires = Some(expires);
        index(&mut self.by_origin, &mut self.by_expiry, entry);
        *self.bytes.entry(origin).or_default() += cost;
    }

    /// Estimated bytes held by the entries of `origin`.
    pub fn bytes_of(&self, origin: Origin) -> usize {
        self.bytes.get(&origin).copied().unwrap_or(0)
    }

    /// All entries, in guid order.
    pub fn iter(&self) -> impl Iterator<Item = &Entry> {
        self.entries.values()
    }

    /// The entries with guids after `after` (all of them for `None`), in guid order.
    pub fn after(&self, after: Option<Guid>) -> impl Iterator<Item = &Entry> {
        use std::ops::Bound;
        let from = after.map_or(Bound::Unbounded, Bound::Excluded);
        self.entries
            .range((from, Bound::Unbounded))
            .map(|(_, entry)| entry)
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when the table is empty.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Inserts a new entry (the caller removed any previous one with the same guid) and
    /// pushes the match events it causes.
    pub fn insert(&mut self, entry: Entry, events: &mut impl Extend<Event>) {
        let guid = entry.info.guid;
        let kind = entry.info.kind();
        let topic = self.by_topic.entry(entry.info.topic.clone()).or_default();
        for other_guid in topic.opposite(kind).partners(entry.origin) {
            let Some(other) = self.entries.get(other_guid) else {
                continue;
            };
            let mut told = [
                (entry.origin == Origin::Local).then(|| pair_event(&entry, other)),
                (other.origin == Origin::Local).then(|| pair_event(other, &entry)),
            ];
            // Of two local endpoints the consumer hears of the pair first (in a domain with
            // permissions its data keys come with it, and a sealed sample from a producer it
            // holds no key for is dropped before admission). The daemon keeps this order per
            // client; across clients, processes and threads it is not a guarantee.
            if kind == EndpointKind::Producer {
                told.reverse();
            }
            events.extend(told.into_iter().flatten());
        }
        topic.side(kind).of(entry.origin).insert(guid);
        index(&mut self.by_origin, &mut self.by_expiry, &entry);
        *self.bytes.entry(entry.origin).or_default() += entry_cost(&entry.info);
        self.entries.insert(guid, entry);
    }

    /// Gives an entry a new refusal: its pairs are unmatched and paired again (with the match
    /// events that brings) when it changed.
    pub fn set_refused(
        &mut self,
        guid: &Guid,
        refused: Option<Arc<Refusal>>,
        events: &mut impl Extend<Event>,
    ) {
        if self.entries.get(guid).is_none_or(|e| e.refused == refused) {
            return;
        }
        if let Some(mut entry) = self.remove(guid, events) {
            entry.refused = refused;
            self.insert(entry, events);
        }
    }

    /// Removes an entry and pushes an `Unmatched` event for every local endpoint that was
    /// paired with it (matched, incompatible or refused).
    pub fn remove(&mut self, guid: &Guid, events: &mut impl Extend<Event>) -> Option<Entry> {
        let entry = self.entries.remove(guid)?;
        unindex(&mut self.by_origin, &mut self.by_expiry, &entry);
        uncharge(&mut self.bytes, entry.origin, entry_cost(&entry.info));
        let kind = entry.info.kind();
        if let Some(topic) = self.by_topic.get_mut(&entry.info.topic) {
            topic.side(kind).of(entry.origin).remove(guid);
            for other_guid in topic.opposite(kind).partners(entry.origin) {
                let Some(other) = self.entries.get(other_guid) else {
                    continue;
                };
                if entry.origin == Origin::Local {
                    events.extend([Event::Unmatched {
                        local: *guid,
                        remote: *other_guid,
                    }]);
                }
                if other.origin == Origin::Local {
                    events.extend([Event::Unmatched {
                        local: *other_guid,
                        remote: *guid,
                    }]);
                }
            }
            if topic.is_empty() {
                self.by_topic.remove(&entry.info.topic);
            }
        }
        Some(entry)
    }

    /// Number of entries owned by `origin`.
    pub fn count_owned(&self, origin: Origin) -> usize {
        self.by_origin.get(&origin).map_or(0, BTreeSet::len)
    }

    /// Number of entries owned by remote nodes.
    pub fn count_remote(&self) -> usize {
        self.entries.len() - self.count_owned(Origin::Local)
    }

    /// Guids of the entries owned by `origin`, in order.
    pub fn owned_by(&self, origin: Origin) -> Vec<Guid> {
        self.by_origin
            .get(&origin)
            .map(|guids| guids.iter().copied().collect())
            .unwrap_or_default()
    }

    /// Earliest expiry among remote entries.
    pub fn earliest_expiry(&self) -> Option<Instant> {
        self.by_expiry.first().map(|(at, _)| *at)
    }

    /// Guids of remote entries whose lease ended at or before `now`.
    pub fn expired(&self, now: Instant) -> Vec<Guid> {
        self.by_expiry
            .iter()
            .take_while(|(at, _)| *at <= now)
            .map(|(_, guid)| *guid)
            .collect()
    }
}

fn index(
    by_origin: &mut HashMap<Origin, BTreeSet<Guid>>,
    by_expiry: &mut BTreeSet<(Instant, Guid)>,
    entry: &Entry,
) {
    by_origin
        .entry(entry.origin)
        .or_default()
        .insert(entry.info.guid);
    if let Some(at) = entry.expires {
        by_expiry.insert((at, entry.info.guid));
    }
}

fn uncharge(bytes: &mut HashMap<Origin, usize>, origin: Origin, cost: usize) {
    if let Some(held) = bytes.get_mut(&origin) {
        *held = held.saturating_sub(cost);
        if *held == 0 {
            bytes.remove(&origin);
        }
    }
}

fn unindex(
    by_origin: &mut HashMap<Origin, BTreeSet<Guid>>,
    by_expiry: &mut BTreeSet<(Instant, Guid)>,
    entry: &Entry,
) {
    if let Some(guids) = by_origin.get_mut(&entry.origin) {
        guids.remove(&entry.info.guid);
        if guids.is_empty() {
            by_origin.remove(&entry.origin);
        }
    }
    if let Some(at) = entry.expires {
        by_expiry.remove(&(at, entry.info.guid));
    }
}

fn pair_event(local: &Entry, other: &Entry) -> Event {
    if let Some(refusal) = other.refused.as_ref().or(local.refused.as_ref()) {
        return Event::Refused {
            local: local.info.guid,
            remote: other.info.clone(),
            reason: refusal.to_string(),
        };
    }
    let (local, other) = (&local.info, &other.info);
    if incompatibility(local, other).is_none() {
        Event::Matched {
            local: local.guid,
            remote: other.clone(),
        }
    } else {
        Event::Incompatible {
            local: local.guid,
            remote: other.clone(),
        }
    }
}

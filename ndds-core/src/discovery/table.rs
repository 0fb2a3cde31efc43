//! The endpoint table: every known endpoint (local and remote), indexed by topic, and the
//! matching rules between them.
//!
//! Matching: a producer and a consumer match when their topic names are equal and their type
//! fingerprints are equal; when the names are equal and the fingerprints differ they are
//! *incompatible*. Events are produced only for the local side of a pair; a pair of two local
//! endpoints produces an event for each.

use std::collections::{BTreeSet, HashMap};
use std::time::Instant;

use super::event::Event;
use crate::wire::{EndpointInfo, EndpointKind, Guid};

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
}

/// The endpoints of one topic, by kind, so matching visits only the opposite kind.
#[derive(Debug, Default)]
struct TopicEntry {
    producers: BTreeSet<Guid>,
    consumers: BTreeSet<Guid>,
}

impl TopicEntry {
    fn side(&mut self, kind: EndpointKind) -> &mut BTreeSet<Guid> {
        match kind {
            EndpointKind::Producer => &mut self.producers,
            EndpointKind::Consumer => &mut self.consumers,
        }
    }

    fn opposite(&self, kind: EndpointKind) -> &BTreeSet<Guid> {
        match kind {
            EndpointKind::Producer => &self.consumers,
            EndpointKind::Consumer => &self.producers,
        }
    }

    fn is_empty(&self) -> bool {
        self.producers.is_empty() && self.consumers.is_empty()
    }
}

/// All endpoints, with a topic index.
#[derive(Debug, Default)]
pub struct Table {
    entries: HashMap<Guid, Entry>,
    by_topic: HashMap<String, TopicEntry>,
    per_origin: HashMap<Origin, usize>,
}

impl Table {
    /// The entry for `guid`.
    pub fn get(&self, guid: &Guid) -> Option<&Entry> {
        self.entries.get(guid)
    }

    /// Gives an existing entry its (possibly new) owner and expiry, without match events: the
    /// endpoint itself did not change.
    pub fn move_to(&mut self, guid: &Guid, origin: Origin, expires: Instant) {
        if let Some(entry) = self.entries.get_mut(guid) {
            uncount(&mut self.per_origin, entry.origin);
            *self.per_origin.entry(origin).or_default() += 1;
            entry.origin = origin;
            entry.expires = Some(expires);
        }
    }

    /// All entries.
    pub fn iter(&self) -> impl Iterator<Item = &Entry> {
        self.entries.values()
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
        for other_guid in topic.opposite(kind) {
            let Some(other) = self.entries.get(other_guid) else {
                continue;
            };
            if entry.origin == Origin::Local {
                events.extend([pair_event(&entry.info, &other.info)]);
            }
            if other.origin == Origin::Local {
                events.extend([pair_event(&other.info, &entry.info)]);
            }
        }
        topic.side(kind).insert(guid);
        *self.per_origin.entry(entry.origin).or_default() += 1;
        self.entries.insert(guid, entry);
    }

    /// Removes an entry and pushes an `Unmatched` event for every local endpoint that was
    /// paired with it (matched or incompatible).
    pub fn remove(&mut self, guid: &Guid, events: &mut impl Extend<Event>) -> Option<Entry> {
        let entry = self.entries.remove(guid)?;
        uncount(&mut self.per_origin, entry.origin);
        let kind = entry.info.kind();
        if let Some(topic) = self.by_topic.get_mut(&entry.info.topic) {
            topic.side(kind).remove(guid);
            for other_guid in topic.opposite(kind) {
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
        self.per_origin.get(&origin).copied().unwrap_or(0)
    }

    /// Guids of the entries owned by `origin`.
    pub fn owned_by(&self, origin: Origin) -> Vec<Guid> {
        let mut guids: Vec<Guid> = self
            .entries
            .values()
            .filter(|e| e.origin == origin)
            .map(|e| e.info.guid)
            .collect();
        guids.sort();
        guids
    }

    /// Earliest expiry among remote entries.
    pub fn earliest_expiry(&self) -> Option<Instant> {
        self.entries.values().filter_map(|e| e.expires).min()
    }

    /// Guids of remote entries whose lease ended at or before `now`.
    pub fn expired(&self, now: Instant) -> Vec<Guid> {
        self.entries
            .values()
            .filter(|e| e.expires.is_some_and(|t| t <= now))
            .map(|e| e.info.guid)
            .collect()
    }
}

fn uncount(counts: &mut HashMap<Origin, usize>, origin: Origin) {
    if let Some(count) = counts.get_mut(&origin) {
        *count -= 1;
        if *count == 0 {
            counts.remove(&origin);
        }
    }
}

fn pair_event(local: &EndpointInfo, other: &EndpointInfo) -> Event {
    if local.fingerprint == other.fingerprint {
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

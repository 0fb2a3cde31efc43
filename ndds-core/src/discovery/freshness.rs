//! Which signed discovery datagrams of a node were taken already, in a domain with
//! permissions: each datagram number ([`crate::wire::signed`]) once, and none of a node that
//! is gone below the highest number it was heard with.
//!
//! Without this a host that holds the domain key could re-seal a daemon's recorded signed
//! datagrams: bring a node that said `Bye` back as a ghost, announce withdrawn endpoints
//! again, or shorten a lease with an old announcement.

use std::collections::{HashMap, VecDeque};

use crate::seal::window::ReplayWindow;
use crate::security::PublicId;

/// Nodes remembered per identity after they are gone (a daemon's restarts, each a new node
/// id): more than a daemon restarts within the lease of its old entries elsewhere.
pub const GONE_PER_IDENTITY: usize = 8;

/// The numbers a known node's datagrams were taken with.
#[derive(Clone, Debug)]
pub(crate) struct Counts {
    /// Numbers at or below it are refused (the node was heard up to it before it was gone).
    floor: u64,
    window: ReplayWindow,
}

impl Counts {
    /// A node first heard (again) with datagram number `count`, nothing at or below `floor`
    /// taken.
    pub(crate) fn new(floor: u64, count: u64) -> Self {
        let mut window = ReplayWindow::new();
        window.accept(count);
        Counts { floor, window }
    }

    /// Takes `count` if it was not taken before; false for a replay (or a number too old to
    /// tell).
    pub(crate) fn take(&mut self, count: u64) -> bool {
        if count <= self.floor || !self.window.fresh(count) {
            return false;
        }
        self.window.accept(count);
        true
    }

    /// The highest number taken.
    pub(crate) fn highest(&self) -> u64 {
        self.window.highest().unwrap_or(self.floor).max(self.floor)
    }
}

/// The highest datagram numbers of nodes that are gone, a few per identity. Only identities
/// the permissions document names are kept: a node of any other identity is refused
/// everything anyway, so its ghost would match nothing, and keeping only named identities
/// bounds the memory by the document (`MAX_SUBJECTS` x [`GONE_PER_IDENTITY`]).
#[derive(Debug, Default)]
pub(crate) struct Gone {
    by_identity: HashMap<PublicId, VecDeque<(u64, u64)>>,
}

impl Gone {
    /// Remembers that `node` of `identity` was heard up to `highest`; the identity's oldest
    /// remembered node makes room.
    pub(crate) fn insert(&mut self, identity: PublicId, node: u64, highest: u64) {
        let nodes = self.by_identity.entry(identity).or_default();
        nodes.retain(|(known, _)| *known != node);
        if nodes.len() >= GONE_PER_IDENTITY {
            nodes.pop_front();
        }
        nodes.push_back((node, highest));
    }

    /// The floor of a node heard again: the highest number it was taken with before.
    pub(crate) fn floor(&self, identity: &PublicId, node: u64) -> u64 {
        self.by_identity
            .get(identity)
            .and_then(|nodes| nodes.iter().find(|(known, _)| *known == node))
            .map_or(0, |(_, highest)| *highest)
    }

    /// Forgets identities the document no longer names.
    pub(crate) fn retain(&mut self, mut named: impl FnMut(&PublicId) -> bool) {
        self.by_identity.retain(|identity, _| named(identity));
    }

    /// Nodes remembered.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.by_identity.values().map(VecDeque::len).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_node_takes_each_number_once_and_nothing_below_its_floor() {
        let mut counts = Counts::new(10, 12);
        assert!(!counts.take(12), "taken when first heard");
        assert!(!counts.take(10) && !counts.take(3), "at or below the floor");
        assert!(counts.take(11), "above the floor, not taken yet");
        assert!(counts.take(40) && !counts.take(40));
        assert_eq!(counts.highest(), 40);
    }

    #[test]
    fn gone_nodes_keep_their_highest_number_a_few_per_identity() {
        let (a, b) = (PublicId::from_bytes([1; 32]), PublicId::from_bytes([2; 32]));
        let mut gone = Gone::default();
        for node in 0..GONE_PER_IDENTITY as u64 + 2 {
            gone.insert(a, node, 100 + node);
        }
        gone.insert(b, 7, 5);
        assert_eq!(gone.floor(&a, 0), 0, "the oldest made room");
        assert_eq!(gone.floor(&a, 1), 0);
        assert_eq!(gone.floor(&a, 2), 102);
        assert_eq!(gone.floor(&b, 7), 5);
        assert_eq!(gone.len(), GONE_PER_IDENTITY + 1);
        gone.insert(a, 2, 300);
        assert_eq!(gone.floor(&a, 2), 300, "the newest count replaces the old");
        gone.retain(|identity| *identity == b);
        assert_eq!((gone.len(), gone.floor(&a, 2)), (1, 0));
    }
}

//! What each source address holds in the discovery tables, and whom to evict when they are full.
//!
//! Every remote node is charged, to the IP address its datagrams come from, the estimated bytes
//! of its node entry and its endpoints. When the tables are full (by bytes or by count) the
//! engine evicts whole nodes: the least recently heard node of the *busiest* source goes
//! first. A flood of forged nodes from one address therefore evicts its own oldest entries,
//! and a genuine daemon arriving from another address still gets in; a source can never push
//! out a smaller one to make room for itself.

use std::collections::{BTreeSet, HashMap};
use std::net::IpAddr;
use std::time::Instant;

/// The charge of one source address.
#[derive(Debug, Default)]
struct Source {
    bytes: usize,
    /// Its nodes by when they were last heard from, oldest first.
    nodes: BTreeSet<(Instant, u64)>,
}

/// Bytes and nodes per source address, with the busiest source found in `O(log n)`.
#[derive(Debug, Default)]
pub struct Sources {
    by_address: HashMap<IpAddr, Source>,
    /// (bytes, address) of every source, so the largest is the last.
    busiest: BTreeSet<(usize, IpAddr)>,
    total: usize,
}

impl Sources {
    /// Estimated bytes held by all remote nodes and their endpoints.
    pub fn total(&self) -> usize {
        self.total
    }

    /// Estimated bytes held for one source address.
    pub fn bytes_of(&self, address: IpAddr) -> usize {
        self.by_address.get(&address).map_or(0, |s| s.bytes)
    }

    /// A node starts being charged to `address`, last heard at `seen`, holding `bytes`.
    pub fn add(&mut self, address: IpAddr, node: u64, seen: Instant, bytes: usize) {
        let source = self.by_address.entry(address).or_default();
        self.busiest.remove(&(source.bytes, address));
        source.bytes += bytes;
        source.nodes.insert((seen, node));
        self.busiest.insert((source.bytes, address));
        self.total += bytes;
    }

    /// A node charged to `address` (last heard at `seen`, holding `bytes`) is gone.
    pub fn remove(&mut self, address: IpAddr, node: u64, seen: Instant, bytes: usize) {
        let Some(source) = self.by_address.get_mut(&address) else {
            return;
        };
        self.busiest.remove(&(source.bytes, address));
        source.bytes = source.bytes.saturating_sub(bytes);
        source.nodes.remove(&(seen, node));
        self.total = self.total.saturating_sub(bytes);
        if source.nodes.is_empty() {
            self.by_address.remove(&address);
        } else {
            self.busiest.insert((source.bytes, address));
        }
    }

    /// A node's charge changes from `old` to `new` bytes.
    pub fn recharge(&mut self, address: IpAddr, old: usize, new: usize) {
        let Some(source) = self.by_address.get_mut(&address) else {
            return;
        };
        self.busiest.remove(&(source.bytes, address));
        source.bytes = source.bytes.saturating_sub(old) + new;
        self.busiest.insert((source.bytes, address));
        self.total = self.total.saturating_sub(old) + new;
    }

    /// A node was heard from again.
    pub fn heard(&mut self, address: IpAddr, node: u64, before: Instant, now: Instant) {
        if let Some(source) = self.by_address.get_mut(&address) {
            source.nodes.remove(&(before, node));
            source.nodes.insert((now, node));
        }
    }

    /// The node to evict to make room for `keep`'s source: the least recently heard node of
    /// the busiest source, never `keep` itself. `None` when the busiest source holds only
    /// `keep`: then it is `keep` that must go without.
    pub fn victim(&self, keep: Option<u64>) -> Option<u64> {
        let (_, address) = self.busiest.last()?;
        self.by_address[address]
            .nodes
            .iter()
            .map(|(_, node)| *node)
            .find(|node| Some(*node) != keep)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn ip(last: u8) -> IpAddr {
        IpAddr::from([10, 0, 0, last])
    }

    #[test]
    fn the_oldest_node_of_the_busiest_source_goes_first() {
        let t = Instant::now();
        let mut sources = Sources::default();
        for n in 0..100u64 {
            sources.add(ip(66), 1000 + n, t + Duration::from_millis(n), 600);
        }
        sources.add(ip(1), 1, t, 5000);
        assert_eq!(sources.total(), 100 * 600 + 5000);
        // The genuine node is older and bigger per node, but its source is smaller.
        assert_eq!(sources.victim(Some(1)), Some(1000));
        assert_eq!(sources.victim(None), Some(1000));
        sources.heard(ip(66), 1000, t, t + Duration::from_secs(1));
        assert_eq!(sources.victim(None), Some(1001));
    }

    #[test]
    fn a_source_holding_only_the_newcomer_evicts_nobody() {
        let t = Instant::now();
        let mut sources = Sources::default();
        sources.add(ip(66), 7, t, 90_000);
        sources.add(ip(1), 1, t, 500);
        assert_eq!(sources.victim(Some(7)), None);
        sources.remove(ip(66), 7, t, 90_000);
        assert_eq!(sources.victim(Some(7)), Some(1));
        assert_eq!(sources.total(), 500);
    }

    #[test]
    fn recharging_moves_a_source_in_the_ranking() {
        let t = Instant::now();
        let mut sources = Sources::default();
        sources.add(ip(1), 1, t, 100);
        sources.add(ip(2), 2, t, 200);
        assert_eq!(sources.victim(None), Some(2));
        sources.recharge(ip(1), 100, 1000);
        assert_eq!(sources.victim(None), Some(1));
        assert_eq!(sources.bytes_of(ip(1)), 1000);
        assert_eq!(sources.total(), 1200);
    }
}

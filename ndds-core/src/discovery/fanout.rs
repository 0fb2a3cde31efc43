//! Where the engine's domain-wide datagrams go.
//!
//! Every datagram the engine addresses to the whole domain (periodic and incremental
//! announcements, withdrawals, `Bye`, `Solicit`) goes
//! - to the multicast group, unless multicast is off ([`DiscoveryConfig::multicast`]);
//! - by unicast to every configured peer ([`DiscoveryConfig::peers`]), even one that is also
//!   heard by multicast: explicit configuration wins, and the receiver takes the second copy as
//!   an ordinary refresh;
//! - by unicast to every known node that has not been heard by multicast for half of this
//!   node's lease (see [`unicast_window`]), provided the node's datagrams come from the
//!   locator it announces. So a node that reaches us only by unicast (it lists us as a peer
//!   but we do not list it, or its multicast does not reach us) still gets our refreshes and
//!   withdrawals, and two nodes whose multicast stops working while unicast still does keep
//!   each other.
//!
//! Each destination gets one copy; a node that is both a peer and known is not sent twice.
//! Unicast replies to a `Solicit` or a new node are not domain-wide and follow their own rule
//! (see the engine).

use std::time::{Duration, Instant};

use super::config::DiscoveryConfig;
use super::event::Destination;
use crate::wire::Locator;

/// How a datagram reached this node. The driver knows it from the socket that received it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Via {
    /// Through the domain's multicast group.
    Multicast,
    /// Addressed to this node's unicast locator.
    Unicast,
}

/// How long a known node may go unheard by multicast before it gets unicast copies of our
/// domain-wide datagrams: half of our own lease.
///
/// Half, not a whole lease: when multicast between two nodes breaks both ways, each must start
/// sending unicast copies before the other forgets it, that is within one lease of the last
/// multicast datagram that got through, less the wait for the next periodic announcement.
pub fn unicast_window(config: &DiscoveryConfig) -> Duration {
    config.lease / 2
}

/// The fixed part of the fan-out: multicast or not, and the configured peers.
#[derive(Clone, Debug)]
pub(crate) struct Fanout {
    multicast: bool,
    /// Sorted, without duplicates or our own locator.
    peers: Vec<Locator>,
    window: Duration,
}

impl Fanout {
    pub(crate) fn new(config: &DiscoveryConfig) -> Self {
        let mut peers: Vec<Locator> = config
            .peers
            .iter()
            .copied()
            .filter(|peer| *peer != config.unicast)
            .collect();
        peers.sort();
        peers.dedup();
        Fanout {
            multicast: config.multicast,
            peers,
            window: unicast_window(config),
        }
    }

    /// The configured peers in use (sorted, without duplicates or this node).
    pub(crate) fn peers(&self) -> &[Locator] {
        &self.peers
    }

    /// Whether a node last heard by multicast at `last_multicast` needs unicast copies at `now`.
    pub(crate) fn multicast_stale(&self, last_multicast: Option<Instant>, now: Instant) -> bool {
        last_multicast.is_none_or(|at| now.saturating_duration_since(at) >= self.window)
    }

    /// Every destination of a domain-wide datagram: the group (if on), the peers, then the
    /// `known` nodes' locators that are not peers already.
    pub(crate) fn destinations(
        &self,
        known: impl IntoIterator<Item = Locator>,
    ) -> Vec<Destination> {
        let mut extra: Vec<Locator> = known
            .into_iter()
            .filter(|l| self.peers.binary_search(l).is_err())
            .collect();
        extra.sort();
        extra.dedup();
        let group = self.multicast.then_some(Destination::Multicast);
        group
            .into_iter()
            .chain(self.peers.iter().copied().map(Destination::Unicast))
            .chain(extra.into_iter().map(Destination::Unicast))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loc(host: u8, port: u16) -> Locator {
        Locator {
            addr: [10, 0, 0, host],
            port,
        }
    }

    #[test]
    fn peers_are_deduplicated_and_never_include_this_node() {
        let mut config = DiscoveryConfig::new(0, loc(1, 7850));
        config.peers = vec![loc(3, 7850), loc(1, 7850), loc(2, 7850), loc(3, 7850)];
        let fanout = Fanout::new(&config);
        assert_eq!(fanout.peers(), &[loc(2, 7850), loc(3, 7850)]);
        let to = fanout.destinations([loc(3, 7850), loc(4, 9), loc(4, 9)]);
        assert_eq!(
            to,
            vec![
                Destination::Multicast,
                Destination::Unicast(loc(2, 7850)),
                Destination::Unicast(loc(3, 7850)),
                Destination::Unicast(loc(4, 9)),
            ]
        );
        config.multicast = false;
        let to = Fanout::new(&config).destinations([]);
        assert!(!to.contains(&Destination::Multicast));
        assert_eq!(to.len(), 2);
    }

    #[test]
    fn a_node_is_stale_after_half_a_lease_without_multicast() {
        let config = DiscoveryConfig::new(0, loc(1, 7850));
        let fanout = Fanout::new(&config);
        let now = Instant::now();
        let half = config.lease / 2;
        assert!(fanout.multicast_stale(None, now));
        assert!(!fanout.multicast_stale(Some(now), now + half - Duration::from_millis(1)));
        assert!(fanout.multicast_stale(Some(now), now + half));
    }
}

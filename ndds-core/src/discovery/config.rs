//! Configuration of the discovery engine.

use std::time::Duration;

use crate::wire::Locator;

/// Settings of one discovery engine. [`DiscoveryConfig::new`] gives the documented defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct DiscoveryConfig {
    /// Domain id carried in every header; datagrams of other domains are dropped.
    pub domain: u16,
    /// Seed of the engine's random numbers (node id unless `node_id` is set, jitter). Same
    /// seed, same run.
    pub seed: u64,
    /// This node's id; drawn from `seed` when `None`. Every node of a domain needs its own.
    pub node_id: Option<u64>,
    /// The key of this node's address-probe tokens: random in a daemon (from the operating
    /// system); `None` derives it from `seed` and the node id, which is predictable (tests).
    pub probe_secret: Option<[u8; 32]>,
    /// Host name announced to other nodes.
    pub hostname: String,
    /// Process id announced to other nodes.
    pub pid: u32,
    /// Unicast address where this node receives discovery datagrams.
    pub unicast: Locator,
    /// Software version announced to other nodes.
    pub version: String,
    /// Period of the full refresh announcement (default 1 s).
    pub announce_period: Duration,
    /// How long others keep our entries without a refresh (default 5 s). Must exceed the
    /// announce period; a few periods make single losses harmless.
    pub lease: Duration,
    /// Delays after start at which `Solicit` is sent (default 0, 200 ms, 1 s).
    pub solicit_delays: Vec<Duration>,
    /// Upper bound of the random delay before answering a `Solicit` (default 10 ms), so that
    /// many nodes do not answer a newcomer in the same instant.
    pub reply_jitter: Duration,
    /// Relative jitter applied to each refresh period (default 0.1 = ±10 %).
    pub period_jitter: f64,
    /// How many periodic announcements repeat a withdrawal (default 3).
    pub withdraw_repeats: u8,
    /// Target size of one announcement datagram; larger announcements are split (default 16 KiB).
    pub announce_chunk: usize,
    /// Declarations that follow an announced one within this time are held and announced
    /// together when it has passed (default 5 ms; zero announces each at once). A single
    /// declaration goes out at once; a burst (a program declaring its endpoints one by one)
    /// costs a datagram per window instead of one per endpoint, and in a domain with
    /// permissions a signature per window.
    pub declare_coalesce: Duration,
    /// Whether to use the domain's multicast group (default true). When false the engine never
    /// produces a [`Destination::Multicast`](super::Destination::Multicast) transmit: discovery
    /// then relies on `peers` and on the nodes that list this one as their peer.
    pub multicast: bool,
    /// Unicast discovery locators of static peers (default none, at most [`MAX_PEERS`]). Every
    /// datagram the engine would multicast is also sent to each of them, multicast on or off.
    /// Duplicates and this node's own locator are ignored.
    pub peers: Vec<Locator>,
}

/// Most static peers a node may list.
pub const MAX_PEERS: usize = 256;

impl DiscoveryConfig {
    /// Defaults for a node of `domain` receiving unicast at `unicast`.
    pub fn new(domain: u16, unicast: Locator) -> Self {
        DiscoveryConfig {
            domain,
            seed: 0,
            probe_secret: None,
            node_id: None,
            hostname: String::new(),
            pid: 0,
            unicast,
            version: String::new(),
            announce_period: Duration::from_secs(1),
            lease: Duration::from_secs(5),
            solicit_delays: vec![
                Duration::ZERO,
                Duration::from_millis(200),
                Duration::from_secs(1),
            ],
            reply_jitter: Duration::from_millis(10),
            period_jitter: 0.1,
            withdraw_repeats: 3,
            announce_chunk: 16 * 1024,
            declare_coalesce: Duration::from_millis(5),
            multicast: true,
            peers: Vec::new(),
        }
    }

    /// Checks the relations between timers.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.announce_period.is_zero() {
            return Err(ConfigError::ZeroPeriod);
        }
        if self.lease <= self.announce_period {
            return Err(ConfigError::LeaseTooShort {
                lease: self.lease,
                period: self.announce_period,
            });
        }
        if !(0.0..0.5).contains(&self.period_jitter) {
            return Err(ConfigError::Jitter(self.period_jitter));
        }
        if self.lease > super::engine::MAX_LEASE {
            return Err(ConfigError::LeaseTooLong(self.lease));
        }
        if !self.solicit_delays.is_sorted() || self.solicit_delays.iter().any(|d| *d > MAX_DELAY) {
            return Err(ConfigError::SolicitDelays);
        }
        if self.reply_jitter > MAX_DELAY {
            return Err(ConfigError::ReplyJitter(self.reply_jitter));
        }
        if self.declare_coalesce >= self.announce_period {
            return Err(ConfigError::Coalesce {
                coalesce: self.declare_coalesce,
                period: self.announce_period,
            });
        }
        if !(MIN_CHUNK..=MAX_CHUNK).contains(&self.announce_chunk) {
            return Err(ConfigError::Chunk(self.announce_chunk));
        }
        if self.peers.len() > MAX_PEERS {
            return Err(ConfigError::TooManyPeers(self.peers.len()));
        }
        if let Some(peer) = self.peers.iter().find(|p| !is_unicast(p)) {
            return Err(ConfigError::Peer(*peer));
        }
        Ok(())
    }
}

/// Whether `locator` can receive unicast: a host address (not `0.0.0.0`, multicast or
/// broadcast) and a port other than 0.
pub fn is_unicast(locator: &Locator) -> bool {
    let addr = std::net::Ipv4Addr::from(locator.addr);
    !(addr.is_unspecified() || addr.is_multicast() || addr.is_broadcast() || locator.port == 0)
}

/// Longest solicit delay or reply jitter accepted.
const MAX_DELAY: Duration = Duration::from_secs(60);
/// Smallest announcement chunk accepted.
const MIN_CHUNK: usize = 512;
/// Largest announcement chunk accepted (leaves room for the header and node info).
const MAX_CHUNK: usize = crate::wire::MAX_DATAGRAM - 4096;

/// An inconsistent [`DiscoveryConfig`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ConfigError {
    /// The announce period is zero.
    #[error("announce period must be greater than zero")]
    ZeroPeriod,
    /// The lease does not exceed the announce period.
    #[error("lease ({lease:?}) must be longer than the announce period ({period:?})")]
    LeaseTooShort {
        /// Configured lease.
        lease: Duration,
        /// Configured period.
        period: Duration,
    },
    /// The lease is longer than other nodes accept (`MAX_LEASE`, 60 s).
    #[error("lease {0:?} is too long (at most 60 s)")]
    LeaseTooLong(Duration),
    /// Jitter outside `0.0..0.5`.
    #[error("period jitter {0} must be in 0.0..0.5")]
    Jitter(f64),
    /// Solicit delays not ascending, or longer than a minute.
    #[error("solicit delays must be ascending and at most 60 s each")]
    SolicitDelays,
    /// Reply jitter longer than a minute.
    #[error("reply jitter {0:?} is longer than 60 s")]
    ReplyJitter(Duration),
    /// Declarations held longer than a refresh period.
    #[error(
        "declarations may be held ({coalesce:?}) only for less than the announce period \
         ({period:?})"
    )]
    Coalesce {
        /// Configured hold.
        coalesce: Duration,
        /// Configured period.
        period: Duration,
    },
    /// Announcement chunk size out of range.
    #[error("announcement chunk of {0} bytes is outside {MIN_CHUNK}..={MAX_CHUNK}")]
    Chunk(usize),
    /// More than [`MAX_PEERS`] peers.
    #[error("{0} peers listed; at most {MAX_PEERS} are accepted")]
    TooManyPeers(usize),
    /// A peer locator that cannot receive unicast.
    #[error(
        "peer {0} is not a unicast address: expected a host address (not 0.0.0.0, multicast or \
         broadcast) and a port other than 0"
    )]
    Peer(Locator),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loc(addr: [u8; 4], port: u16) -> Locator {
        Locator { addr, port }
    }

    #[test]
    fn peers_are_bounded_and_must_be_unicast() {
        let mut config = DiscoveryConfig::new(0, loc([10, 0, 0, 1], 7850));
        config.peers = (0..MAX_PEERS)
            .map(|i| loc([10, 1, (i / 256) as u8, i as u8], 7850))
            .collect();
        assert_eq!(config.validate(), Ok(()));
        config.peers.push(loc([10, 2, 0, 1], 7850));
        let err = config.validate().unwrap_err();
        assert_eq!(err, ConfigError::TooManyPeers(MAX_PEERS + 1));
        assert!(err.to_string().contains("at most 256"), "{err}");

        for bad in [
            loc([0, 0, 0, 0], 7850),
            loc([239, 255, 76, 0], 7850),
            loc([255, 255, 255, 255], 7850),
            loc([10, 0, 0, 2], 0),
        ] {
            config.peers = vec![bad];
            let err = config.validate().unwrap_err();
            assert_eq!(err, ConfigError::Peer(bad));
            assert!(err.to_string().contains(&bad.to_string()), "{err}");
        }
    }

    #[test]
    fn declarations_are_held_for_less_than_a_period() {
        let mut config = DiscoveryConfig::new(0, loc([10, 0, 0, 1], 7850));
        config.declare_coalesce = Duration::ZERO;
        assert_eq!(config.validate(), Ok(()));
        config.declare_coalesce = config.announce_period;
        let err = config.validate().unwrap_err();
        assert!(matches!(err, ConfigError::Coalesce { .. }), "{err}");
        assert!(
            err.to_string().contains("less than the announce period"),
            "{err}"
        );
    }

    #[test]
    fn multicast_off_without_peers_is_valid() {
        // Such a node is found by the nodes that list it, and answers them.
        let mut config = DiscoveryConfig::new(0, loc([10, 0, 0, 1], 7850));
        config.multicast = false;
        assert_eq!(config.validate(), Ok(()));
    }
}

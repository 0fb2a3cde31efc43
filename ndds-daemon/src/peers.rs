//! Static unicast peers: how they are written, checked and resolved.
//!
//! A peer is written `HOST` or `HOST:PORT`, where `HOST` is an IPv4 address or a host name and
//! `PORT` defaults to the domain's unicast discovery port (`7850 + domain`, see
//! [`ndds_core::domain::unicast_port`]). Host names are resolved once, when the daemon starts,
//! to their first IPv4 address; a name that does not resolve stops the start with an error
//! naming the peer.

use std::fmt;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::str::FromStr;
use std::time::Duration;

use ndds_core::discovery::config::is_unicast;
use ndds_core::domain;
use ndds_core::wire::Locator;
use serde::Deserialize;

/// How long the name resolution of all peers may take at start.
const RESOLVE_TIMEOUT: Duration = Duration::from_secs(10);

/// A peer as written in `--peers` or the config file's `peers`.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Deserialize)]
#[serde(try_from = "String")]
pub struct PeerSpec {
    /// Host name or IPv4 address.
    pub host: String,
    /// UDP port; `None` means the domain's unicast discovery port.
    pub port: Option<u16>,
}

/// A peer that cannot be parsed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "invalid peer {text:?}: {problem}; expected HOST or HOST:PORT (IPv4 address or host name, port 1-65535)"
)]
pub struct PeerSpecError {
    /// The text as given.
    pub text: String,
    /// What is wrong with it.
    pub problem: &'static str,
}

impl FromStr for PeerSpec {
    type Err = PeerSpecError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let fail = |problem| PeerSpecError {
            text: text.to_owned(),
            problem,
        };
        let trimmed = text.trim();
        let (host, port) = match trimmed.rsplit_once(':') {
            Some((host, port)) => {
                let port = port
                    .parse::<u16>()
                    .map_err(|_| fail("the port is not a number from 1 to 65535"))?;
                if port == 0 {
                    return Err(fail("port 0 cannot be a peer's port"));
                }
                (host, Some(port))
            }
            None => (trimmed, None),
        };
        if host.is_empty() {
            return Err(fail("the host is empty"));
        }
        if host.contains(':') {
            return Err(fail("IPv6 addresses are not supported"));
        }
        if host.chars().any(char::is_whitespace) {
            return Err(fail("the host contains white space"));
        }
        Ok(PeerSpec {
            host: host.to_owned(),
            port,
        })
    }
}

impl TryFrom<String> for PeerSpec {
    type Error = PeerSpecError;

    fn try_from(text: String) -> Result<Self, Self::Error> {
        text.parse()
    }
}

impl fmt::Display for PeerSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.port {
            Some(port) => write!(f, "{}:{port}", self.host),
            None => f.write_str(&self.host),
        }
    }
}

/// A peer resolved at start.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Peer {
    /// As configured.
    pub spec: PeerSpec,
    /// Its unicast discovery locator.
    pub locator: Locator,
}

/// A peer that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum PeerError {
    /// The host name did not resolve.
    #[error(
        "cannot resolve peer {peer}: {source}; expected a host name with an IPv4 address, or an IPv4 address"
    )]
    Resolve {
        /// The peer as configured.
        peer: PeerSpec,
        /// The resolver's error.
        source: std::io::Error,
    },
    /// The host name resolved, but to IPv6 addresses only.
    #[error("peer {peer} has no IPv4 address (discovery is IPv4 only)")]
    NoIpv4 {
        /// The peer as configured.
        peer: PeerSpec,
    },
    /// The address cannot receive unicast.
    #[error(
        "peer {peer} is {addr}, which is not a unicast host address (0.0.0.0, multicast and broadcast cannot be peers)"
    )]
    NotUnicast {
        /// The peer as configured.
        peer: PeerSpec,
        /// What it resolved to.
        addr: SocketAddrV4,
    },
    /// Resolution took longer than allowed.
    #[error(
        "resolving the peers took longer than {RESOLVE_TIMEOUT:?}; list IPv4 addresses, or fix the resolver"
    )]
    Timeout,
}

/// Resolves every peer of `domain` (concurrently, within a time limit). Must be called inside a
/// tokio runtime.
pub async fn resolve(specs: &[PeerSpec], domain: u16) -> Result<Vec<Peer>, PeerError> {
    let lookups = specs.iter().map(|spec| resolve_one(spec, domain));
    let all = tokio::time::timeout(RESOLVE_TIMEOUT, futures_util::future::join_all(lookups))
        .await
        .map_err(|_| PeerError::Timeout)?;
    all.into_iter().collect()
}

async fn resolve_one(spec: &PeerSpec, domain: u16) -> Result<Peer, PeerError> {
    let port = spec.port.unwrap_or_else(|| domain::unicast_port(domain));
    let addr = match spec.host.parse::<Ipv4Addr>() {
        Ok(ip) => SocketAddrV4::new(ip, port),
        Err(_) => {
            let mut found = tokio::net::lookup_host((spec.host.as_str(), port))
                .await
                .map_err(|source| PeerError::Resolve {
                    peer: spec.clone(),
                    source,
                })?;
            found
                .find_map(|addr| match addr {
                    SocketAddr::V4(v4) => Some(v4),
                    SocketAddr::V6(_) => None,
                })
                .ok_or_else(|| PeerError::NoIpv4 { peer: spec.clone() })?
        }
    };
    let locator = Locator::from(addr);
    if !is_unicast(&locator) {
        return Err(PeerError::NotUnicast {
            peer: spec.clone(),
            addr,
        });
    }
    Ok(Peer {
        spec: spec.clone(),
        locator,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(text: &str) -> PeerSpec {
        text.parse().unwrap()
    }

    #[test]
    fn peers_parse_with_and_without_port() {
        assert_eq!(
            spec("10.0.0.2:7900"),
            PeerSpec {
                host: "10.0.0.2".into(),
                port: Some(7900)
            }
        );
        assert_eq!(spec(" robot-7 ").port, None);
        assert_eq!(spec("robot-7").to_string(), "robot-7");
        assert_eq!(spec("robot-7:1").to_string(), "robot-7:1");
        for (bad, problem) in [
            ("", "empty"),
            (":7850", "empty"),
            ("a:b", "not a number"),
            ("a:70000", "not a number"),
            ("a:0", "port 0"),
            ("fe80::1", "IPv6"),
            ("a b", "white space"),
        ] {
            let err = bad.parse::<PeerSpec>().unwrap_err().to_string();
            assert!(
                err.contains(problem) && err.contains("HOST:PORT"),
                "{bad}: {err}"
            );
        }
    }

    #[tokio::test]
    async fn a_missing_port_is_the_domain_default_and_names_resolve() {
        let peers = resolve(&[spec("127.0.0.1"), spec("localhost:9000")], 5)
            .await
            .unwrap();
        assert_eq!(peers[0].locator.to_string(), "127.0.0.1:7855");
        assert_eq!(peers[1].locator.to_string(), "127.0.0.1:9000");
        assert_eq!(peers[1].spec.to_string(), "localhost:9000");
    }

    #[tokio::test]
    async fn unusable_peers_are_refused_by_name() {
        let err = resolve(&[spec("no-such-host.invalid")], 0)
            .await
            .unwrap_err();
        assert!(matches!(err, PeerError::Resolve { .. }), "{err}");
        assert!(err.to_string().contains("no-such-host.invalid"), "{err}");
        let err = resolve(&[spec("239.255.76.1")], 0).await.unwrap_err();
        assert!(err.to_string().contains("239.255.76.1"), "{err}");
        assert!(matches!(err, PeerError::NotUnicast { .. }), "{err}");
    }
}

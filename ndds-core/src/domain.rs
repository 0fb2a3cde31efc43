//! How a domain id maps to discovery addresses and the local socket's name.
//!
//! | what | value for domain `d` (0 ≤ d ≤ 232) |
//! |---|---|
//! | discovery multicast group | `239.255.76.d` |
//! | discovery UDP port (multicast) | `7600 + d` |
//! | unicast discovery port | `7850 + d` |
//! | daemon Unix socket name | `ndds-d.sock` (in the directory `ndds_daemon::local` picks) |
//!
//! Every value can be overridden (daemon flags and config file, `NDDS_SOCKET`); these are only
//! the defaults that let daemons and clients of one domain find each other with no set-up.
//! The unicast port is fixed so that a static peer list can name a peer by its host alone
//! (`--peers host`); a daemon that finds it taken (several daemons of one domain on one host)
//! falls back to any free port, and peers then learn that port from its announcements.

use std::net::Ipv4Addr;

/// Largest valid domain id.
pub const MAX_DOMAIN: u16 = 232;
/// Discovery port of domain 0; domain `d` uses `BASE_PORT + d`.
pub const BASE_PORT: u16 = 7600;

/// Unicast discovery port of domain 0; domain `d` uses `UNICAST_BASE_PORT + d`. The range
/// (7850 to 8082) does not overlap the multicast ports (7600 to 7832).
pub const UNICAST_BASE_PORT: u16 = 7850;

/// A domain id outside `0..=MAX_DOMAIN`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("domain id {0} is out of range (0..={MAX_DOMAIN})")]
pub struct DomainError(pub u32);

/// Checks that `domain` is a valid domain id.
pub fn check(domain: u32) -> Result<u16, DomainError> {
    u16::try_from(domain)
        .ok()
        .filter(|d| *d <= MAX_DOMAIN)
        .ok_or(DomainError(domain))
}

/// The discovery multicast group of a domain.
pub fn multicast_group(domain: u16) -> Ipv4Addr {
    Ipv4Addr::new(239, 255, 76, domain.min(MAX_DOMAIN) as u8)
}

/// The discovery UDP port of a domain.
pub fn discovery_port(domain: u16) -> u16 {
    BASE_PORT + domain.min(MAX_DOMAIN)
}

/// The default unicast discovery port of a domain: where a daemon receives unicast discovery
/// datagrams, and the port a peer named without one is assumed to use.
pub fn unicast_port(domain: u16) -> u16 {
    UNICAST_BASE_PORT + domain.min(MAX_DOMAIN)
}

/// The file name of a domain's daemon socket. Which directory holds it (the user's runtime
/// directory, `/run/ndds`, or a private one) is the drivers' choice, as it depends on who runs
/// them.
pub fn socket_name(domain: u16) -> String {
    format!("ndds-{}.sock", domain.min(MAX_DOMAIN))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mapping_matches_the_documented_table() {
        assert_eq!(multicast_group(0), Ipv4Addr::new(239, 255, 76, 0));
        assert_eq!(multicast_group(232), Ipv4Addr::new(239, 255, 76, 232));
        assert_eq!(discovery_port(0), 7600);
        assert_eq!(discovery_port(17), 7617);
        assert_eq!(unicast_port(0), 7850);
        assert_eq!(unicast_port(232), 8082);
        assert!(discovery_port(MAX_DOMAIN) < unicast_port(0));
        assert_eq!(socket_name(3), "ndds-3.sock");
        assert_eq!(check(232), Ok(232));
        assert_eq!(check(233), Err(DomainError(233)));
        assert_eq!(check(70_000), Err(DomainError(70_000)));
    }
}

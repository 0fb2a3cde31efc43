//! Choosing the network interface: an IPv4 address or an interface name, checked against the
//! addresses this host actually has, so a typo fails at start with the list of choices instead
//! of a daemon that silently hears nothing.

use std::net::Ipv4Addr;

/// The interface could not be resolved.
#[derive(Debug, thiserror::Error)]
pub enum InterfaceError {
    /// Listing the host's interfaces failed.
    #[error("cannot list network interfaces: {0}")]
    List(#[from] std::io::Error),
    /// No interface has this name or address.
    #[error("no IPv4 interface matches {spec:?}; available: {available}")]
    NotFound {
        /// What was asked for.
        spec: String,
        /// `name address` pairs of the host's IPv4 interfaces.
        available: String,
    },
    /// `0.0.0.0` or a multicast address was given.
    #[error("{0} cannot be used as an interface: name one address of this host")]
    Unusable(Ipv4Addr),
}

/// Resolves `spec` (an IPv4 address of this host, or an interface name such as `eth0` or
/// `lo`) to the IPv4 address to bind.
pub fn resolve(spec: &str) -> Result<Ipv4Addr, InterfaceError> {
    let spec = spec.trim();
    if let Ok(addr) = spec.parse::<Ipv4Addr>() {
        if addr.is_unspecified() || addr.is_multicast() || addr.is_broadcast() {
            return Err(InterfaceError::Unusable(addr));
        }
        // Loopback needs no lookup: it exists in every network namespace.
        if addr.is_loopback() {
            return Ok(addr);
        }
    }
    let interfaces = host_ipv4()?;
    interfaces
        .iter()
        .find(|(name, addr)| name == spec || addr.to_string() == spec)
        .map(|(_, addr)| *addr)
        .ok_or_else(|| InterfaceError::NotFound {
            spec: spec.to_owned(),
            available: interfaces
                .iter()
                .map(|(name, addr)| format!("{name} {addr}"))
                .collect::<Vec<_>>()
                .join(", "),
        })
}

/// The host's IPv4 interfaces as `(name, address)`.
pub fn host_ipv4() -> Result<Vec<(String, Ipv4Addr)>, InterfaceError> {
    Ok(if_addrs::get_if_addrs()?
        .into_iter()
        .filter_map(|iface| match iface.addr {
            if_addrs::IfAddr::V4(v4) => Some((iface.name, v4.ip)),
            if_addrs::IfAddr::V6(_) => None,
        })
        .collect())
}

/// The name of the interface that has `addr`, if any (for logs and `ndds nodes`).
pub fn name_of(addr: Ipv4Addr) -> Option<String> {
    host_ipv4()
        .ok()?
        .into_iter()
        .find(|(_, a)| *a == addr)
        .map(|(name, _)| name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_by_address_and_name() {
        assert_eq!(resolve("127.0.0.1").unwrap(), Ipv4Addr::LOCALHOST);
        assert_eq!(resolve("lo").unwrap(), Ipv4Addr::LOCALHOST);
    }

    #[test]
    fn unknown_and_unusable_interfaces_are_refused_with_choices() {
        let err = resolve("no-such-nic0").unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("no-such-nic0") && text.contains("lo 127.0.0.1"),
            "{text}"
        );
        assert!(matches!(
            resolve("0.0.0.0"),
            Err(InterfaceError::Unusable(_))
        ));
        assert!(matches!(
            resolve("203.0.113.77"),
            Err(InterfaceError::NotFound { .. })
        ));
    }
}

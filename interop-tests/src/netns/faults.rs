//! Network faults of one host, as an nftables table in the host's namespace.
//!
//! Everything is filtered on the way *in*, at the receiver, and only what arrives through the
//! host's link to the bridge from another address: traffic inside the host (loopback, and its
//! own multicast echo, which the kernel loops back as if it had arrived on the link) is never
//! touched. The whole table is replaced in one nft transaction at each change, so a
//! host never runs with half a rule set.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::net::Ipv4Addr;

/// The nftables table (family `inet`) that holds a host's faults.
pub const TABLE: &str = "ndds_faults";

/// The faults in force on one host.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Faults {
    /// Share of incoming UDP datagrams dropped, in percent (0: none).
    pub loss_percent: u8,
    /// Hosts whose packets are dropped (one side of a partition).
    pub blocked: BTreeSet<Ipv4Addr>,
}

impl Faults {
    /// True when nothing is dropped.
    pub fn is_empty(&self) -> bool {
        self.loss_percent == 0 && self.blocked.is_empty()
    }

    /// The nft script that replaces the host's fault table with these faults (or removes it
    /// when there are none). `link` is the host's interface to the bridge, `own` its address.
    pub fn script(&self, link: &str, own: Ipv4Addr) -> String {
        // Adding then deleting the table makes the deletion valid whether or not it existed.
        let mut script = format!("add table inet {TABLE}\ndelete table inet {TABLE}\n");
        if self.is_empty() {
            return script;
        }
        let _ = writeln!(script, "table inet {TABLE} {{");
        script.push_str(
            "  chain input {\n    type filter hook input priority filter; policy accept;\n",
        );
        if !self.blocked.is_empty() {
            let peers: Vec<String> = self.blocked.iter().map(Ipv4Addr::to_string).collect();
            let _ = writeln!(
                script,
                "    iifname \"{link}\" ip saddr {{ {} }} counter drop",
                peers.join(", ")
            );
        }
        if self.loss_percent > 0 {
            let _ = writeln!(
                script,
                "    iifname \"{link}\" ip saddr != {own} meta l4proto udp numgen random mod 100 < {} \
                 counter drop",
                self.loss_percent.min(100)
            );
        }
        script.push_str("  }\n}\n");
        script
    }
}

/// The packets dropped so far, summed over the counters of a listing of the fault table
/// (`nft list table`). Counters restart whenever the table is replaced.
pub fn dropped(listing: &str) -> u64 {
    listing
        .split_whitespace()
        .collect::<Vec<_>>()
        .windows(3)
        .filter(|w| w[0] == "counter" && w[1] == "packets")
        .filter_map(|w| w[2].parse::<u64>().ok())
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_faults_only_removes_the_table() {
        let script = Faults::default().script("veth0", Ipv4Addr::new(10, 1, 2, 9));
        assert_eq!(
            script,
            "add table inet ndds_faults\ndelete table inet ndds_faults\n"
        );
    }

    #[test]
    fn loss_and_partition_drop_on_the_bridge_link_only() {
        let faults = Faults {
            loss_percent: 30,
            blocked: [Ipv4Addr::new(10, 1, 2, 3), Ipv4Addr::new(10, 1, 2, 1)].into(),
        };
        let script = faults.script("veth0", Ipv4Addr::new(10, 1, 2, 9));
        assert!(script.contains("iifname \"veth0\" ip saddr { 10.1.2.1, 10.1.2.3 } counter drop"));
        assert!(script.contains(
            "iifname \"veth0\" ip saddr != 10.1.2.9 meta l4proto udp numgen random mod 100 < 30 \
             counter drop"
        ));
        assert!(script.contains("hook input"));
    }

    #[test]
    fn dropped_packets_sum_the_counters() {
        let listing = "table inet ndds_faults {\n chain input {\n  iifname \"veth0\" ip saddr \
                       10.1.2.1 counter packets 7 bytes 700 drop\n  iifname \"veth0\" meta \
                       l4proto udp numgen random mod 100 < 30 counter packets 35 bytes 9 drop\n }\n}";
        assert_eq!(dropped(listing), 42);
        assert_eq!(dropped(""), 0);
    }
}

//! UDP traffic through a host's link to the bridge, counted by an nftables table of its own
//! in the host's namespace (apart from the fault table, which is replaced at every change).
//!
//! The counters sit on the `input` and `output` hooks, where IP fragments are still (input:
//! already) whole datagrams: they count datagrams and their IP lengths, not link frames. The
//! host's own multicast, which the kernel loops back as if it had arrived on the link, is not
//! counted as input.

use std::net::Ipv4Addr;
use std::ops::Sub;

/// The nftables table (family `inet`) that holds a host's traffic counters.
pub const METER_TABLE: &str = "ndds_meter";

/// UDP datagrams and bytes (IP length) through one host's link, each way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Datagrams received from the bridge.
    pub in_packets: u64,
    /// Their bytes.
    pub in_bytes: u64,
    /// Datagrams sent to the bridge.
    pub out_packets: u64,
    /// Their bytes.
    pub out_bytes: u64,
}

impl Sub for Traffic {
    type Output = Traffic;

    /// The traffic between two readings (`later - earlier`).
    fn sub(self, earlier: Traffic) -> Traffic {
        Traffic {
            in_packets: self.in_packets.saturating_sub(earlier.in_packets),
            in_bytes: self.in_bytes.saturating_sub(earlier.in_bytes),
            out_packets: self.out_packets.saturating_sub(earlier.out_packets),
            out_bytes: self.out_bytes.saturating_sub(earlier.out_bytes),
        }
    }
}

/// The nft script that (re)creates the meter table with zeroed counters. `link` is the host's
/// interface to the bridge, `own` its address.
pub fn script(link: &str, own: Ipv4Addr) -> String {
    format!(
        "add table inet {METER_TABLE}\ndelete table inet {METER_TABLE}\n\
         table inet {METER_TABLE} {{\n\
         \x20 counter udp_in {{ }}\n\
         \x20 counter udp_out {{ }}\n\
         \x20 chain input {{\n\
         \x20   type filter hook input priority filter - 10; policy accept;\n\
         \x20   iifname \"{link}\" ip saddr != {own} meta l4proto udp counter name \"udp_in\"\n\
         \x20 }}\n\
         \x20 chain output {{\n\
         \x20   type filter hook output priority filter - 10; policy accept;\n\
         \x20   oifname \"{link}\" meta l4proto udp counter name \"udp_out\"\n\
         \x20 }}\n\
         }}\n"
    )
}

/// The counters of a listing of the meter table (`nft list counters table ...`); zero for a
/// counter the listing lacks.
pub fn parse(listing: &str) -> Traffic {
    let (in_packets, in_bytes) = counter(listing, "udp_in");
    let (out_packets, out_bytes) = counter(listing, "udp_out");
    Traffic {
        in_packets,
        in_bytes,
        out_packets,
        out_bytes,
    }
}

/// `packets N bytes M` of the named counter object.
fn counter(listing: &str, name: &str) -> (u64, u64) {
    let words: Vec<&str> = listing.split_whitespace().collect();
    let Some(start) = words
        .windows(2)
        .position(|w| w[0] == "counter" && w[1] == name)
    else {
        return (0, 0);
    };
    let after = &words[start..];
    let value = |key: &str| {
        after
            .windows(2)
            .find(|w| w[0] == key)
            .and_then(|w| w[1].parse().ok())
            .unwrap_or(0)
    };
    (value("packets"), value("bytes"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_script_counts_udp_on_the_link_both_ways() {
        let script = script("veth0", Ipv4Addr::new(10, 1, 2, 9));
        assert!(script.starts_with("add table inet ndds_meter\ndelete table inet ndds_meter\n"));
        assert!(script.contains(
            "iifname \"veth0\" ip saddr != 10.1.2.9 meta l4proto udp counter name \"udp_in\""
        ));
        assert!(script.contains("oifname \"veth0\" meta l4proto udp counter name \"udp_out\""));
        assert!(script.contains("hook input") && script.contains("hook output"));
    }

    #[test]
    fn counters_are_read_by_name() {
        let listing = "table inet ndds_meter {\n\tcounter udp_in {\n\t\tpackets 12 bytes 3400\n\t}\n\
                       \tcounter udp_out {\n\t\tpackets 5 bytes 900\n\t}\n}\n";
        let traffic = parse(listing);
        assert_eq!(
            traffic,
            Traffic {
                in_packets: 12,
                in_bytes: 3400,
                out_packets: 5,
                out_bytes: 900
            }
        );
        assert_eq!(parse(""), Traffic::default());
        let earlier = Traffic {
            in_packets: 2,
            in_bytes: 400,
            out_packets: 1,
            out_bytes: 100,
        };
        assert_eq!((traffic - earlier).in_packets, 10);
        assert_eq!((traffic - earlier).out_bytes, 800);
    }
}

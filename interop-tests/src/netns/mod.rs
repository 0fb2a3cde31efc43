//! Simulated hosts: network namespaces joined by a bridge, with faults injected by `nft`.
//!
//! A [`Network`] of N hosts is N+1 namespaces: a *switch* holding a bridge (multicast
//! snooping off, so discovery multicast floods to every port), and N *hosts*, each linked to
//! the bridge by a veth pair and given one address of a random private /24 (`10.x.y.0/24`).
//! Nothing is created in the machine's own namespace and nothing routes out of the network, so
//! no traffic can leave the machine. Names carry the test process's pid and a random tag:
//! parallel tests and runs never collide, and a run that was killed is cleaned up by the next
//! (see [`sweep_stale`]).
//!
//! Dropping the [`Network`] kills every process still inside its namespaces and deletes them,
//! also when the test panics.
//!
//! Faults act at the receivers, through an nftables table in each host's namespace:
//! [`Network::drop_incoming`] drops a share of a host's incoming UDP, [`Network::partition`]
//! drops everything between two groups of hosts, [`Network::heal`] ends partitions. Process
//! faults (kill -9, SIGSTOP, SIGCONT) are methods of the process handles.
//!
//! Needs root, `ip` (iproute2) and `nft` (nftables): [`Network::new`] panics with a message
//! naming what is missing.
//!
//! ```no_run
//! use interop_tests::netns::Cluster;
//!
//! let cluster = Cluster::new(3); // a daemon on each of three hosts
//! cluster.network().partition(&[0], &[1, 2]);
//! cluster.network().heal();
//! ```

mod cluster;
mod command;
mod faults;
mod host;
mod meter;
mod sweep;

use std::net::Ipv4Addr;
use std::sync::Mutex;

pub use cluster::Cluster;
pub use command::{locate, require};
pub use faults::{Faults, TABLE};
pub use host::Host;
pub use meter::{METER_TABLE, Traffic};
pub use sweep::{PREFIX, list, sweep_stale};

use command::{ip, ip_batch};

/// Name of each host's interface to the bridge.
pub const LINK: &str = "veth0";
/// Most hosts in one network (one /24, the bridge's port names).
pub const MAX_HOSTS: usize = 200;

/// Hosts on a bridge, each in its own network namespace. Torn down on drop.
#[derive(Debug)]
pub struct Network {
    tag: String,
    switch: String,
    subnet: [u8; 3],
    hosts: Vec<Host>,
    /// Every namespace created so far, deleted on drop (also after a failed set-up).
    created: Vec<String>,
}

impl Network {
    /// Creates `hosts` hosts on a new bridge. Panics with the failing command's error; what was
    /// already created is removed.
    pub fn new(hosts: usize) -> Network {
        assert!(
            (1..=MAX_HOSTS).contains(&hosts),
            "a network has 1 to {MAX_HOSTS} hosts"
        );
        require();
        sweep::sweep_once();
        let mut rng = fastrand::Rng::new();
        let tag = format!("{}{}-{:04x}", PREFIX, std::process::id(), rng.u16(..));
        let mut network = Network {
            switch: format!("{tag}-s"),
            tag,
            subnet: [10, rng.u8(..), rng.u8(..)],
            hosts: Vec::with_capacity(hosts),
            created: Vec::new(),
        };
        network
            .build(hosts)
            .unwrap_or_else(|err| panic!("cannot build the test network: {err}"));
        network
    }

    fn build(&mut self, hosts: usize) -> Result<(), String> {
        let names: Vec<String> = (0..hosts).map(|i| format!("{}-h{i}", self.tag)).collect();
        {
            // `ip netns add` sets up the shared mount of /var/run/netns on first use: keep
            // concurrent tests of this process from racing on it.
            static ADD: Mutex<()> = Mutex::new(());
            let _guard = ADD.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
            for name in std::iter::once(&self.switch).chain(&names) {
                self.created.push(name.clone());
                ip(&["netns", "add", name])?;
            }
        }
        let mut switch = vec![
            "link add br0 type bridge mcast_snooping 0".to_owned(),
            "link set br0 up".to_owned(),
        ];
        for (i, name) in names.iter().enumerate() {
            switch.push(format!(
                "link add p{i} type veth peer name {LINK} netns {name}"
            ));
            switch.push(format!("link set p{i} master br0 up"));
        }
        ip_batch(Some(&self.switch), &switch)?;
        for (i, name) in names.into_iter().enumerate() {
            let address = self.address(i);
            ip_batch(
                Some(&name),
                &[
                    "link set lo up".to_owned(),
                    format!("addr add {address}/24 dev {LINK}"),
                    format!("link set {LINK} up"),
                ],
            )?;
            self.hosts.push(Host::new(name, address));
        }
        Ok(())
    }

    fn address(&self, index: usize) -> Ipv4Addr {
        let [a, b, c] = self.subnet;
        Ipv4Addr::new(
            a,
            b,
            c,
            u8::try_from(index + 1).expect("at most MAX_HOSTS hosts"),
        )
    }

    /// Host `index` (0-based).
    pub fn host(&self, index: usize) -> &Host {
        &self.hosts[index]
    }

    /// Every host, in order.
    pub fn hosts(&self) -> &[Host] {
        &self.hosts
    }

    /// Names of every namespace of this network (the switch first).
    pub fn namespaces(&self) -> Vec<String> {
        self.created.clone()
    }

    /// Drops `percent` % of the UDP datagrams that reach host `index` from the bridge (0 ends
    /// the loss). Each datagram is dropped independently.
    pub fn drop_incoming(&self, index: usize, percent: u8) {
        assert!(percent <= 100, "a share in percent");
        self.host(index)
            .change_faults(|faults| faults.loss_percent = percent);
    }

    /// Cuts hosts `a` from hosts `b`, both ways: each host drops whatever comes from the other
    /// side. Hosts within one side still reach each other.
    pub fn partition(&self, a: &[usize], b: &[usize]) {
        assert!(
            a.iter().all(|i| !b.contains(i)),
            "a host cannot be on both sides of a partition"
        );
        let addresses =
            |side: &[usize]| -> Vec<Ipv4Addr> { side.iter().map(|&i| self.host(i).ip()).collect() };
        let (from_a, from_b) = (addresses(a), addresses(b));
        for &i in a {
            self.host(i).change_faults(|f| f.blocked.extend(&from_b));
        }
        for &i in b {
            self.host(i).change_faults(|f| f.blocked.extend(&from_a));
        }
    }

    /// Cuts host `index` from every other host.
    pub fn isolate(&self, index: usize) {
        let others: Vec<usize> = (0..self.hosts.len()).filter(|&i| i != index).collect();
        self.partition(&[index], &others);
    }

    /// Ends every partition (loss set by [`drop_incoming`](Self::drop_incoming) stays).
    pub fn heal(&self) {
        for host in &self.hosts {
            host.change_faults(|f| f.blocked.clear());
        }
    }
}

impl Drop for Network {
    fn drop(&mut self) {
        // Hosts first: their processes die before the bridge goes.
        for name in self.created.iter().rev() {
            sweep::remove(name);
        }
    }
}

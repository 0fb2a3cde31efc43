//! A [`Network`] with one `ndds-daemon` per host, all in one [`TestDomain`], and a tool
//! session with each daemon for reading its graph.

use std::path::PathBuf;
use std::time::Duration;

use ndds_client::{Graph, Participant};

use super::{Host, Network};
use crate::TestDomain;
use crate::process::{ClientProcess, DaemonProcess, Output};

/// Hosts with a daemon each. Fields drop in order: tool sessions, daemons, the domain's
/// directory, then the network (which kills anything still running in it).
#[derive(Debug)]
pub struct Cluster {
    tools: Vec<Participant>,
    daemons: Vec<DaemonProcess>,
    domain: TestDomain,
    network: Network,
}

impl Cluster {
    /// `hosts` hosts on a new network, a daemon on each (named `h0`, `h1`, ... in the
    /// domain), the test timers ([`PERIOD`](crate::PERIOD), [`LEASE`](crate::LEASE)).
    pub fn new(hosts: usize) -> Self {
        Self::start(Network::new(hosts))
    }

    /// A daemon on each host of `network` (which may already have faults in force), as
    /// [`new`](Self::new) does.
    pub fn start(network: Network) -> Self {
        Self::start_in(network, TestDomain::new())
    }

    /// A daemon on each host of `network` in `domain` (for example a sealed one:
    /// [`TestDomain::sealed`]; its clients then get the key too).
    pub fn start_in(network: Network, domain: TestDomain) -> Self {
        let daemons: Vec<DaemonProcess> = network
            .hosts()
            .iter()
            .enumerate()
            .map(|(i, host)| host.daemon(&domain, &Self::daemon_name(i)))
            .collect();
        let tools = network
            .hosts()
            .iter()
            .enumerate()
            .map(|(i, host)| host.tool(&domain.socket(&Self::daemon_name(i))))
            .collect();
        Cluster {
            tools,
            daemons,
            domain,
            network,
        }
    }

    /// The daemon name of host `index` in the domain (`h<index>`).
    pub fn daemon_name(index: usize) -> String {
        format!("h{index}")
    }

    /// The network, for faults.
    pub fn network(&self) -> &Network {
        &self.network
    }

    /// The domain the daemons share.
    pub fn domain(&self) -> &TestDomain {
        &self.domain
    }

    /// Host `index`.
    pub fn host(&self, index: usize) -> &Host {
        self.network.host(index)
    }

    /// Number of hosts.
    pub fn len(&self) -> usize {
        self.network.hosts().len()
    }

    /// Always false: a network has at least one host.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The socket of host `index`'s daemon.
    pub fn socket(&self, index: usize) -> PathBuf {
        self.domain.socket(&Self::daemon_name(index))
    }

    /// The daemon of host `index`.
    pub fn daemon(&self, index: usize) -> &DaemonProcess {
        &self.daemons[index]
    }

    /// The daemon of host `index`, for kill -9 and SIGTERM.
    pub fn daemon_mut(&mut self, index: usize) -> &mut DaemonProcess {
        &mut self.daemons[index]
    }

    /// Starts a new daemon on host `index` in place of the current one (which is killed first
    /// if it still runs), and opens a new tool session with it. Its log continues the old one.
    pub fn restart_daemon(&mut self, index: usize) {
        self.daemons[index].kill9();
        let host = self.network.host(index);
        self.daemons[index] = host.daemon(&self.domain, &Self::daemon_name(index));
        self.tools[index] = host.tool(&self.socket(index));
    }

    /// The tool session with host `index`'s daemon (its `graph()` returns errors instead of
    /// panicking, for tests that stop daemons).
    pub fn tool(&self, index: usize) -> &Participant {
        &self.tools[index]
    }

    /// The graph of host `index`'s daemon, through the tool session. Panics (with the daemon's
    /// log) if the daemon does not answer.
    pub fn graph(&self, index: usize) -> Graph {
        self.tools[index].graph().unwrap_or_else(|err| {
            panic!(
                "daemon of host {index} does not answer: {err}; its log:\n{}",
                self.daemons[index].log_text()
            )
        })
    }

    /// Starts `ndds-test-node ARGS` on host `index`, a client of that host's daemon.
    pub fn test_node(&self, index: usize, args: &[&str]) -> ClientProcess {
        let env: Vec<(&str, &std::path::Path)> = (self.domain.key.iter())
            .map(|key| ("NDDS_KEY_FILE", key.as_path()))
            .collect();
        ClientProcess::test_node_on_with_env(self.host(index), &self.socket(index), args, &env)
    }

    /// Runs `ndds ARGS` on host `index` against its daemon.
    pub fn ndds(&self, index: usize, args: &[&str], timeout: Duration) -> Output {
        self.host(index).ndds(&self.socket(index), args, timeout)
    }
}

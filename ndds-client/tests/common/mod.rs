//! Shared set-up of the SDK tests: every test gets its own domain, ports, multicast group and
//! socket directory, so tests running in parallel never discover each other, and everything
//! stays on loopback.

#![allow(dead_code)]

use std::net::Ipv4Addr;
use std::path::Path;
use std::time::Duration;

use ndds_client::{DaemonConfig, EmbeddedPolicy, Participant};

/// A daemon configuration unique to one test, on loopback, with fast timers.
pub fn unique_config(dir: &Path, name: &str) -> DaemonConfig {
    let mut rng = fastrand::Rng::new();
    let domain = rng.u16(1..=232);
    let mut config = DaemonConfig::new(domain, Ipv4Addr::LOCALHOST);
    config.socket = dir.join(format!("{name}.sock"));
    config.port = rng.u16(20_000..60_000);
    config.group = Ipv4Addr::new(239, 255, rng.u8(100..=254), rng.u8(1..=254));
    config.announce_period = Duration::from_millis(200);
    config.lease = Duration::from_millis(1000);
    config
}

/// The same domain, port and group as `config`, on another socket: a second "host".
pub fn sibling(config: &DaemonConfig, dir: &Path, name: &str) -> DaemonConfig {
    let mut other = config.clone();
    other.socket = dir.join(format!("{name}.sock"));
    other
}

/// A participant on an embedded daemon with `config` (started if not yet running).
pub fn participant(config: &DaemonConfig) -> Participant {
    Participant::builder()
        .embedded(EmbeddedPolicy::Auto)
        .embedded_config(config.clone())
        .name("sdk-test")
        .connect()
        .expect("participant connects")
}

/// Polls `check` every 10 ms until it holds or `timeout` passes.
pub fn eventually(timeout: Duration, mut check: impl FnMut() -> bool) -> bool {
    let deadline = std::time::Instant::now() + timeout;
    while std::time::Instant::now() < deadline {
        if check() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    check()
}

//! Amplification through discovery: an attacker sends a daemon `Solicit`s whose source address
//! (and announced locator) is a victim's, so that the daemon's answers (a full announcement by
//! unicast, then unicast copies of its refreshes while the forged node lives) go to the
//! victim. In a sealed domain the forgeries do not open and nothing goes to the victim; in an
//! open domain the daemon first probes the address (`Probe`, kind 5), the victim never answers,
//! and it gets at most the probes: no more bytes than the attacker sent (before the probes, the
//! victim got about 22 times the bytes sent). Real daemons on network namespaces; the attacker spoofs the
//! victim's address from its own host (needs root, `ip` and `nft`).

mod support;

use std::net::{SocketAddr, SocketAddrV4};
use std::time::{Duration, Instant};

use interop_tests::TestDomain;
use interop_tests::netns::{Cluster, Network};
use ndds_core::wire::{self, Locator, Message, NodeInfo, Solicit};
use support::{exclusive, node};

const RESPONDER: usize = 0;
const ATTACKER: usize = 1;
const VICTIM: usize = 2;
const SOLICITS: u64 = 300;
const ATTACK: Duration = Duration::from_secs(3);
/// After the attack: the reply jitter, and refreshes copied to the forged nodes until their
/// (announced) lease ends.
const AFTERMATH: Duration = Duration::from_secs(7);
const FORGED_LEASE_MS: u32 = 5000;

/// Sends `SOLICITS` solicitations from the victim's address (bound with `IP_TRANSPARENT` on the
/// attacker's host), each from a new node id announcing the victim's address; returns the
/// bytes sent.
fn spoof(cluster: &Cluster, target: SocketAddrV4) -> u64 {
    let victim = cluster.host(VICTIM).ip();
    let domain = cluster.domain().domain;
    cluster.host(ATTACKER).enter(|| {
        let socket = socket2::Socket::new(
            socket2::Domain::IPV4,
            socket2::Type::DGRAM,
            Some(socket2::Protocol::UDP),
        )
        .expect("socket");
        // A source address that is not the host's own: IP_TRANSPARENT (root) lets the kernel
        // route it.
        nix::sys::socket::setsockopt(&socket, nix::sys::socket::sockopt::IpTransparent, &true)
            .expect("IP_TRANSPARENT");
        let from = SocketAddrV4::new(victim, 7999);
        socket
            .bind(&SocketAddr::V4(from).into())
            .expect("bind to the victim's address");
        let started = Instant::now();
        let mut bytes = 0u64;
        for i in 0..SOLICITS {
            let due = started + ATTACK.mul_f64(i as f64 / SOLICITS as f64);
            std::thread::sleep(due.saturating_duration_since(Instant::now()));
            let solicit = Message::Solicit(Solicit {
                node: NodeInfo {
                    hostname: "spoofed".into(),
                    pid: 1,
                    unicast: Locator::from(from),
                    lease_ms: FORGED_LEASE_MS,
                    announce_period_ms: 1000,
                    version: String::new(),
                },
            });
            let mut datagram = Vec::new();
            wire::encode(domain, 0xA000_0000 + i, &solicit, &mut datagram).expect("solicit");
            if socket
                .send_to(&datagram, &SocketAddr::V4(target).into())
                .is_ok()
            {
                // IP and UDP headers, as the meter counts.
                bytes += datagram.len() as u64 + 28;
            }
        }
        bytes
    })
}

/// Runs the attack in `domain`; returns (bytes the attacker sent, bytes the victim received).
fn amplification(domain: TestDomain) -> (u64, u64) {
    let mut cluster = Cluster::start_in(Network::new(3), domain);
    // Something to announce: ten producers on the responder's host.
    let _producer = node(
        &cluster,
        RESPONDER,
        &[
            "produce", "--topic", "amp/t", "--topics", "10", "--rate", "0",
        ],
    );
    // The victim runs nothing: whatever reaches it is the attack's doing.
    cluster.daemon_mut(VICTIM).kill9();
    let target = SocketAddrV4::from(cluster.graph(RESPONDER).local.info.unicast);
    let victim = cluster.host(VICTIM);
    victim.start_meter();
    std::thread::sleep(Duration::from_secs(1));
    let quiet = victim.traffic();
    let sent = spoof(&cluster, target);
    std::thread::sleep(AFTERMATH);
    let received = (cluster.host(VICTIM).traffic() - quiet).in_bytes;
    (sent, received)
}

#[test]
fn spoofed_solicitations_amplify_nothing_sealed_or_open() {
    if support::skipped() {
        return;
    }
    let _turn = exclusive();
    let (sent, received) = amplification(TestDomain::sealed());
    let (open_sent, open_received) = amplification(TestDomain::new());
    eprintln!(
        "spoofed solicitations: sealed domain {sent} bytes sent, {received} bytes to the victim \
         ({:.2}x); open domain {open_sent} bytes sent, {open_received} bytes to the victim \
         ({:.2}x)",
        received as f64 / sent as f64,
        open_received as f64 / open_sent as f64,
    );
    assert!(sent > 0 && open_sent > 0);
    assert!(
        received <= 3 * sent,
        "sealed: the victim received {received} bytes for {sent} spoofed"
    );
    assert!(
        open_received <= 3 * open_sent,
        "open: the victim received {open_received} bytes for {open_sent} spoofed"
    );
    // The open domain's probes did reach the victim: the attack reached the daemon.
    assert!(
        open_received > 0,
        "the spoofed solicitations reached the open domain's daemon"
    );
}

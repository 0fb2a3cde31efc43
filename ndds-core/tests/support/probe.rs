//! Answering an engine's address probe, as the daemon probed would.

use std::net::SocketAddr;
use std::time::Instant;

use ndds_core::discovery::{Destination, Engine, Via};
use ndds_core::wire::{self, Locator, Message, ProbeReply};

/// Takes the engine's pending datagrams, finds its `Probe` to `at` and answers it from `at`
/// (as node `sender` of `domain`). Panics when there is no such probe.
pub fn answer_probe(engine: &mut Engine, now: Instant, at: Locator, domain: u16, sender: u64) {
    let token = std::iter::from_fn(|| engine.poll_transmit())
        .filter(|t| t.destination == Destination::Unicast(at))
        .find_map(|t| match wire::decode(&t.payload) {
            Ok((_, Message::Probe(probe))) => Some(probe.token),
            _ => None,
        })
        .expect("a probe to the address");
    let mut reply = Vec::new();
    let answer = Message::ProbeReply(ProbeReply { token });
    wire::encode(domain, sender, &answer, &mut reply).expect("probe reply");
    engine.handle_datagram(now, SocketAddr::V4(at.into()), Via::Unicast, &reply);
}

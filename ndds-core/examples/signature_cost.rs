//! What signing discovery costs (docs/benchmarks.md, "Signed discovery"): the time to wrap
//! a typical announcement (one endpoint, about 500 bytes) in a `Signed` datagram and to verify
//! one, on this machine. Run with `cargo run --release -p ndds-core --example
//! signature_cost`.

use std::time::Instant;

use ndds_core::security::Identity;
use ndds_core::wire::{self, signed};

fn main() {
    let identity = Identity::from_secret([7; 32]);
    let mut inner = Vec::new();
    wire::Header {
        kind: wire::MessageKind::Announce,
        domain: 0,
        sender: 42,
    }
    .emit(&mut inner);
    inner.resize(512, 0xA5);
    const N: u32 = 20_000;
    let started = Instant::now();
    let mut last = Vec::new();
    for count in 1..=u64::from(N) {
        last = signed::wrap(&inner, &identity, count).expect("a valid datagram");
    }
    let sign = started.elapsed() / N;
    let view = signed::parse(&last).expect("parses");
    let started = Instant::now();
    for _ in 0..N {
        view.verify().expect("verifies");
    }
    let verify = started.elapsed() / N;
    println!(
        "{N} datagrams of {} bytes: signing {sign:?} each, verifying {verify:?} each",
        inner.len()
    );
}

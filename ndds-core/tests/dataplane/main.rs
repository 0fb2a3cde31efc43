//! The participant's data plane ([`ParticipantCore`]) over a simulated network in virtual
//! time (see `sim.rs`): several participants, each a core at its own address, with loss,
//! reordering, duplication, partitions, nodes going down and a small MTU.
//!
//! - `reliable`: exactly once and in order under random faults, a partition longer than the
//!   reader liveness, flow control by slow consumers, mixed consumers of one participant;
//! - `large`: fragmented samples, repaired piece by piece (last-is-best for best effort);
//! - `rules`: arbitration fail-over and fail-back, minimum separation, deadlines;
//! - `forged`: traffic from unmatched senders or from a matched id at another address;
//! - `late_joiners`: the kept samples of reliable and best-effort producers;
//! - `late_match`: a consumer matched only after the producer silenced it picks up the stream;
//! - `liveness`: a reliable reader that never acknowledges leaves the window;
//! - `replay`: a run replays exactly from its seed;
//! - `sealed`: a domain with a key: streams as usual, outsiders without the key shut out;
//! - `throughput`: how much of its lossless rate a reliable stream keeps through 10 % loss.
//!
//! [`ParticipantCore`]: ndds_core::participant::ParticipantCore

mod forged;
mod large;
mod late_joiners;
mod late_match;
mod liveness;
mod reliable;
mod replay;
mod rules;
mod sealed;
mod sim;
mod throughput;

use std::time::Duration;

use ndds_core::arbitration::Rules;
use ndds_core::participant::{ConsumerSpec, ProducerSpec};
use ndds_core::reliability::{ReaderConfig, WriterConfig};

/// One millisecond.
pub const MS: Duration = Duration::from_millis(1);

/// A reliable consumer that may hold `credit` samples (`None`: unlimited).
pub fn reliable_consumer(credit: Option<usize>) -> ConsumerSpec {
    ConsumerSpec {
        rules: Rules::default(),
        reliable: Some(ReaderConfig::default()),
        credit,
    }
}

/// A best-effort consumer with these rules.
pub fn best_effort_consumer(rules: Rules) -> ConsumerSpec {
    ConsumerSpec {
        rules,
        reliable: None,
        credit: None,
    }
}

/// A reliable producer with a window of `depth` whose writes wait for room.
pub fn reliable_producer(depth: usize) -> ProducerSpec {
    reliable_producer_with(WriterConfig {
        depth,
        ..WriterConfig::default()
    })
}

/// A reliable producer with this writer configuration.
pub fn reliable_producer_with(config: WriterConfig) -> ProducerSpec {
    ProducerSpec {
        strength: 0,
        persistence_us: 0,
        reliable: Some(config),
        refuse_when_full: true,
        batching: None,
        late_joiners: config.late_joiners,
    }
}

/// A best-effort producer of `strength` and `persistence`.
pub fn best_effort_producer(strength: i32, persistence: Duration) -> ProducerSpec {
    ProducerSpec {
        strength,
        persistence_us: persistence.as_micros() as u64,
        reliable: None,
        refuse_when_full: false,
        batching: None,
        late_joiners: 0,
    }
}

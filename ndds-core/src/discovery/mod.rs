//! The sans-IO discovery engine: announce local endpoints, refresh them, solicit at start-up,
//! withdraw on close, decay remote entries, and match producers with consumers.
//!
//! See [`engine`] for the call order and behaviour, [`fanout`] for where datagrams go
//! (multicast group, static peers, unicast-only nodes), [`table`] for the matching rules,
//! [`sources`] for how full tables are made room in; signed datagrams are taken once each
//! (`freshness`).

pub mod config;
pub mod engine;
pub mod event;
pub mod fanout;
mod freshness;
pub mod sources;
pub mod table;

pub use config::{ConfigError, DiscoveryConfig, MAX_PEERS};
pub use engine::{Engine, LocalError, MAX_TOPIC_LEN, RemoteNode, Stats};
pub use event::{Destination, Event, LossReason, Transmit};
pub use fanout::Via;
pub use table::{Entry, Incompatibility, Origin, incompatibility};

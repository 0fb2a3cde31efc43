//! # ndds-core
//!
//! The protocol of ndds without any IO: the datagram wire format, type descriptions and their
//! fingerprints, the discovery engine (announce, refresh, solicit, withdraw, decay, matching),
//! a participant's data plane, and the messages local clients exchange with their daemon.
//!
//! Nothing here opens a socket, spawns a task or reads a clock. Every function that needs the
//! time takes `now`; randomness comes from a seed in the configuration. The daemon
//! (`ndds-daemon`) and client (`ndds-client`) are thin drivers around these state machines, and
//! the tests drive them over a simulated network with virtual time.
//!
//! ## Layout
//! - [`wire`]: header and one file per datagram kind, encode/decode, drop reasons.
//! - [`admission`]: who an endpoint believes (matched peers at their locators only).
//! - [`arbitration`]: a consumer's arbitration, minimum separation, deadline and statuses.
//! - [`reliability`]: reliable streams (history, heartbeats, acknowledgements, repair).
//! - [`fragment`]: large samples split into pieces and reassembled.
//! - [`participant`]: a participant's whole data plane (every producer and consumer, what
//!   it sends and believes), composed of the above, for one I/O thread to drive.
//! - [`types`]: type descriptions, layouts, canonical text and fingerprints.
//! - [`dynamic`]: decode a sample to JSON (and encode JSON to a sample) from its description.
//! - [`discovery`]: the sans-IO discovery engine and its configuration.
//! - [`ipc`]: frames between a client or tool and its local daemon over the Unix socket.
//! - [`domain`]: how a domain id maps to multicast group, port and socket path.
//! - [`ports`]: the pure logic of port-directed communication (priority select).
//! - [`suggest`]: "did you mean" for mistyped names (topics, machines, configurations, ...).
#![warn(missing_docs)]

pub mod admission;
pub mod arbitration;
pub mod discovery;
pub mod domain;
pub mod dynamic;
pub mod fragment;
mod hex;
pub mod ipc;
pub mod participant;
pub mod ports;
pub mod reliability;
pub mod seal;
pub mod security;
pub mod suggest;
pub mod types;
pub mod wire;

//! What the discovery engine tells its driver.

use std::sync::Arc;

use crate::wire::{EndpointInfo, Guid, Locator, NodeInfo};

/// An output of the discovery engine, taken with [`super::Engine::poll_event`].
///
/// Match events always name a *local* endpoint: they are addressed to the client that owns it.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// `local` and `remote` are producer and consumer of one topic with one type fingerprint.
    Matched {
        /// The local endpoint.
        local: Guid,
        /// The other endpoint (remote, or local to this node too).
        remote: EndpointInfo,
    },
    /// `local` and `remote` share a topic but their type fingerprints differ.
    Incompatible {
        /// The local endpoint.
        local: Guid,
        /// The other endpoint.
        remote: EndpointInfo,
    },
    /// `local` and `remote` would pair, but the permissions document does not allow one of
    /// them (see [`crate::security`]).
    Refused {
        /// The local endpoint.
        local: Guid,
        /// The other endpoint.
        remote: EndpointInfo,
        /// Why, in words: the subject, the rule.
        reason: String,
    },
    /// A previously matched, incompatible or refused endpoint went away.
    Unmatched {
        /// The local endpoint.
        local: Guid,
        /// The endpoint that went away (or the local endpoint that was closed).
        remote: Guid,
    },
    /// A node was heard from for the first time.
    NodeDiscovered {
        /// Its node id.
        node: u64,
        /// What it said about itself.
        info: NodeInfo,
    },
    /// A node and all its endpoints were forgotten.
    NodeLost {
        /// Its node id.
        node: u64,
        /// Why.
        reason: LossReason,
    },
}

/// Why a node was forgotten.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LossReason {
    /// Its lease expired without a refresh.
    Expired,
    /// It said `Bye`.
    Bye,
    /// The discovery tables were full and it was the oldest node of the busiest source.
    Evicted,
}

/// Where a datagram produced by the engine must go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Destination {
    /// The domain's discovery multicast group.
    Multicast,
    /// One node's unicast locator.
    Unicast(Locator),
}

/// A datagram to send.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Transmit {
    /// Where to send it.
    pub destination: Destination,
    /// The complete datagram, header included. The copies of one datagram sent to several
    /// destinations share these bytes.
    pub payload: Arc<[u8]>,
}

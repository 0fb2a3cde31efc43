//! Ports: port-directed communication (Shin, 1985) carried over ndds — a named channel with
//! exactly one owner and any number of users.
//!
//! So far: [`PortUser::send`] (blocks until the owner replies, or the timeout),
//! [`PortOwner::receive`] (the next request, with a [`ReplyHandle`] naming the sender) and
//! [`ReplyHandle::reply`] (non-blocking; replies may be given later and in any order), a
//! second owner reported to both owners and to users, and message formats checked (type
//! fingerprints); query / response with handler priorities ([`Responder`],
//! [`PortUser::query`]); `waitfor`, the n-way rendezvous with a combining function
//! ([`Rendezvous`]); a priority [`select`] over several ports; `sendall` from the owner to
//! every user ([`PortOwner::sendall`], [`PortUser::receive_all`]). Every blocking primitive
//! also has an async form (`send_async`, `query_async`, `receive_async`, `sendall_async`,
//! `receive_all_async`, `wait_async`). The pure logic lives in `ndds_core::ports` (the priority select).
//!
//! On the network, port `P` uses the reliable topics `port/P/request` (users to owner),
//! `port/P/reply/<user>` (owner to one user handle) and `port/P/owner` (the owner's
//! declaration, repeated every [`ANNOUNCE_PERIOD`]).

mod asynch;
mod error;
mod existing;
mod owner;
mod respond;
mod sendall;
mod user;
mod waitfor;
mod wire;

use std::time::Duration;

use ndds_core::types::builtin;
use serde::Serialize;
use serde::de::DeserializeOwned;

pub use error::PortError;
pub use existing::{OwnerLocation, owners_elsewhere};
pub use owner::{PortOwner, ReplyHandle};
pub use respond::{PENDING_PER_PORT, Responder};
pub use sendall::{Broadcast, BroadcastReply, Replies};
pub use user::PortUser;
pub use waitfor::{Arrival, LINGER, REPEAT, Rendezvous};
pub use wire::{Filter, OwnerInfo, Reply, Request, Restrictions, Usage, UserInfo};

use crate::{
    Consumer, ConsumerQos, Participant, Producer, ProducerQos, Reliability, TypeDescription,
};

/// A port an owner can [`select`] over.
pub trait Selectable {
    /// The port's name.
    fn port(&self) -> &str;
    /// Its priority (higher first).
    fn priority(&self) -> i32;
    /// Requests waiting now (taking them off the network into the owner's buffer).
    fn waiting(&self) -> usize;
}

/// Waits (at most `timeout`) until one of `ports` has a request and returns the index of the
/// one to receive from: the highest priority among those with requests waiting, the first
/// listed among equal priorities (deterministic); its oldest request is received next (FIFO
/// within a port).
pub fn select(ports: &[&dyn Selectable], timeout: Duration) -> Result<usize, PortError> {
    let start = std::time::Instant::now();
    loop {
        let best = ports
            .iter()
            .enumerate()
            .filter(|(_, p)| p.waiting() > 0)
            .max_by_key(|(i, p)| (p.priority(), std::cmp::Reverse(*i)))
            .map(|(i, _)| i);
        if let Some(index) = best {
            return Ok(index);
        }
        if start.elapsed() >= timeout {
            return Err(PortError::Timeout {
                port: ports
                    .iter()
                    .map(|p| p.port())
                    .collect::<Vec<_>>()
                    .join(", "),
                operation: "select",
                task: String::new(),
                owner: None,
                waited: start.elapsed(),
            });
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// The reply of a command port (a machine's `fsm.NAME`, a runtime's `cs.NAME`): what the
/// command did, or why not, in words for the person who asked.
pub type CommandReply = Result<String, String>;

/// How often an owner repeats its declaration; users forget an owner not heard for three.
pub const ANNOUNCE_PERIOD: Duration = Duration::from_millis(250);

fn topic(port: &str, leaf: &str) -> String {
    format!("port/{port}/{leaf}")
}

fn check_name(port: &str) -> Result<(), PortError> {
    if port.is_empty() || port.contains('/') || port.chars().any(char::is_control) {
        return Err(PortError::BadName(port.to_owned()));
    }
    Ok(())
}

fn declare_error(port: &str, topic: &str, source: crate::error::DeclareError) -> PortError {
    PortError::Declare {
        port: port.to_owned(),
        topic: topic.to_owned(),
        source,
    }
}

/// A [`PortError::Spawn`] of thread `thread` for `port`.
fn spawn_error(port: &str, thread: &str) -> impl FnOnce(std::io::Error) -> PortError {
    let (port, thread) = (port.to_owned(), thread.to_owned());
    move |source| PortError::Spawn {
        port: Some(port),
        thread,
        source,
    }
}

/// The message types ports put on the network, with the type description each is announced
/// with (tools decode them from it), under its `ndds::port::` name.
pub trait PortWire: Serialize + DeserializeOwned {
    /// The announced name ([`builtin`]).
    const TYPE_NAME: &'static str;

    /// The announced type description.
    fn description() -> TypeDescription {
        TypeDescription::named::<Self>(Self::TYPE_NAME)
    }
}

impl PortWire for Request {
    const TYPE_NAME: &'static str = builtin::PORT_REQUEST;
}

impl PortWire for Reply {
    const TYPE_NAME: &'static str = builtin::PORT_REPLY;
}

impl PortWire for Arrival {
    const TYPE_NAME: &'static str = builtin::PORT_ARRIVAL;
}

impl PortWire for Broadcast {
    const TYPE_NAME: &'static str = builtin::PORT_BROADCAST;
}

impl PortWire for BroadcastReply {
    const TYPE_NAME: &'static str = builtin::PORT_BROADCAST_REPLY;
}

impl PortWire for OwnerInfo {
    const TYPE_NAME: &'static str = builtin::PORT_OWNER_INFO;

    fn description() -> TypeDescription {
        // Its enums sit behind a Vec and an Option, where tracing cannot see their variants.
        TypeDescription::describer()
            .with::<Usage>()
            .with::<Filter>()
            .describe::<OwnerInfo>()
            .map_or_else(
                |_| TypeDescription::named::<OwnerInfo>(Self::TYPE_NAME),
                |desc| desc.with_name(Self::TYPE_NAME),
            )
    }
}

impl PortWire for UserInfo {
    const TYPE_NAME: &'static str = builtin::PORT_USER_INFO;

    fn description() -> TypeDescription {
        TypeDescription::describer()
            .with::<Usage>()
            .describe::<UserInfo>()
            .map_or_else(
                |_| TypeDescription::named::<UserInfo>(Self::TYPE_NAME),
                |desc| desc.with_name(Self::TYPE_NAME),
            )
    }
}

fn reliable_consumer<T: PortWire>(
    participant: &Participant,
    port: &str,
    topic: &str,
) -> Result<Consumer<T>, PortError> {
    let qos = ConsumerQos {
        reliability: Reliability::Reliable { depth: 256 },
        depth: 256,
        ..ConsumerQos::default()
    };
    participant
        .consumer_with_type::<T>(topic, T::description(), qos)
        .map_err(|e| declare_error(port, topic, e))
}

fn reliable_producer<T: PortWire>(
    participant: &Participant,
    port: &str,
    topic: &str,
) -> Result<Producer<T>, PortError> {
    let qos = ProducerQos {
        reliability: Reliability::Reliable { depth: 256 },
        ..ProducerQos::default()
    };
    participant
        .producer_with_type::<T>(topic, T::description(), qos)
        .map_err(|e| declare_error(port, topic, e))
}

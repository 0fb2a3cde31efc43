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
//! `port/P/reply/<user>` (owner to one user handle), `port/P/owner` and `port/P/users` (the
//! owner's and the users' declarations, written once and kept for late joiners: who is there
//! is what discovery matched, see `declaration`).
//!
//! No primitive polls: each is a future that sleeps on the queues and conditions it waits for
//! (`wait`); the blocking forms run it on the calling thread, the async forms on the caller's
//! executor.

mod asynch;
mod declaration;
mod description;
mod encoded;
mod error;
mod existing;
mod filter;
mod module;
mod owner;
mod respond;
mod sendall;
mod user;
mod wait;
mod waitfor;
mod wire;

use std::future::Future;
use std::pin::Pin;
use std::time::{Duration, Instant};

use ndds_core::ports::PrioritySelect;

use ndds_core::types::builtin;
use serde::Serialize;
use serde::de::DeserializeOwned;

pub use declaration::QUEUE_REPORT;
pub use description::{ModuleFile, ModuleFileError};
pub use encoded::Encoded;
pub use error::PortError;
pub use existing::{OwnerLocation, owners_elsewhere};
pub use filter::{BoundedBuffer, FILTER_INBOX, FilterPort, RequestFilter, Verdict};
pub use module::{Module, ModuleBuilder, ModuleContext, ModuleError, RunningModule, TaskContext};
pub use ndds_core::ports::schedule::{Arg, Call};
pub use ndds_core::ports::{LoadError, LoadProblem, Performed};
pub use owner::{PortOwner, ReplyHandle};
pub use respond::{PENDING_PER_PORT, Responder};
pub use sendall::{Answers, Broadcast, BroadcastReply, Replies};
pub use user::{ADMISSION_WAIT, PortUser};
pub use waitfor::{Arrival, LINGER, REPEAT, Rendezvous};
pub use wire::{
    Filter, ModuleInfo, OwnerInfo, ProcessClass, Reply, Request, Restrictions, Usage, UserInfo,
};

use crate::{
    Consumer, ConsumerQos, Participant, Producer, ProducerQos, Reliability, TypeDescription,
};

/// A port an owner can [`select`] over.
pub trait Selectable {
    /// The port's name.
    fn port(&self) -> &str;
    /// Its priority (higher first; `None` after every port with one).
    fn priority(&self) -> Option<i32>;
    /// Requests waiting now (taking them off the network into the owner's buffer).
    fn waiting(&self) -> usize;
    /// Resolves once a request may be waiting (it may be taken into the owner's buffer on
    /// the way): what [`select`] sleeps on.
    fn arrival(&self) -> Pin<Box<dyn Future<Output = ()> + '_>>;
}

/// Waits (at most `timeout`) until one of `ports` has a request and returns the index of the
/// one to receive from: the highest priority among those with requests waiting, the first
/// listed among equal priorities (deterministic); its oldest request is received next (FIFO
/// within a port). The choice is [`PrioritySelect`]'s, as for a [`Responder`]'s handlers.
pub fn select(ports: &[&dyn Selectable], timeout: Duration) -> Result<usize, PortError> {
    let start = Instant::now();
    let chosen = wait::block_on(wait::timeout_at(wait::deadline(start, timeout), async {
        loop {
            if let Some(index) = choose(ports) {
                return index;
            }
            let arrivals: Vec<_> = ports.iter().map(|p| p.arrival()).collect();
            any(arrivals).await;
        }
    }));
    // At the deadline, a request that is there already is still chosen.
    chosen
        .or_else(|| choose(ports))
        .ok_or_else(|| PortError::Timeout {
            port: ports
                .iter()
                .map(|p| p.port())
                .collect::<Vec<_>>()
                .join(", "),
            operation: "select",
            task: String::new(),
            owner: None,
            waited: start.elapsed(),
        })
}

/// The port among `ports` to receive from now, if any has a request.
fn choose(ports: &[&dyn Selectable]) -> Option<usize> {
    let mut ready = PrioritySelect::new();
    for (index, port) in ports.iter().enumerate() {
        let name = index.to_string();
        if ready.add_port(&name, port.priority(), 1).is_ok() && port.waiting() > 0 {
            let _ = ready.push(&name, index);
        }
    }
    ready.pop().map(|(_, index)| index)
}

/// Resolves when the first of `futures` does.
async fn any(mut futures: Vec<Pin<Box<dyn Future<Output = ()> + '_>>>) {
    std::future::poll_fn(|cx| {
        if futures.iter_mut().any(|f| f.as_mut().poll(cx).is_ready()) {
            std::task::Poll::Ready(())
        } else {
            std::task::Poll::Pending
        }
    })
    .await;
}

/// The reply of a command port (a machine's `fsm.NAME`, a runtime's `cs.NAME`): what the
/// command did, or why not, in words for the person who asked.
pub type CommandReply = Result<String, String>;

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

impl PortWire for ModuleInfo {
    const TYPE_NAME: &'static str = builtin::PORT_MODULE_INFO;
}

impl PortWire for OwnerInfo {
    const TYPE_NAME: &'static str = builtin::PORT_OWNER_INFO;

    fn description() -> TypeDescription {
        // Its enums sit behind a Vec and an Option, where tracing cannot see their variants.
        TypeDescription::describer()
            .with::<Usage>()
            .with::<Filter>()
            .with::<ProcessClass>()
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

/// A reliable producer of declarations: its last sample is kept for endpoints that match
/// later, so a declaration is written once (and again when it changes).
fn declaring_producer<T: PortWire>(
    participant: &Participant,
    port: &str,
    topic: &str,
) -> Result<Producer<T>, PortError> {
    let qos = ProducerQos {
        reliability: Reliability::Reliable { depth: 256 },
        late_joiners: 1,
        ..ProducerQos::default()
    };
    participant
        .producer_with_type::<T>(topic, T::description(), qos)
        .map_err(|e| declare_error(port, topic, e))
}

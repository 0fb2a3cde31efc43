//! Owner-to-user traffic: `sendall` (the owner sends one message to every user of its port and
//! unblocks on the first reply; the later replies stay available, as in the V kernel's group
//! sends), `callall` (the same, waiting for every user's answer) and `send_to` (to one user).
//!
//! On the network: the owner writes on the reliable topic `port/<P>/all` (to every user) or
//! `port/<P>/to/<user handle>` (to one); users take those messages with
//! [`PortUser::receive_all`](super::PortUser::receive_all) and
//! [`PortUser::receive`](super::PortUser::receive) and reply on `port/<P>/all-reply`, which the
//! owner reads. Each message has an id of its own at the owner; a [`ReplyDemux`] hands each
//! reply to the call that waits for it, so that calls of one owner may overlap.

use std::collections::{HashMap, VecDeque};
use std::marker::PhantomData;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::error::PortError;

/// A message broadcast by an owner.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Broadcast {
    /// Owner incarnation and sequence: what replies name.
    pub owner: u64,
    /// The broadcast's sequence number at this owner.
    pub id: u64,
    /// The owner's task.
    pub task: String,
    /// The message, postcard-encoded.
    #[serde(with = "serde_bytes")]
    pub payload: Vec<u8>,
}

/// A user's reply to a broadcast.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct BroadcastReply {
    /// The owner incarnation it answers.
    pub owner: u64,
    /// The broadcast it answers.
    pub id: u64,
    /// The replying user's task.
    pub task: String,
    /// The replying user handle (what the owner's admission counts).
    pub user: String,
    /// The reply, postcard-encoded.
    #[serde(with = "serde_bytes")]
    pub payload: Vec<u8>,
}

/// The replies to one `sendall`: the first (which `sendall` waited for) and the later ones.
pub struct Replies<'a, R> {
    pub(crate) port: &'a str,
    pub(crate) awaited: Awaited<'a>,
    pub(crate) owner: u64,
    pub(crate) source: &'a crate::Consumer<BroadcastReply>,
    pub(crate) shared: &'a super::owner::OwnerShared,
    pub(crate) first: (String, R),
    pub(crate) _reply: PhantomData<fn() -> R>,
}

impl<R: DeserializeOwned> Replies<'_, R> {
    /// The first reply: the replying task and its reply.
    pub fn first(&self) -> &(String, R) {
        &self.first
    }

    /// The next later reply, waiting at most `timeout`; `None` when none came.
    pub fn next(&self, timeout: Duration) -> Option<Result<(String, R), PortError>> {
        let at = super::wait::deadline(Instant::now(), timeout);
        let shared = self.shared;
        let reply = super::wait::block_on(super::wait::timeout_at(
            at,
            self.awaited
                .demux
                .next(self.source, self.owner, self.awaited.id, |r| {
                    shared.accepts_broadcast_reply(r, &[super::Usage::ReceiveAll])
                }),
        ))
        .flatten()?;
        Some(decode(self.port, reply))
    }
}

/// The answers to one `callall`: every user's that came, and the users that did not answer
/// within the timeout.
#[derive(Clone, Debug, PartialEq)]
pub struct Answers<R> {
    /// Each answering task and its answer, in the order they came.
    pub replies: Vec<(String, R)>,
    /// The tasks of the users that were sent the query and did not answer in time.
    pub missing: Vec<String>,
}

/// Decodes a reply's payload: the replying task and the reply.
pub(crate) fn decode<R: DeserializeOwned>(
    port: &str,
    reply: BroadcastReply,
) -> Result<(String, R), PortError> {
    postcard::from_bytes(&reply.payload)
        .map(|value| (reply.task, value))
        .map_err(|e| PortError::Codec {
            port: port.to_owned(),
            what: "decoding a user's reply",
            reason: e.to_string(),
        })
}

/// Replies an owner waits for, by message id: the call that reads a reply meant for another
/// call keeps it for that one and wakes it. Replies to calls nobody waits for any more, and
/// from other owners' messages, are dropped.
#[derive(Default)]
pub(crate) struct ReplyDemux {
    awaiting: Mutex<HashMap<u64, VecDeque<BroadcastReply>>>,
    handed: super::wait::Notify,
}

/// Replies kept for one waiting call, at most (more are dropped).
const KEPT_PER_CALL: usize = 1024;

/// A message whose replies are awaited; they are dropped once this goes.
pub(crate) struct Awaited<'a> {
    demux: &'a ReplyDemux,
    pub(crate) id: u64,
}

impl Drop for Awaited<'_> {
    fn drop(&mut self) {
        self.demux.lock().remove(&self.id);
    }
}

impl ReplyDemux {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<u64, VecDeque<BroadcastReply>>> {
        self.awaiting.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Awaits the replies to message `id` (before it is written, so none is missed).
    pub(crate) fn await_replies(&self, id: u64) -> Awaited<'_> {
        self.lock().entry(id).or_default();
        Awaited { demux: self, id }
    }

    /// The next reply to message `id` of owner incarnation `owner` that `accept` takes (it
    /// judges each reply once: the restrictions, and the user a call was for).
    pub(crate) async fn next(
        &self,
        source: &crate::Consumer<BroadcastReply>,
        owner: u64,
        id: u64,
        accept: impl Fn(&BroadcastReply) -> bool,
    ) -> Option<BroadcastReply> {
        use super::wait::{self, Either};
        loop {
            let seen = self.handed.generation();
            let kept = self.lock().get_mut(&id).and_then(VecDeque::pop_front);
            if let Some(reply) = kept {
                if accept(&reply) {
                    return Some(reply);
                }
                continue;
            }
            match wait::race(wait::next_sample(source), self.handed.changed(seen)).await {
                Either::Left(Some(sample)) => {
                    let reply = sample.value;
                    if reply.owner != owner {
                        continue;
                    }
                    if reply.id == id {
                        if accept(&reply) {
                            return Some(reply);
                        }
                        continue;
                    }
                    let mut awaiting = self.lock();
                    if let Some(kept) = awaiting.get_mut(&reply.id)
                        && kept.len() < KEPT_PER_CALL
                    {
                        kept.push_back(reply);
                        drop(awaiting);
                        self.handed.notify();
                    }
                }
                // The topic closed: only a reply another call took can still come.
                Either::Left(None) => self.handed.changed(seen).await,
                Either::Right(()) => {}
            }
        }
    }
}

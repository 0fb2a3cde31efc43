//! `sendall`: the owner sends one message to every user of its port and unblocks on the first
//! reply; the later replies stay available (as in the V kernel's group sends).
//!
//! On the network: the owner writes on the reliable topic `port/<P>/all`; users take those
//! messages with [`PortUser::receive_all`](super::PortUser::receive_all) and reply on
//! `port/<P>/all-reply`, which the owner reads.

use std::marker::PhantomData;
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
    pub(crate) id: u64,
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
        super::wait::block_on(next_reply(
            self.port,
            self.source,
            self.shared,
            (self.owner, self.id),
            at,
        ))
    }
}

/// The next reply to broadcast `id` of `owner` on `source`, by `at`. Replies to other
/// broadcasts are dropped, and so are replies from users the port's restrictions refuse or
/// have not admitted (`shared` judges them; they are counted there).
pub(crate) async fn next_reply<R: DeserializeOwned>(
    port: &str,
    source: &crate::Consumer<BroadcastReply>,
    shared: &super::owner::OwnerShared,
    (owner, id): (u64, u64),
    at: Option<Instant>,
) -> Option<Result<(String, R), PortError>> {
    let reply = super::wait::timeout_at(at, async {
        loop {
            let reply = super::wait::next_sample(source).await?.value;
            if reply.owner == owner && reply.id == id && shared.accepts_broadcast_reply(&reply) {
                return Some(reply);
            }
        }
    })
    .await
    .flatten()?;
    Some(
        postcard::from_bytes(&reply.payload)
            .map(|value| (reply.task, value))
            .map_err(|e| PortError::Codec {
                port: port.to_owned(),
                what: "decoding a broadcast reply",
                reason: e.to_string(),
            }),
    )
}

//! [`PortError`]: what a port primitive can fail with. Every variant names the port (or the
//! rendezvous), except a [`Responder`](super::Responder)'s own thread that did not start.

use std::time::Duration;

use ndds_core::ports::SelectError;

use crate::error::{DeclareError, WriteError};

/// A port primitive that failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PortError {
    /// No reply (or no request) within the timeout.
    #[error("port `{port}`: {operation} by `{task}` timed out after {waited:?}{}", owner.as_ref().map(|o| format!(" ({} `{o}`)", if matches!(*operation, "send_to" | "owner's query" | "owner's send") { "user" } else { "owner" })).unwrap_or_default())]
    Timeout {
        /// The port.
        port: String,
        /// `send` or `receive`.
        operation: &'static str,
        /// The task that waited.
        task: String,
        /// The owner it waited for, if one was known (for the owner's `send_to`: the user).
        owner: Option<String>,
        /// How long it waited.
        waited: Duration,
    },
    /// A rendezvous not complete within the timeout.
    #[error("waitfor `{name}`: `{task}` waited {waited:?}; still missing: {}", missing.join(", "))]
    WaitFor {
        /// The rendezvous.
        name: String,
        /// The task that waited.
        task: String,
        /// Tasks whose arrival never came (empty: all came, but not all had this task's).
        missing: Vec<String>,
        /// How long it waited.
        waited: Duration,
    },
    /// The owner's `send_to` named a user that is not there (or does not take such messages,
    /// or is not admitted) within the timeout.
    #[error("port `{port}`: owner `{owner}` has no user `{user}` that declared `{usage}` (users present: {})", if present.is_empty() { "none".to_owned() } else { present.join(", ") })]
    NoSuchUser {
        /// The port.
        port: String,
        /// The owner's task.
        owner: String,
        /// The user's task it named.
        user: String,
        /// The usage such a user must declare.
        usage: &'static str,
        /// The users present, with their usages.
        present: Vec<String>,
    },
    /// Two owners declared the port: reported to both, and to users.
    #[error("port `{port}` has two owners: `{first}` and `{second}`")]
    SecondOwner {
        /// The port.
        port: String,
        /// One owner (this side's, for an owner).
        first: String,
        /// The other.
        second: String,
    },
    /// This owner was replaced: another task took the port over with a higher claim
    /// ([`PortOwner::take_over`](super::PortOwner::take_over)). It receives and replies no
    /// more; users send to the replacement.
    #[error("port `{port}`: owner `{owner}` was replaced by `{by}`; it serves the port no more")]
    Superseded {
        /// The port.
        port: String,
        /// This owner's task.
        owner: String,
        /// The replacement, in words.
        by: String,
    },
    /// A restriction of the port refuses this user.
    #[error("port `{port}`: `{user}` refused by owner `{owner}`: {restriction}: {detail}")]
    Refused {
        /// The port.
        port: String,
        /// The owner.
        owner: String,
        /// The user.
        user: String,
        /// Which restriction.
        restriction: &'static str,
        /// Why, in words.
        detail: String,
    },
    /// The message formats of the two sides differ.
    #[error(
        "port `{port}`: `{user}` uses message formats {user_formats} but owner `{owner}` expects {owner_formats}"
    )]
    Format {
        /// The port.
        port: String,
        /// The owner.
        owner: String,
        /// The user.
        user: String,
        /// The owner's request/reply fingerprints.
        owner_formats: String,
        /// The user's.
        user_formats: String,
    },
    /// A message that could not be encoded or decoded.
    #[error("port `{port}`: {what}: {reason}")]
    Codec {
        /// The port.
        port: String,
        /// What was being done.
        what: &'static str,
        /// Why it failed.
        reason: String,
    },
    /// A topic of the port could not be declared.
    #[error("port `{port}`: topic `{topic}`: {source}")]
    Declare {
        /// The port.
        port: String,
        /// The topic.
        topic: String,
        /// Why the daemon did not declare it.
        source: DeclareError,
    },
    /// A message could not be written to a topic of the port (a closed window, a failed send:
    /// see the source).
    #[error("port `{port}`: writing {what}: {source}")]
    Write {
        /// The port.
        port: String,
        /// What was being written (a request, the reply to a task, ...).
        what: String,
        /// Why it failed.
        source: WriteError,
    },
    /// A thread the primitive runs on could not be started.
    #[error("{}cannot start thread `{thread}`: {source}", port.as_ref().map(|p| format!("port `{p}`: ")).unwrap_or_default())]
    Spawn {
        /// The port (`None` for a [`Responder`](super::Responder), which has none yet).
        port: Option<String>,
        /// The thread's name.
        thread: String,
        /// Why it did not start.
        source: std::io::Error,
    },
    /// An async operation's thread ended without a result (it panicked).
    #[error("port `{port}`: the operation's thread ended without a result")]
    ThreadEnded {
        /// The port.
        port: String,
    },
    /// A port declared with the restriction `Filter::Task` but without the filter's code.
    #[error(
        "port `{port}`: a `Filter::Task` restriction needs the filter's code: declare the port with `PortOwner::declare_filtered`"
    )]
    FilterCode {
        /// The port.
        port: String,
    },
    /// A bounded-buffer filter declared with a capacity of 0.
    #[error("port `{port}`: a bounded-buffer filter needs a capacity of at least 1")]
    ZeroCapacity {
        /// The port.
        port: String,
    },
    /// The owner's reply type does not suit its restrictions (a bounded-buffer filter answers
    /// sends at once, so its replies must be `()`).
    #[error(
        "port `{port}`: a bounded-buffer filter answers sends at once: the reply type must be \
         `{expected}`, not `{got}`"
    )]
    ReplyType {
        /// The port.
        port: String,
        /// The reply type needed.
        expected: &'static str,
        /// The owner's reply type.
        got: &'static str,
    },
    /// A request whose reply id cannot name a reply topic: the sender's bug, not the port's.
    #[error("port `{port}`: `{sender}` gave an unusable reply id {id:?}")]
    BadReplyId {
        /// The port.
        port: String,
        /// The task that sent the request.
        sender: String,
        /// The id it gave.
        id: String,
    },
    /// A [`Responder`](super::Responder) could not take a handler for the port (it has one
    /// already).
    #[error("port `{port}`: cannot add its response handler: {source}")]
    Handler {
        /// The port.
        port: String,
        /// Why not.
        source: SelectError,
    },
    /// [`Rendezvous::join`](super::Rendezvous::join) as a task the rendezvous does not name.
    #[error("waitfor `{name}`: task `{task}` is not among the rendezvous' tasks {tasks:?}")]
    UnknownTask {
        /// The rendezvous.
        name: String,
        /// The task that tried to join.
        task: String,
        /// The tasks it names.
        tasks: Vec<String>,
    },
    /// A port of [`Encoded`](super::Encoded) messages declared without their descriptions
    /// (they carry no Rust type to trace).
    #[error(
        "port `{port}`: `Encoded` messages carry no Rust type: declare the port with \
         `declare_described` and the messages' type descriptions"
    )]
    Undescribed {
        /// The port.
        port: String,
    },
    /// A port name that cannot be part of topic names.
    #[error("bad port name `{0}`: it must be non-empty, without `/` or control characters")]
    BadName(String),
}

//! [`PortError`]: what a port primitive can fail with. Every variant names the port.

use std::time::Duration;

/// A port primitive that failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PortError {
    /// No reply (or no request) within the timeout.
    #[error("port `{port}`: {operation} by `{task}` timed out after {waited:?}{}", owner.as_ref().map(|o| format!(" (owner `{o}`)")).unwrap_or_default())]
    Timeout {
        /// The port.
        port: String,
        /// `send` or `receive`.
        operation: &'static str,
        /// The task that waited.
        task: String,
        /// The owner it waited for, if one was known.
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
    /// A topic of the port could not be declared or written.
    #[error("port `{port}`: {reason}")]
    Transport {
        /// The port.
        port: String,
        /// Why.
        reason: String,
    },
    /// A port name that cannot be part of topic names.
    #[error("bad port name `{0}`: it must be non-empty, without `/` or control characters")]
    BadName(String),
}

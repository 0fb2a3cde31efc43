//! The message direction restriction: what each end of a port does with it.

use serde::{Deserialize, Serialize};

/// What one end of a port does with it: the message direction restriction (Shin, section 3,
/// and the six usages of section 5). An owner declares its own usages in
/// `Restrictions::usages`; a user declares its own with
/// `PortUser::declare_with`. The two ends must complement
/// each other:
///
/// | owner | user |
/// |---|---|
/// | `Receive` (and `reply`) | `Send` |
/// | `Response` (a response handler) | `Query` |
/// | `Send` (`send_to`) | `Receive` |
/// | `Query` (`send_to`, answered by a user's handler) | `Response` |
/// | `SendAll` (`sendall`), `CallAll` (`callall`) | `ReceiveAll` |
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Usage {
    /// A user's `send`: a request answered by the owner's `reply`; an owner's: messages to
    /// one user (`send_to`).
    Send,
    /// A user's `query`: a request answered by the owner's response handler; an owner's:
    /// a query to one user (`send_to`) answered by its response handler.
    Query,
    /// A user's `receive_all`: messages the owner sends to every user (`sendall`,
    /// `callall`).
    ReceiveAll,
    /// A user's `receive`: messages the owner sends to this user alone; an owner's:
    /// `receive` (and `reply`).
    Receive,
    /// A user's response handler for the owner's queries (taken with `receive`); an owner's:
    /// a response handler for users' queries.
    Response,
    /// An owner's `sendall`.
    SendAll,
    /// An owner's `callall`.
    CallAll,
}

impl Usage {
    /// The usage of a user that complements this usage of an owner (`None`: not an owner's
    /// usage).
    pub fn user_complement(self) -> Option<Usage> {
        Some(match self {
            Usage::Receive => Usage::Send,
            Usage::Response => Usage::Query,
            Usage::Send => Usage::Receive,
            Usage::Query => Usage::Response,
            Usage::SendAll | Usage::CallAll => Usage::ReceiveAll,
            Usage::ReceiveAll => return None,
        })
    }

    /// Whether a user may declare this usage.
    pub fn of_user(self) -> bool {
        !matches!(self, Usage::SendAll | Usage::CallAll)
    }
}

//! Identities and per-topic permissions.
//!
//! Each daemon of a domain with a permissions document has an Ed25519 identity ([`Identity`])
//! and signs every discovery datagram it sends with it ([`crate::wire::signed`]). A
//! receiving daemon binds a node to the identity it first spoke with, refuses datagrams that
//! name the node and are not signed by it (`unverified`), and looks the identity up in its
//! own copy of the document ([`Permissions`], signed by an administrator key kept offline) to
//! decide, endpoint by endpoint, whether the node may publish, subscribe, own or use what it
//! announces. A refused endpoint stays known (it is shown with its [`Refusal`]) but matches
//! nothing, and the local clients whose endpoints it would have matched are told why. A
//! daemon also refuses its own clients' declarations that its subject may not make.
//!
//! Why signatures on discovery datagrams rather than a handshake per pair of daemons: the
//! statements that matter (which endpoints a node has, its lease, its `Bye`) travel by
//! multicast to every daemon at once, and a signature authenticates each of them for every
//! receiver with no state per pair and nothing to lose on a lossy link. Its cost is one
//! Ed25519 signature per datagram sent and one verification per datagram received (tens of
//! microseconds; discovery sends a few datagrams per second). Replays are the seal's to
//! refuse, so a permissions document requires a domain key.

mod identity;
mod permissions;

pub use identity::{Identity, IdentityFileError, KEY_PREFIX, KeyTextError, PublicId};
pub use permissions::{
    Action, MAX_NAME_LEN, MAX_PATTERNS, MAX_SUBJECTS, Pattern, Permissions, PermissionsError,
    Refusal, SIGNATURE_LINE, Subject, needs, sign, split_signed, unsigned_text, verify_signed,
};

use std::sync::Arc;
use std::time::Instant;

/// What a discovery engine enforces (see [`crate::discovery::Engine::guard_with`]).
#[derive(Clone, Debug)]
pub struct Guard {
    /// This daemon's identity: signs everything it sends.
    pub identity: Identity,
    /// The document, already verified against the administrator key.
    pub permissions: Arc<Permissions>,
    /// When the document's validity ends, on the engine's clock (the driver converts from
    /// wall-clock time); `None`: it does not end while this engine runs.
    pub valid_until: Option<Instant>,
}

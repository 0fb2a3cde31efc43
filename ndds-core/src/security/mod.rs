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
//! microseconds; discovery sends a few datagrams per second). The seal refuses replays
//! by hosts without the domain key, so a permissions document requires one; replays by a
//! holder of the key are refused by the count each signed datagram carries
//! ([`crate::wire::signed`]).

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

/// The keys of one pair of participants' data, in a domain with permissions: what one seals
/// for the other, and what it opens from it. Given by a daemon to its client only for a pair
/// its document allows, and derived from the secret the two participants' daemons share (X25519
/// of their agreement keys), so that nobody else — a host with the domain key included — can
/// read or forge the pair's datagrams.
#[derive(Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct DataKeys {
    /// Seals what the local participant sends the other.
    pub send: [u8; 32],
    /// Opens what the other sends the local participant.
    pub receive: [u8; 32],
}

impl std::fmt::Debug for DataKeys {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("DataKeys(..)")
    }
}

impl DataKeys {
    /// The keys of participants `local` and `other` from the secret their daemons share.
    pub fn derive(shared: &[u8; 32], local: u64, other: u64) -> DataKeys {
        DataKeys {
            send: direction(shared, local, other),
            receive: direction(shared, other, local),
        }
    }
}

/// The key of the datagrams `from` sends `to`.
fn direction(shared: &[u8; 32], from: u64, to: u64) -> [u8; 32] {
    let hkdf = hkdf::Hkdf::<sha2::Sha256>::new(Some(b"ndds-data-v1"), shared);
    let mut info = [0u8; 16];
    info[..8].copy_from_slice(&from.to_le_bytes());
    info[8..].copy_from_slice(&to.to_le_bytes());
    let mut out = [0u8; 32];
    // 32 bytes is far below HKDF-SHA256's limit: this cannot fail.
    let _ = hkdf.expand(&info, &mut out);
    out
}

/// Bits of a node id that, in a domain with permissions, come from the daemon's identity (the
/// other 24 are drawn at each start): a datagram signed by one identity cannot name a node id
/// of another, so nobody can take a daemon's node id before it is heard (finding an identity
/// whose id bits match would take about 2^40 key generations).
pub const NODE_ID_IDENTITY_BITS: u32 = 40;

/// The node id of a daemon with `identity`, its start's 24 random bits taken from `random`.
pub fn node_id_for(identity: &PublicId, random: u64) -> u64 {
    let low = random & ((1 << (64 - NODE_ID_IDENTITY_BITS)) - 1);
    (identity_bits(identity) << (64 - NODE_ID_IDENTITY_BITS)) | low.max(1)
}

/// Whether `node` is a node id of `identity` ([`node_id_for`]).
pub fn owns_node_id(identity: &PublicId, node: u64) -> bool {
    node >> (64 - NODE_ID_IDENTITY_BITS) == identity_bits(identity)
}

fn identity_bits(identity: &PublicId) -> u64 {
    use sha2::Digest as _;
    let digest = sha2::Sha256::new()
        .chain_update(b"ndds-node-id-v1")
        .chain_update(identity.as_bytes())
        .finalize();
    let mut bytes = [0u8; 8];
    bytes[3..].copy_from_slice(&digest[..5]);
    u64::from_be_bytes(bytes)
}

//! `Signed` (kind 7): a discovery datagram signed by its daemon's Ed25519 identity, in
//! domains with a permissions document.
//!
//! ```text
//!  0                16                48                80          88                  152
//!  +----------------+-----------------+-----------------+-----------+-------------------+------
//!  | header (kind 7)| identity (32)   | agreement (32)  | count (8) | signature (64)    | inner
//!  +----------------+-----------------+-----------------+-----------+-------------------+------
//! ```
//!
//! `inner` is a complete discovery datagram (header and body) of the same domain and sender;
//! `agreement` is the sender's X25519 public key (for the data keys of its participants'
//! pairs, [`crate::security::DataKeys`]); `count` (little-endian) numbers the node's signed
//! datagrams from 1, one more for each; the signature is the identity's Ed25519 signature of
//! `ndds-signed-v2`, then `agreement`, `count` and `inner`.
//! Every datagram a daemon with an identity sends is signed, so a node's endpoints, leases
//! and `Bye` are believed only from its identity; a receiver takes each count of a node once
//! (a replay window per node, and the highest count of a node that is gone kept for a while),
//! so a host that holds the domain key and re-seals a recorded signed datagram gets nothing
//! from it.

use super::DropReason;
use super::header::{HEADER_LEN, Header, MessageKind};
use crate::security::{Identity, PublicId};

/// Bytes a signature adds to a datagram: a header, the identity, the signature.
pub const SIGNED_OVERHEAD: usize = HEADER_LEN + 32 + 32 + 8 + 64;

/// A signed datagram, not yet verified.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SignedView<'a> {
    /// The outer header.
    pub header: Header,
    /// Who says it signed.
    pub identity: PublicId,
    /// Its X25519 public key.
    pub agreement: [u8; 32],
    /// The datagram's number among the node's signed datagrams.
    pub count: u64,
    /// The signature.
    pub signature: [u8; 64],
    /// The datagram signed.
    pub inner: &'a [u8],
}

impl SignedView<'_> {
    /// Whether the signature verifies and the inner datagram is of the outer one's domain and
    /// sender; `Err(Unverified)` or `Err(Invalid)` otherwise.
    pub fn verify(&self) -> Result<(), DropReason> {
        let (inner, _) = Header::parse(self.inner)?;
        if inner.domain != self.header.domain
            || inner.sender != self.header.sender
            || inner.kind == MessageKind::Signed
        {
            return Err(DropReason::Invalid);
        }
        if !self.identity.verifies(
            &message(&self.agreement, self.count, self.inner),
            &self.signature,
        ) {
            return Err(DropReason::Unverified);
        }
        Ok(())
    }
}

/// Reads a `Signed` datagram's parts (nothing verified yet).
pub fn parse(bytes: &[u8]) -> Result<SignedView<'_>, DropReason> {
    let (header, body) = Header::parse(bytes)?;
    if header.kind != MessageKind::Signed {
        return Err(DropReason::Unexpected);
    }
    const FIXED: usize = SIGNED_OVERHEAD - HEADER_LEN;
    if body.len() < FIXED + HEADER_LEN {
        return Err(DropReason::Malformed);
    }
    let identity = PublicId::from_bytes(body[..32].try_into().expect("32 bytes"));
    let agreement: [u8; 32] = body[32..64].try_into().expect("32 bytes");
    let count = u64::from_le_bytes(body[64..72].try_into().expect("8 bytes"));
    let signature: [u8; 64] = body[72..136].try_into().expect("64 bytes");
    Ok(SignedView {
        header,
        identity,
        agreement,
        count,
        signature,
        inner: &body[FIXED..],
    })
}

/// `inner` (a complete datagram) signed by `identity` as its sender's datagram number `count`.
pub fn wrap(inner: &[u8], identity: &Identity, count: u64) -> Result<Vec<u8>, DropReason> {
    let (header, _) = Header::parse(inner)?;
    let mut out = Vec::with_capacity(SIGNED_OVERHEAD + inner.len());
    Header {
        kind: MessageKind::Signed,
        ..header
    }
    .emit(&mut out);
    let agreement = identity.agreement_public();
    out.extend_from_slice(identity.public().as_bytes());
    out.extend_from_slice(&agreement);
    out.extend_from_slice(&count.to_le_bytes());
    out.extend_from_slice(&identity.sign(&message(&agreement, count, inner)));
    out.extend_from_slice(inner);
    Ok(out)
}

fn message(agreement: &[u8; 32], count: u64, inner: &[u8]) -> Vec<u8> {
    let mut message = Vec::with_capacity(14 + 32 + 8 + inner.len());
    message.extend_from_slice(b"ndds-signed-v2");
    message.extend_from_slice(agreement);
    message.extend_from_slice(&count.to_le_bytes());
    message.extend_from_slice(inner);
    message
}

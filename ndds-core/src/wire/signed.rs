//! `Signed` (kind 7): a discovery datagram signed by its daemon's Ed25519 identity, in
//! domains with a permissions document.
//!
//! ```text
//!  0                16                      48                                  112
//!  +----------------+-----------------------+-----------------------------------+----------
//!  | header (kind 7)| identity (32 bytes)   | signature (64 bytes)              | inner
//!  +----------------+-----------------------+-----------------------------------+----------
//! ```
//!
//! `inner` is a complete discovery datagram (header and body) of the same domain and sender;
//! the signature is the identity's Ed25519 signature of `ndds-signed-v1` followed by `inner`.
//! Every datagram a daemon with an identity sends is signed, so a node's endpoints, leases
//! and `Bye` are believed only from the identity it first spoke with. (Replays of a signed
//! datagram are what the domain key's seal refuses: permissions require a sealed domain.)

use super::DropReason;
use super::header::{HEADER_LEN, Header, MessageKind};
use crate::security::{Identity, PublicId};

/// Bytes a signature adds to a datagram: a header, the identity, the signature.
pub const SIGNED_OVERHEAD: usize = HEADER_LEN + 32 + 64;

/// A signed datagram, not yet verified.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SignedView<'a> {
    /// The outer header.
    pub header: Header,
    /// Who says it signed.
    pub identity: PublicId,
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
        if !self
            .identity
            .verifies(&message(self.inner), &self.signature)
        {
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
    if body.len() < 96 + HEADER_LEN {
        return Err(DropReason::Malformed);
    }
    let identity = PublicId::from_bytes(body[..32].try_into().expect("32 bytes"));
    let signature: [u8; 64] = body[32..96].try_into().expect("64 bytes");
    Ok(SignedView {
        header,
        identity,
        signature,
        inner: &body[96..],
    })
}

/// `inner` (a complete datagram) signed by `identity`.
pub fn wrap(inner: &[u8], identity: &Identity) -> Result<Vec<u8>, DropReason> {
    let (header, _) = Header::parse(inner)?;
    let mut out = Vec::with_capacity(SIGNED_OVERHEAD + inner.len());
    Header {
        kind: MessageKind::Signed,
        ..header
    }
    .emit(&mut out);
    out.extend_from_slice(identity.public().as_bytes());
    out.extend_from_slice(&identity.sign(&message(inner)));
    out.extend_from_slice(inner);
    Ok(out)
}

fn message(inner: &[u8]) -> Vec<u8> {
    let mut message = Vec::with_capacity(14 + inner.len());
    message.extend_from_slice(b"ndds-signed-v1");
    message.extend_from_slice(inner);
    message
}

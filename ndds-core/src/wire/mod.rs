//! The datagram wire format: a fixed [`Header`] then a postcard-encoded body, one message kind
//! per file.
//!
//! Decoding never panics and never allocates more than the datagram's length justifies (see
//! [`bounded`]). Anything that is not a well-formed datagram of this protocol version yields a
//! [`DropReason`] that receivers count; nothing is parsed past the first problem.

pub mod announce;
pub mod bounded;
pub mod bye;
pub mod data;
pub mod endpoint;
pub mod feedback;
pub mod header;
pub mod node;
pub mod probe;
pub mod qos;
pub mod signed;
pub mod solicit;
pub mod withdraw;

use serde::Serialize;

pub use announce::Announce;
pub use bye::Bye;
pub use data::{DataDatagram, DataSub, DataWriter, SampleMeta};
pub use endpoint::{EndpointInfo, EndpointKind, Guid, Locator};
pub use feedback::{FeedbackDatagram, FeedbackSub};
pub use header::{HEADER_LEN, Header, MAGIC, MessageKind, PROTOCOL_VERSION};
pub use node::NodeInfo;
pub use probe::{Probe, ProbeReply};
pub use qos::{ConsumerMode, ConsumerQosWire, EndpointQos, ProducerQosWire, Reliability};
pub use solicit::Solicit;
pub use withdraw::Withdraw;

/// Largest datagram ndds sends or accepts (the largest UDP payload IPv4 can carry).
pub const MAX_DATAGRAM: usize = 65_507;

/// Why a received datagram was dropped. Each reason has its own counter in the daemon and
/// the client; the names are the counter names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, thiserror::Error)]
pub enum DropReason {
    /// Shorter than the 16-byte header.
    #[error("truncated datagram (shorter than the header)")]
    Truncated,
    /// Does not start with `NDDS`.
    #[error("foreign datagram (bad magic)")]
    ForeignMagic,
    /// A protocol version this implementation does not speak.
    #[error("unsupported protocol version")]
    UnsupportedVersion,
    /// A message kind this version does not know.
    #[error("unknown message kind")]
    UnknownKind,
    /// From another domain.
    #[error("datagram of another domain")]
    OtherDomain,
    /// The body did not decode, or bytes were left over after it.
    #[error("malformed body")]
    Malformed,
    /// The body decoded but violates a rule of the protocol (see the message's docs).
    #[error("invalid content")]
    Invalid,
    /// Our own datagram, looped back by multicast.
    #[error("own datagram")]
    Own,
    /// A well-formed message this receiver does not handle: `Data` or `Feedback` on a
    /// discovery socket, discovery messages on a data socket, anything reaching an engine
    /// after `close`.
    #[error("message kind not handled by this receiver")]
    Unexpected,
    /// A discovery message naming a known node, from another address than that node's.
    #[error("names a known node but comes from another address")]
    Spoofed,
    /// A signed discovery datagram whose signature does not verify, or one that is unsigned
    /// or signed by another identity than the node's (domains with permissions).
    #[error("signature missing, wrong or of another identity")]
    Unverified,
    /// A signed discovery datagram whose number its node's datagrams were taken with already,
    /// or one too old to tell (a replay by a holder of the domain key; domains with
    /// permissions).
    #[error("signed datagram taken already (a replay)")]
    Replayed,
}

impl DropReason {
    /// Every reason, for counter tables.
    pub const ALL: [DropReason; 12] = [
        DropReason::Truncated,
        DropReason::ForeignMagic,
        DropReason::UnsupportedVersion,
        DropReason::UnknownKind,
        DropReason::OtherDomain,
        DropReason::Malformed,
        DropReason::Invalid,
        DropReason::Own,
        DropReason::Unexpected,
        DropReason::Spoofed,
        DropReason::Unverified,
        DropReason::Replayed,
    ];

    /// Stable snake-case name used as a counter key.
    pub fn name(self) -> &'static str {
        match self {
            DropReason::Truncated => "truncated",
            DropReason::ForeignMagic => "foreign_magic",
            DropReason::UnsupportedVersion => "unsupported_version",
            DropReason::UnknownKind => "unknown_kind",
            DropReason::OtherDomain => "other_domain",
            DropReason::Malformed => "malformed",
            DropReason::Invalid => "invalid",
            DropReason::Own => "own",
            DropReason::Unexpected => "unexpected",
            DropReason::Spoofed => "spoofed",
            DropReason::Unverified => "unverified",
            DropReason::Replayed => "replayed",
        }
    }

    /// Position in [`DropReason::ALL`], for array-backed counters.
    pub fn index(self) -> usize {
        DropReason::ALL
            .iter()
            .position(|r| *r == self)
            .unwrap_or_default()
    }
}

/// A decoded discovery datagram body. (`Data` and `Feedback` datagrams are sequences of
/// submessages, parsed with [`DataDatagram`] and [`FeedbackDatagram`].)
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    /// See [`solicit`].
    Solicit(Solicit),
    /// See [`announce`].
    Announce(Announce),
    /// See [`withdraw`].
    Withdraw(Withdraw),
    /// See [`bye`].
    Bye(Bye),
    /// See [`probe`].
    Probe(Probe),
    /// See [`probe`].
    ProbeReply(ProbeReply),
}

impl Message {
    /// The header kind of this message.
    pub fn kind(&self) -> MessageKind {
        match self {
            Message::Solicit(_) => MessageKind::Solicit,
            Message::Announce(_) => MessageKind::Announce,
            Message::Withdraw(_) => MessageKind::Withdraw,
            Message::Bye(_) => MessageKind::Bye,
            Message::Probe(_) => MessageKind::Probe,
            Message::ProbeReply(_) => MessageKind::ProbeReply,
        }
    }
}

/// Failure to encode a message.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    /// postcard refused the value (cannot happen for the types in this module).
    #[error("encoding failed: {0}")]
    Postcard(#[from] postcard::Error),
    /// The encoded datagram would exceed [`MAX_DATAGRAM`].
    #[error("datagram of {size} bytes exceeds the {MAX_DATAGRAM}-byte limit")]
    TooLarge {
        /// Size the datagram would have had.
        size: usize,
    },
}

/// Appends a complete datagram (header then body) to `out`.
///
/// On error `out` is left as it was.
pub fn encode(
    domain: u16,
    sender: u64,
    message: &Message,
    out: &mut Vec<u8>,
) -> Result<(), EncodeError> {
    let start = out.len();
    let header = Header {
        kind: message.kind(),
        domain,
        sender,
    };
    header.emit(out);
    let result = match message {
        Message::Solicit(body) => append_body(body, out),
        Message::Announce(body) => append_body(body, out),
        Message::Withdraw(body) => append_body(body, out),
        Message::Bye(body) => append_body(body, out),
        Message::Probe(body) => append_body(body, out),
        Message::ProbeReply(body) => append_body(body, out),
    };
    let size = out.len() - start;
    match result {
        Ok(()) if size <= MAX_DATAGRAM => Ok(()),
        Ok(()) => {
            out.truncate(start);
            Err(EncodeError::TooLarge { size })
        }
        Err(err) => {
            out.truncate(start);
            Err(err.into())
        }
    }
}

fn append_body<T: Serialize>(body: &T, out: &mut Vec<u8>) -> Result<(), postcard::Error> {
    let buf = std::mem::take(out);
    *out = postcard::to_extend(body, buf)?;
    Ok(())
}

/// Decodes a discovery datagram: header checks, then the body of the kind the header names.
/// `Data` and `Feedback` datagrams are [`DropReason::Unexpected`] here.
///
/// The domain is not checked here; see [`decode_for_domain`].
pub fn decode(bytes: &[u8]) -> Result<(Header, Message), DropReason> {
    let (header, body) = Header::parse(bytes)?;
    let message = match header.kind {
        MessageKind::Solicit => Message::Solicit(decode_body(body)?),
        MessageKind::Announce => Message::Announce(decode_body(body)?),
        MessageKind::Withdraw => Message::Withdraw(decode_body(body)?),
        MessageKind::Bye => Message::Bye(decode_body(body)?),
        MessageKind::Probe => Message::Probe(decode_body(body)?),
        MessageKind::ProbeReply => Message::ProbeReply(decode_body(body)?),
        // A signed envelope is opened by the engine first (see [`signed`]).
        MessageKind::Signed | MessageKind::Data | MessageKind::Feedback => {
            return Err(DropReason::Unexpected);
        }
    };
    Ok((header, message))
}

/// Decodes a datagram and rejects it unless it belongs to `domain`.
pub fn decode_for_domain(bytes: &[u8], domain: u16) -> Result<(Header, Message), DropReason> {
    let (header, _) = Header::parse(bytes)?;
    if header.domain != domain {
        return Err(DropReason::OtherDomain);
    }
    decode(bytes)
}

fn decode_body<'a, T: serde::Deserialize<'a>>(body: &'a [u8]) -> Result<T, DropReason> {
    match postcard::take_from_bytes::<T>(body) {
        Ok((value, [])) => Ok(value),
        Ok((_, _trailing)) => Err(DropReason::Malformed),
        Err(_) => Err(DropReason::Malformed),
    }
}

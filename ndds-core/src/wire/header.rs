//! The fixed 16-byte header that starts every ndds datagram.
//!
//! ```text
//!  0               4       5       6               8                              16
//!  +---------------+-------+-------+---------------+-------------------------------+
//!  | magic "NDDS"  |version| kind  | domain (u16le)|       sender id (u64le)       |
//!  +---------------+-------+-------+---------------+-------------------------------+
//! ```
//!
//! The header is a fixed layout, not postcard, so a receiver can reject foreign traffic, other
//! protocol versions and other domains by looking at 16 bytes, before any body is parsed.

use super::DropReason;

/// The four bytes every ndds datagram starts with.
pub const MAGIC: [u8; 4] = *b"NDDS";
/// The protocol version this implementation speaks. Datagrams of any other version are dropped.
pub const PROTOCOL_VERSION: u8 = 2;
/// Length of the fixed header in bytes.
pub const HEADER_LEN: usize = 16;

/// Kinds of datagram. The numeric values are part of the wire protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum MessageKind {
    /// A daemon asks every other daemon to announce itself (sent at start-up).
    Solicit = 1,
    /// A daemon announces itself and some or all of its local endpoints.
    Announce = 2,
    /// A daemon withdraws some of its endpoints.
    Withdraw = 3,
    /// A daemon leaves the domain: forget it and all of its endpoints.
    Bye = 4,
    /// A daemon checks that a node receives at the address it claims.
    Probe = 5,
    /// The answer to a `Probe`.
    ProbeReply = 6,
    /// Another discovery datagram, signed by its daemon's identity (domains with permissions).
    Signed = 7,
    /// Samples and stream control, sent by a producing process directly to a consuming one.
    Data = 16,
    /// Acknowledgements and repair requests from a consuming process to a producing one.
    Feedback = 17,
}

impl MessageKind {
    /// Every kind, in wire order.
    pub const ALL: [MessageKind; 9] = [
        MessageKind::Solicit,
        MessageKind::Announce,
        MessageKind::Withdraw,
        MessageKind::Bye,
        MessageKind::Probe,
        MessageKind::ProbeReply,
        MessageKind::Signed,
        MessageKind::Data,
        MessageKind::Feedback,
    ];

    /// The kind with this wire value, or `None` for a value this version does not know.
    pub fn from_u8(value: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|kind| *kind as u8 == value)
    }

    /// The name used in logs and in `docs/protocol.md`.
    pub fn name(self) -> &'static str {
        match self {
            MessageKind::Solicit => "Solicit",
            MessageKind::Announce => "Announce",
            MessageKind::Withdraw => "Withdraw",
            MessageKind::Bye => "Bye",
            MessageKind::Probe => "Probe",
            MessageKind::ProbeReply => "ProbeReply",
            MessageKind::Signed => "Signed",
            MessageKind::Data => "Data",
            MessageKind::Feedback => "Feedback",
        }
    }
}

/// A validated datagram header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// What the body holds.
    pub kind: MessageKind,
    /// The domain the sender belongs to.
    pub domain: u16,
    /// Daemon node id (discovery messages) or participant id (data messages).
    pub sender: u64,
}

impl Header {
    /// Appends the 16 header bytes to `out`.
    pub fn emit(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&MAGIC);
        out.push(PROTOCOL_VERSION);
        out.push(self.kind as u8);
        out.extend_from_slice(&self.domain.to_le_bytes());
        out.extend_from_slice(&self.sender.to_le_bytes());
    }

    /// Parses the header at the start of `bytes`, returning it and the body that follows.
    ///
    /// Never panics: every index is checked against the length first.
    pub fn parse(bytes: &[u8]) -> Result<(Header, &[u8]), DropReason> {
        let Some((head, body)) = bytes.split_first_chunk::<HEADER_LEN>() else {
            return Err(if bytes.len() >= 4 && bytes[..4] != MAGIC {
                DropReason::ForeignMagic
            } else {
                DropReason::Truncated
            });
        };
        if head[..4] != MAGIC {
            return Err(DropReason::ForeignMagic);
        }
        if head[4] != PROTOCOL_VERSION {
            return Err(DropReason::UnsupportedVersion);
        }
        let kind = MessageKind::from_u8(head[5]).ok_or(DropReason::UnknownKind)?;
        let domain = u16::from_le_bytes([head[6], head[7]]);
        let mut sender = [0u8; 8];
        sender.copy_from_slice(&head[8..16]);
        let header = Header {
            kind,
            domain,
            sender: u64::from_le_bytes(sender),
        };
        Ok((header, body))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trips_and_has_fixed_layout() {
        let header = Header {
            kind: MessageKind::Announce,
            domain: 0x0102,
            sender: 0x1122_3344_5566_7788,
        };
        let mut bytes = Vec::new();
        header.emit(&mut bytes);
        assert_eq!(bytes.len(), HEADER_LEN);
        assert_eq!(&bytes[..4], b"NDDS");
        assert_eq!(bytes[4], PROTOCOL_VERSION);
        assert_eq!(bytes[5], 2);
        assert_eq!(&bytes[6..8], &[0x02, 0x01]);
        assert_eq!(bytes[8], 0x88);
        bytes.extend_from_slice(b"body");
        let (parsed, body) = Header::parse(&bytes).unwrap();
        assert_eq!(parsed, header);
        assert_eq!(body, b"body");
    }

    #[test]
    fn foreign_and_short_datagrams_are_classified() {
        assert_eq!(Header::parse(b"ND"), Err(DropReason::Truncated));
        assert_eq!(
            Header::parse(b"RTPS\x02\x01"),
            Err(DropReason::ForeignMagic)
        );
        let mut other_version = Vec::new();
        Header {
            kind: MessageKind::Bye,
            domain: 0,
            sender: 1,
        }
        .emit(&mut other_version);
        other_version[4] = 9;
        assert_eq!(
            Header::parse(&other_version),
            Err(DropReason::UnsupportedVersion)
        );
        other_version[4] = PROTOCOL_VERSION;
        other_version[5] = 200;
        assert_eq!(Header::parse(&other_version), Err(DropReason::UnknownKind));
    }
}

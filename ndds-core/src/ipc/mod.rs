//! Frames between a client (or tool) and its local daemon over the daemon's Unix socket.
//!
//! Each frame is a 4-byte big-endian length followed by that many bytes of postcard: a
//! [`ClientMessage`] from client to daemon, a [`DaemonMessage`] from daemon to client. The
//! first frame of a connection is [`ClientMessage::Hello`]; the daemon answers
//! [`DaemonMessage::Welcome`] and the session is open, or [`DaemonMessage::Refused`] and closes
//! the connection. A frame longer than
//! [`MAX_FRAME`], or one that does not decode, ends the connection with a logged reason.

pub mod client;
pub mod daemon;
pub mod graph;

pub use client::{ClientMessage, EndpointDecl, Hello, Role};
pub use daemon::{DaemonMessage, Welcome};
pub use graph::{ClientSummary, EndpointSummary, Graph, NodeSummary, PeerSummary};

/// Version of the frames in this module; client and daemon must agree. Version 2 added the
/// unicast discovery fields of [`NodeSummary`] (`peers`, `multicast_seen_ms`, `unicast_copies`);
/// version 3 the kernel's uid of each client in [`ClientSummary`]; version 4 the messages of
/// domains with permissions (`NotPermitted`, `PairKeys`, identities in [`NodeSummary`]);
/// version 5 participant ids chosen by the daemon ([`Welcome::participant`]).
pub const IPC_VERSION: u16 = 5;

/// Largest frame either side sends or accepts, in bytes.
pub const MAX_FRAME: usize = 16 * 1024 * 1024;

/// Length of the frame length prefix.
pub const FRAME_PREFIX: usize = 4;

/// Encodes one frame (length prefix and body) of `message`.
pub fn encode_frame<T: serde::Serialize>(message: &T) -> Result<Vec<u8>, FrameError> {
    let mut frame = vec![0u8; FRAME_PREFIX];
    frame = postcard::to_extend(message, frame)?;
    let len = frame.len() - FRAME_PREFIX;
    if len > MAX_FRAME {
        return Err(FrameError::TooLarge(len));
    }
    frame[..FRAME_PREFIX].copy_from_slice(&(len as u32).to_be_bytes());
    Ok(frame)
}

/// Encodes one frame body (without the length prefix), for codecs that add the prefix.
pub fn encode_body<T: serde::Serialize>(message: &T) -> Result<Vec<u8>, FrameError> {
    let body = postcard::to_allocvec(message)?;
    if body.len() > MAX_FRAME {
        return Err(FrameError::TooLarge(body.len()));
    }
    Ok(body)
}

/// Decodes one frame body (without its length prefix).
pub fn decode_body<'a, T: serde::Deserialize<'a>>(body: &'a [u8]) -> Result<T, FrameError> {
    match postcard::take_from_bytes(body)? {
        (value, []) => Ok(value),
        (_, rest) => Err(FrameError::Trailing(rest.len())),
    }
}

/// A frame that cannot be sent or was not understood.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// postcard could not encode or decode the body.
    #[error("frame body: {0}")]
    Postcard(#[from] postcard::Error),
    /// Bytes left over after the body.
    #[error("{0} bytes left over after the frame body")]
    Trailing(usize),
    /// Longer than [`MAX_FRAME`].
    #[error("frame of {0} bytes exceeds the {MAX_FRAME}-byte limit")]
    TooLarge(usize),
}

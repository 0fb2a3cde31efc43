//! One client or tool connection on the Unix socket.
//!
//! The task reads length-delimited postcard frames and forwards them to the driver, and writes
//! the frames the driver queues for it. The first frame must be `Hello`; anything that does not
//! decode ends the connection with a logged reason. The driver is told when the connection
//! ends, whatever the cause, so the client's endpoints are withdrawn at once.
//!
//! Frames are read with [`FrameCodec`]: a length prefix over [`ipc::MAX_FRAME`] ends the
//! connection, and a frame's buffer grows with the bytes that arrive, so a client that claims
//! 16 MiB and sends 4 bytes holds 4 bytes of the daemon's memory, not 16 MiB.

use bytes::{Buf as _, BufMut as _, Bytes, BytesMut};
use futures_util::{SinkExt, StreamExt};
use ndds_core::ipc::{self, ClientMessage, DaemonMessage};
use tokio::net::UnixStream;
use tokio::sync::mpsc;
use tokio_util::codec::{Decoder, Encoder, FramedRead, FramedWrite};
use tokio_util::sync::CancellationToken;

use std::sync::Arc;
use std::sync::atomic::Ordering;

use crate::driver::{ClientId, Counters, Input};
use crate::local::PeerCred;

/// Largest frame a client may send: its largest message is a declaration, whose type
/// description fits one datagram. (Frames to clients may reach [`ipc::MAX_FRAME`].)
pub const MAX_CLIENT_FRAME: usize = 1 << 20;

/// Frames the driver may queue for one client before the client counts as not reading.
pub const OUTBOX: usize = 4096;
/// How long the frames left after a session ends may take to write.
const DRAIN_TIMEOUT: std::time::Duration = std::time::Duration::from_millis(500);

/// The codec of the Unix-socket protocol: 4-byte big-endian length, then the body.
///
/// Unlike `tokio_util`'s `LengthDelimitedCodec`, decoding never reserves the length a prefix
/// claims: the read buffer grows only as bytes arrive.
#[derive(Clone, Copy, Debug)]
pub struct FrameCodec {
    /// Longest frame decoded; longer ones are errors.
    pub max: usize,
}

impl Default for FrameCodec {
    fn default() -> Self {
        FrameCodec {
            max: ipc::MAX_FRAME,
        }
    }
}

impl Decoder for FrameCodec {
    type Item = BytesMut;
    type Error = std::io::Error;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<BytesMut>, Self::Error> {
        let Some(prefix) = src.get(..ipc::FRAME_PREFIX) else {
            return Ok(None);
        };
        let len = u32::from_be_bytes(prefix.try_into().expect("4-byte prefix")) as usize;
        if len > self.max {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("frame of {len} bytes exceeds the {} byte limit", self.max),
            ));
        }
        if src.len() < ipc::FRAME_PREFIX + len {
            return Ok(None);
        }
        src.advance(ipc::FRAME_PREFIX);
        Ok(Some(src.split_to(len)))
    }
}

impl Encoder<Bytes> for FrameCodec {
    type Error = std::io::Error;

    fn encode(&mut self, body: Bytes, dst: &mut BytesMut) -> Result<(), Self::Error> {
        let len = u32::try_from(body.len())
            .ok()
            .filter(|len| *len as usize <= ipc::MAX_FRAME)
            .ok_or_else(|| {
                std::io::Error::new(std::io::ErrorKind::InvalidInput, "frame too large")
            })?;
        dst.reserve(ipc::FRAME_PREFIX + body.len());
        dst.put_u32(len);
        dst.extend_from_slice(&body);
        Ok(())
    }
}

/// What the driver holds to talk to a connection.
#[derive(Debug)]
pub struct ClientLink {
    /// Frames to write.
    pub outbox: mpsc::Sender<DaemonMessage>,
    /// Cancelled by the driver to drop the connection.
    pub cancel: CancellationToken,
}

/// Serves one connection until it closes, the driver drops it, or the daemon stops.
pub async fn serve(
    stream: UnixStream,
    client: ClientId,
    cred: PeerCred,
    inputs: mpsc::Sender<Input>,
    cancel: CancellationToken,
    counters: Arc<Counters>,
) {
    let (read_half, write_half) = stream.into_split();
    let mut reader = FramedRead::new(
        read_half,
        FrameCodec {
            max: MAX_CLIENT_FRAME,
        },
    );
    let mut writer = FramedWrite::new(write_half, FrameCodec::default());
    let (outbox, mut pending) = mpsc::channel(OUTBOX);
    let link = ClientLink {
        outbox,
        cancel: cancel.clone(),
    };
    if inputs
        .send(Input::Opened { client, link, cred })
        .await
        .is_err()
    {
        return;
    }
    let reason = loop {
        tokio::select! {
            () = cancel.cancelled() => break "dropped by the daemon".to_owned(),
            frame = reader.next() => match frame {
                None => break "connection closed".to_owned(),
                Some(Err(err)) => {
                    counters.protocol_errors.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!(client, %err, "bad frame from client; disconnecting");
                    break format!("framing error: {err}");
                }
                Some(Ok(bytes)) => match ipc::decode_body::<ClientMessage>(&bytes) {
                    Ok(message) => {
                        if inputs.send(Input::Frame { client, message }).await.is_err() {
                            break "daemon stopping".to_owned();
                        }
                    }
                    Err(err) => {
                        counters.protocol_errors.fetch_add(1, Ordering::Relaxed);
                        tracing::warn!(client, %err, "client sent an undecodable frame; disconnecting");
                        break format!("undecodable frame: {err}");
                    }
                },
            },
            message = pending.recv() => match message {
                None => break "session ended by the daemon".to_owned(),
                Some(message) => {
                    // A client that stops reading must not hold this task: the daemon's
                    // cancellation interrupts a blocked write.
                    let written = tokio::select! {
                        () = cancel.cancelled() => Err("dropped by the daemon".to_owned()),
                        written = write_frame(&mut writer, &message) => written,
                    };
                    if let Err(reason) = written {
                        break reason;
                    }
                }
            },
        }
    };
    // Whatever the daemon queued before ending the session normally (e.g. `Refused`) is still
    // sent, briefly; a dropped client gets nothing more.
    if !cancel.is_cancelled() {
        let drain = async {
            while let Ok(message) = pending.try_recv() {
                if write_frame(&mut writer, &message).await.is_err() {
                    break;
                }
            }
        };
        let _ = tokio::time::timeout(DRAIN_TIMEOUT, drain).await;
    }
    tracing::debug!(client, %reason, "client connection ended");
    let _ = inputs.send(Input::Closed { client, reason }).await;
}

async fn write_frame(
    writer: &mut FramedWrite<tokio::net::unix::OwnedWriteHalf, FrameCodec>,
    message: &DaemonMessage,
) -> Result<(), String> {
    let body = ipc::encode_body(message).map_err(|err| format!("cannot encode: {err}"))?;
    writer
        .send(Bytes::from(body))
        .await
        .map_err(|err| format!("write failed: {err}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_claimed_length_reserves_nothing_until_bytes_arrive() {
        let mut codec = FrameCodec::default();
        let mut buf = BytesMut::new();
        buf.extend_from_slice(&(ipc::MAX_FRAME as u32).to_be_bytes());
        buf.extend_from_slice(b"abcd");
        assert!(codec.decode(&mut buf).unwrap().is_none());
        assert!(
            buf.capacity() < 4096,
            "capacity {} after a 16 MiB claim",
            buf.capacity()
        );
    }

    #[test]
    fn frames_round_trip_and_oversized_claims_are_errors() {
        let mut codec = FrameCodec::default();
        let mut buf = BytesMut::new();
        codec
            .encode(Bytes::from_static(b"hello"), &mut buf)
            .unwrap();
        codec.encode(Bytes::from_static(b""), &mut buf).unwrap();
        assert_eq!(&codec.decode(&mut buf).unwrap().unwrap()[..], b"hello");
        assert_eq!(&codec.decode(&mut buf).unwrap().unwrap()[..], b"");
        assert!(codec.decode(&mut buf).unwrap().is_none());
        buf.extend_from_slice(&(ipc::MAX_FRAME as u32 + 1).to_be_bytes());
        let err = codec.decode(&mut buf).unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::InvalidData);
        // A client's frames are held to a far smaller limit.
        let mut client = FrameCodec {
            max: MAX_CLIENT_FRAME,
        };
        let mut buf = BytesMut::new();
        buf.extend_from_slice(&(MAX_CLIENT_FRAME as u32 + 1).to_be_bytes());
        assert!(client.decode(&mut buf).is_err());
    }
}

//! One client or tool connection on the Unix socket.
//!
//! The task reads length-delimited postcard frames and forwards them to the driver, and writes
//! the frames the driver queues for it. The first frame must be `Hello`; anything that does not
//! decode ends the connection with a logged reason. The driver is told when the connection
//! ends, whatever the cause, so the client's endpoints are withdrawn at once.

use futures_util::{SinkExt, StreamExt};
use ndds_core::ipc::{self, ClientMessage, DaemonMessage};
use tokio::net::UnixStream;
use tokio::sync::mpsc;
use tokio_util::codec::{FramedRead, FramedWrite, LengthDelimitedCodec};
use tokio_util::sync::CancellationToken;

use std::sync::Arc;
use std::sync::atomic::Ordering;

use crate::driver::{ClientId, Counters, Input};

/// Frames the driver may queue for one client before the client counts as not reading.
pub const OUTBOX: usize = 4096;
/// How long the frames left after a session ends may take to write.
const DRAIN_TIMEOUT: std::time::Duration = std::time::Duration::from_millis(500);

/// The codec of the Unix-socket protocol: 4-byte big-endian length, then the body.
pub fn codec() -> LengthDelimitedCodec {
    LengthDelimitedCodec::builder()
        .length_field_length(ipc::FRAME_PREFIX)
        .big_endian()
        .max_frame_length(ipc::MAX_FRAME)
        .new_codec()
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
    inputs: mpsc::Sender<Input>,
    cancel: CancellationToken,
    counters: Arc<Counters>,
) {
    let (read_half, write_half) = stream.into_split();
    let mut reader = FramedRead::new(read_half, codec());
    let mut writer = FramedWrite::new(write_half, codec());
    let (outbox, mut pending) = mpsc::channel(OUTBOX);
    let link = ClientLink {
        outbox,
        cancel: cancel.clone(),
    };
    if inputs.send(Input::Opened { client, link }).await.is_err() {
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
    writer: &mut FramedWrite<tokio::net::unix::OwnedWriteHalf, LengthDelimitedCodec>,
    message: &DaemonMessage,
) -> Result<(), String> {
    let body = ipc::encode_body(message).map_err(|err| format!("cannot encode: {err}"))?;
    writer
        .send(bytes::Bytes::from(body))
        .await
        .map_err(|err| format!("write failed: {err}"))
}

//! Errors of the SDK, one enum per operation.

use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use ndds_core::types::TypeDescription;
use ndds_core::wire::Guid;

/// [`crate::Participant::connect`] failed.
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    /// No daemon answers on the socket and the embedded fallback is disabled.
    #[error(
        "no ndds daemon at {path} ({reason}); start `ndds-daemon`, set NDDS_SOCKET, or allow the embedded daemon"
    )]
    NoDaemon {
        /// The socket path tried.
        path: PathBuf,
        /// The OS error.
        reason: String,
    },
    /// The daemon refused the session.
    #[error("the daemon at {path} refused the session: {reason}")]
    Refused {
        /// The socket path.
        path: PathBuf,
        /// Its reason.
        reason: String,
    },
    /// The daemon did not complete the handshake.
    #[error("handshake with the daemon at {path} failed: {reason}")]
    Handshake {
        /// The socket path.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// The embedded daemon could not start.
    #[error("cannot start the embedded daemon: {0}")]
    Embedded(#[from] ndds_daemon::EmbedError),
    /// The data socket could not be opened.
    #[error("cannot open the data socket on {interface}: {source}")]
    DataSocket {
        /// The interface address.
        interface: std::net::Ipv4Addr,
        /// The OS error.
        source: std::io::Error,
    },
    /// A setting (environment variable or builder value) is invalid.
    #[error("invalid setting: {0}")]
    Setting(String),
    /// The domain's key file (`NDDS_KEY_FILE` or [`crate::ParticipantBuilder::key_file`])
    /// cannot be used: unreadable, readable by others, or not a key file.
    #[error(transparent)]
    KeyFile(#[from] ndds_daemon::keys::KeyError),
    /// The socket is not safe to use: the daemon at it runs as another user (not root), so
    /// it may be a squatter's.
    #[error(transparent)]
    Socket(#[from] ndds_daemon::local::LocalError),
    /// A helper thread could not be started.
    #[error("cannot start a participant thread: {0}")]
    Thread(std::io::Error),
    /// The process is exiting: its embedded daemons were stopped and no new one starts.
    #[error("the process is exiting: no embedded daemon can start")]
    Exiting,
}

/// Declaring a producer or consumer failed.
#[derive(Debug, thiserror::Error)]
pub enum DeclareError {
    /// The daemon rejected the declaration.
    #[error("the daemon rejected {topic:?}: {reason}")]
    Rejected {
        /// The topic.
        topic: String,
        /// The daemon's reason.
        reason: String,
    },
    /// The connection to the daemon is gone.
    #[error("the connection to the daemon is closed")]
    Disconnected,
    /// The daemon did not answer in time.
    #[error("the daemon did not answer the declaration of {0:?} in time")]
    Timeout(String),
}

/// Writing a sample failed.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The value could not be serialized.
    #[error("cannot serialize the sample: {0}")]
    Serialize(#[from] postcard::Error),
    /// The encoded sample does not fit in one datagram.
    #[error("encoded sample of {size} bytes exceeds the {max}-byte limit of one datagram")]
    TooLarge {
        /// Size of the encoded sample.
        size: usize,
        /// The largest encoded sample that is accepted.
        max: usize,
    },
    /// A reliable producer's flow-control window stayed closed for its whole write timeout:
    /// its slowest reliable consumer has not taken (and acknowledged) the samples written
    /// before. Nothing was sent; the sample can be written again later. A write from a direct
    /// callback (on the participant's I/O thread) fails so at once, without waiting.
    #[error(
        "reliable write blocked for {waited:?}: the slowest reliable consumer has {unacknowledged} samples not yet acknowledged"
    )]
    WouldBlock {
        /// How long the write waited.
        waited: std::time::Duration,
        /// Samples written but not acknowledged by every reliable consumer.
        unacknowledged: usize,
    },
    /// Sending failed for every destination; the last OS error.
    #[error("send failed: {0}")]
    Io(#[from] std::io::Error),
}

/// Receiving a sample failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RecvError {
    /// `try_recv`: nothing queued.
    #[error("no sample available")]
    Empty,
    /// `recv_timeout`: nothing arrived in time.
    #[error("timed out waiting for a sample")]
    Timeout,
    /// `recv_timeout` / `recv_raw_timeout`: nothing arrived in time, and producers of the topic
    /// exist that this consumer is not matched with (another type, or best effort for a
    /// reliable consumer), the likely reason. (The event forms deliver the same facts as
    /// [`crate::Notification::Incompatible`] events and time out with [`RecvError::Timeout`].)
    #[error("{0}")]
    TimeoutUnmatched(Box<Unmatched>),
    /// The consumer's queue lost its sender. A consumer keeps its own queue open, so this
    /// is not produced while the consumer exists; it is the answer of a queue torn down
    /// around a waiting reader. (A lost daemon does not close consumers: samples keep flowing
    /// from the producers already known.)
    #[error("the consumer's queue is closed")]
    Closed,
    /// The operation belongs to the other consumer mode (`recv`, streams and callbacks are for
    /// immediate consumers, `poll` for polled ones).
    #[error("the consumer is in {0:?} mode")]
    WrongMode(crate::qos::ConsumerMode),
    /// A callback thread could not be started.
    #[error("cannot start the callback thread: {0}")]
    Thread(String),
}

impl RecvError {
    /// True for both timeouts ([`RecvError::Timeout`], [`RecvError::TimeoutUnmatched`]).
    pub fn is_timeout(&self) -> bool {
        matches!(self, RecvError::Timeout | RecvError::TimeoutUnmatched(_))
    }
}

/// A consumer timed out while producers of its topic were not matched with it: see
/// [`RecvError::TimeoutUnmatched`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unmatched {
    /// The consumer's topic.
    pub topic: String,
    /// How long it waited.
    pub waited: Duration,
    /// The producers not matched, and why.
    pub producers: Vec<UnmatchedProducer>,
}

/// A producer a consumer is not matched with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnmatchedProducer {
    /// The producer.
    pub writer: Guid,
    /// Its process id.
    pub pid: u32,
    /// Its process name.
    pub process: String,
    /// Why they do not match.
    pub mismatch: Mismatch,
}

/// Why a producer and a consumer of one topic do not match.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Mismatch {
    /// Their types differ (name or shape: the struct's name is part of its type).
    Type {
        /// The consumer's type.
        consumer: TypeDescription,
        /// The producer's type.
        producer: TypeDescription,
    },
    /// The consumer requests reliability; the producer is best-effort.
    Reliability,
}

impl fmt::Display for Unmatched {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let count = self.producers.len();
        write!(
            f,
            "timed out after {} waiting for a sample on `{}`: {count} producer{} not matched: ",
            Seconds(self.waited),
            self.topic,
            if count == 1 { "" } else { "s" }
        )?;
        for (i, producer) in self.producers.iter().enumerate() {
            if i > 0 {
                f.write_str("; ")?;
            }
            write!(f, "{producer}")?;
        }
        Ok(())
    }
}

impl fmt::Display for UnmatchedProducer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (process, pid) = (&self.process, self.pid);
        match &self.mismatch {
            Mismatch::Type { consumer, producer } => write!(
                f,
                "type {} vs {} (this consumer's, then the producer's, in {process} pid {pid})",
                consumer.shape(),
                producer.shape()
            ),
            Mismatch::Reliability => write!(
                f,
                "the producer is best-effort, this consumer requests reliable (producer in \
                 {process} pid {pid})"
            ),
        }
    }
}

/// A duration as messages write it: `1 s`, `1.5 s`, `200 ms`.
struct Seconds(Duration);

impl fmt::Display for Seconds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let duration = self.0;
        if duration >= Duration::from_secs(1) {
            let secs = duration.as_secs_f64();
            if duration.subsec_millis() == 0 {
                write!(f, "{} s", duration.as_secs())
            } else {
                write!(f, "{secs:.1} s")
            }
        } else {
            write!(f, "{} ms", duration.as_millis())
        }
    }
}

/// A query to the daemon failed.
#[derive(Debug, thiserror::Error)]
pub enum QueryError {
    /// The connection to the daemon is gone.
    #[error("the connection to the daemon is closed")]
    Disconnected,
    /// The daemon did not answer in time.
    #[error("the daemon did not answer in time")]
    Timeout,
}

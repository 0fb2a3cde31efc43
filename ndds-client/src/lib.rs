//! # ndds-client
//!
//! The SDK that control programs link: typed producers and consumers of named topics, with
//! samples sent directly from producing to consuming processes over UDP, and discovery handled
//! by the host's `ndds-daemon` (or an embedded one when none runs); and, on top of topics,
//! ports: named channels with one owner and any number of users.
//!
//! ```no_run
//! use std::time::Duration;
//! use ndds_client::{ConsumerQos, Participant, ProducerQos};
//! use serde::{Deserialize, Serialize};
//!
//! #[derive(Serialize, Deserialize, Debug)]
//! struct Pose { x: f64, y: f64 }
//!
//! let participant = Participant::connect()?;   // local daemon, else an embedded one
//! let producer = participant.producer::<Pose>("arm/pose", ProducerQos::default())?;
//! let consumer = participant.consumer::<Pose>("arm/pose", ConsumerQos::default())?;
//! producer.wait_for_consumers(1, Duration::from_secs(1));
//! producer.write(&Pose { x: 1.0, y: 2.0 })?;
//! let sample = consumer.recv_timeout(Duration::from_secs(1))?;
//! println!("{:?} from {}", sample.value, sample.info.writer);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Any `T: Serialize + DeserializeOwned` can be a sample type. Its structure is traced with
//! serde-reflection and announced with the endpoint, so producers and consumers of different
//! types never match (both sides log an *incompatible type* warning) and tools such as
//! `ndds echo` decode the topic without the Rust type.
//!
//! ## What it does not do
//! - Protocol logic: the wire format, type descriptions, the discovery engine and the whole
//!   data plane (arbitration with strength, persistence, minimum separation and deadlines;
//!   reliable streams; batching; fragments; who is believed) are `ndds-core`'s, without IO;
//!   this crate drives them with a socket, two threads and the clock.
//! - Discovery: the host's daemon (`ndds-daemon`) runs it; the SDK asks the daemon over a
//!   Unix socket, or embeds one when none answers.
//! - ControlShell: CSMats, sample modules, habitats, configurations, state machines and
//!   description files are in `ndds-runtime` (which builds on this crate), the component
//!   library in `ndds-components`; neither is a dependency of the SDK.
//!
//! ## Layout
//! - [`participant`]: connecting, the embedded-daemon fallback, declaring endpoints;
//!   [`embedded`]: the daemons this process embeds, and stopping them.
//! - [`producer`], [`consumer`]: the endpoint handles; [`sample`]: what consumers receive;
//!   [`qos`]: what endpoints are declared with; [`error`]: one error enum per operation.
//! - [`ports`]: port-directed communication over reliable topics (send, receive and reply;
//!   query and response; `waitfor`; `sendall`; a priority select).
//! - Internal: `session` (the daemon connection) and `daemon_link` (its reader thread, which
//!   also reconnects); `local_endpoints` (the local endpoints by entity number, updated by the
//!   daemon's match events) and `matches` (what each one is matched or incompatible with);
//!   `data_plane` (the driver of the data plane: the UDP socket and the I/O thread around
//!   `ndds_core::participant::ParticipantCore`, which holds every endpoint's protocol state);
//!   `consumer::delivery` (a consumer's queue, latest-value cell or direct callback) and
//!   `consumer::dispatch` (the participant's one callback thread); `sync` (lock helpers).
#![warn(missing_docs)]

pub mod consumer;
mod daemon_link;
mod data_plane;
pub mod embedded;
pub mod error;
mod local_endpoints;
mod matches;
pub mod participant;
pub mod ports;
pub mod producer;
pub mod qos;
pub mod sample;
mod session;
mod sync;

pub use consumer::{
    CallbackConsumer, Consumer, ConsumerStats, DirectConsumer, EventStream, RawConsumer,
    SampleStream,
};
pub use daemon_link::RECONNECT_GRACE;
pub use data_plane::{DEFAULT_MAX_SAMPLE, ParticipantStats};
pub use embedded::{stop_embedded_daemon, stop_embedded_daemons};
pub use error::{
    ConnectError, DeclareError, Mismatch, QueryError, RecvError, Unmatched, UnmatchedProducer,
    WriteError,
};
pub use ndds_core::discovery::Incompatibility;
pub use ndds_core::ipc::Graph;
pub use ndds_core::types::TypeDescription;
pub use ndds_core::wire::{EndpointInfo, Guid};
pub use ndds_daemon::DaemonConfig;
pub use participant::{EmbeddedPolicy, Participant, ParticipantBuilder};
pub use producer::{Producer, RawProducer};
pub use qos::{Batching, ConsumerMode, ConsumerQos, ProducerQos, Reliability, WhenFull};
pub use sample::{
    Event, Notification, PollStatus, Polled, RawEvent, RawSample, Sample, SampleInfo, SampleStatus,
};

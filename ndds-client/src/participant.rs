//! The participant: one process's session with its local daemon, its data socket, and the
//! producers and consumers declared through it.
//!
//! Two threads serve a participant: the *session* thread reads the daemon's frames (match
//! events and answers) and the *data* thread receives samples. Neither keeps the participant
//! alive: when the last handle ([`Participant`], producers, consumers) is dropped, the session
//! is closed, the daemon withdraws every endpoint at once, and both threads end. In a sealed
//! domain whose keys came from a file, a third thread looks at that file every second and puts
//! a rotation step in force.

use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use ndds_core::domain;
use ndds_core::ipc::{ClientMessage, EndpointDecl, Graph, Hello, IPC_VERSION, Role, Welcome};
use ndds_core::participant::ConsumerSpec;
use ndds_core::reliability::ReaderConfig;
use ndds_core::seal::{Keyring, SealMode};
use ndds_core::types::TypeDescription;
use ndds_core::wire::{EndpointQos, Reliability};
use ndds_daemon::{DaemonConfig, DaemonError, EmbedError};
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::consumer::{Consumer, ConsumerState, Delivery, Dispatcher, RawConsumer};
use crate::daemon_link;
use crate::data_plane::{DataPlane, Limits, ParticipantStats};
use crate::embedded::{self, Ensured};
use crate::error::{ConnectError, DeclareError, QueryError};
use crate::local_endpoints::{Endpoint, LocalEndpoints};
use crate::producer::{Producer, ProducerState, RawProducer};
use crate::qos::{ConsumerMode, ConsumerQos, ProducerQos};
use crate::session::{self, Session, Takeover};
use crate::sync::lock;

/// Whether a participant may start a daemon inside its own process.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum EmbeddedPolicy {
    /// Connect to the local daemon; if none answers, start an embedded one (default).
    #[default]
    Auto,
    /// Only ever connect to a running daemon.
    Never,
    /// Always start an embedded daemon (fails if another daemon owns the socket).
    Always,
}

impl std::str::FromStr for EmbeddedPolicy {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        match text.trim().to_ascii_lowercase().as_str() {
            "auto" | "" => Ok(EmbeddedPolicy::Auto),
            "never" | "no" | "0" | "false" => Ok(EmbeddedPolicy::Never),
            "always" | "yes" | "1" | "true" => Ok(EmbeddedPolicy::Always),
            other => Err(format!(
                "embedded daemon policy {other:?} is not one of auto, never, always"
            )),
        }
    }
}

/// Options of [`Participant::connect`]; see each setter for its environment variable.
#[derive(Clone, Debug, Default)]
pub struct ParticipantBuilder {
    domain: Option<u16>,
    socket: Option<PathBuf>,
    embedded: Option<EmbeddedPolicy>,
    embedded_config: Option<DaemonConfig>,
    name: Option<String>,
    role: Option<Role>,
    max_sample: Option<usize>,
    recv_buffer: Option<usize>,
    key_file: Option<PathBuf>,
    integrity_only: bool,
}

/// Smallest accepted [`ParticipantBuilder::max_sample_size`].
const MIN_MAX_SAMPLE: usize = 1024;
/// Largest accepted [`ParticipantBuilder::max_sample_size`] (a fragment's `total_len` is a
/// `u32`).
const MAX_MAX_SAMPLE: usize = u32::MAX as usize;

impl ParticipantBuilder {
    /// Domain id (default: `NDDS_DOMAIN`, else 0).
    pub fn domain(mut self, domain: u16) -> Self {
        self.domain = Some(domain);
        self
    }

    /// Daemon socket path (default: `NDDS_SOCKET`, else the domain's default path).
    pub fn socket(mut self, path: impl Into<PathBuf>) -> Self {
        self.socket = Some(path.into());
        self
    }

    /// Embedded-daemon policy (default: `NDDS_EMBEDDED` = auto | never | always, else auto).
    pub fn embedded(mut self, policy: EmbeddedPolicy) -> Self {
        self.embedded = Some(policy);
        self
    }

    /// Configuration of the embedded daemon, if one is started (default: the domain's
    /// defaults on loopback). Its domain and socket override [`Self::domain`] and
    /// [`Self::socket`].
    pub fn embedded_config(mut self, config: DaemonConfig) -> Self {
        self.embedded_config = Some(config);
        self
    }

    /// Process name shown by `ndds nodes` (default: the executable's name).
    pub fn name(mut self, name: impl Into<String>) -> Self {
        self.name = Some(name.into());
        self
    }

    /// Largest sample, in encoded bytes, this participant's producers write and its consumers
    /// accept (default: `NDDS_MAX_SAMPLE`, else [`crate::DEFAULT_MAX_SAMPLE`], 16 MiB). Larger
    /// writes fail with [`crate::WriteError::TooLarge`]; larger incoming samples are refused
    /// and counted. Up to four samples of this size may be held in reassembly at once. Accepted
    /// range: 1 KiB to 4 GiB − 1.
    pub fn max_sample_size(mut self, bytes: usize) -> Self {
        self.max_sample = Some(bytes);
        self
    }

    /// Bytes of the data socket's receive buffer asked of the kernel (default:
    /// `NDDS_RECV_BUFFER`, else 8 MiB). Datagrams that arrive while the participant's
    /// receive thread is not scheduled wait there; when it is full they are lost (a best-effort
    /// gap, a reliable repair). The kernel grants at most `net.core.rmem_max` unless the
    /// process has `CAP_NET_ADMIN`; a larger ask that is not granted is logged as a warning.
    /// A recorder of fast topics asks for more (`ndds record` asks for 64 MiB).
    pub fn receive_buffer(mut self, bytes: usize) -> Self {
        self.recv_buffer = Some(bytes);
        self
    }

    /// The domain's key file (default: `NDDS_KEY_FILE`, else none: an open domain). With a
    /// key, every datagram this participant sends is sealed and only sealed ones are
    /// accepted; an embedded daemon gets the key too. See `docs/security.md`.
    pub fn key_file(mut self, path: impl Into<PathBuf>) -> Self {
        self.key_file = Some(path.into());
        self
    }

    /// With a key: authenticate datagrams without encrypting them (they stay readable on the
    /// wire).
    pub fn integrity_only(mut self, integrity_only: bool) -> Self {
        self.integrity_only = integrity_only;
        self
    }

    /// Connect as a tool (listed apart from control programs).
    pub fn tool(mut self) -> Self {
        self.role = Some(Role::Tool);
        self
    }

    /// Connects to the local daemon, or starts an embedded one as the policy allows.
    pub fn connect(self) -> Result<Participant, ConnectError> {
        let settings = self.resolve()?;
        Participant::open(settings)
    }

    fn resolve(self) -> Result<Settings, ConnectError> {
        let env = |name: &str| std::env::var(name).ok().filter(|v| !v.is_empty());
        let domain = match (
            self.embedded_config.as_ref(),
            self.domain,
            env("NDDS_DOMAIN"),
        ) {
            (Some(config), _, _) => config.domain,
            (None, Some(domain), _) => domain,
            (None, None, Some(text)) => {
                let value: u32 = text.parse().map_err(|_| {
                    ConnectError::Setting(format!("NDDS_DOMAIN={text:?} is not a number"))
                })?;
                domain::check(value).map_err(|err| ConnectError::Setting(err.to_string()))?
            }
            (None, None, None) => 0,
        };
        let socket = match (
            self.embedded_config.as_ref(),
            self.socket,
            env("NDDS_SOCKET"),
        ) {
            (Some(config), _, _) => config.socket.clone(),
            (None, Some(path), _) => path,
            (None, None, Some(path)) => PathBuf::from(path),
            (None, None, None) => ndds_daemon::local::locate(domain),
        };
        let embedded = match (self.embedded, env("NDDS_EMBEDDED")) {
            (Some(policy), _) => policy,
            (None, Some(text)) => text
                .parse()
                .map_err(|err: String| ConnectError::Setting(format!("NDDS_EMBEDDED: {err}")))?,
            (None, None) => EmbeddedPolicy::Auto,
        };
        let key_file = self
            .key_file
            .or_else(|| env("NDDS_KEY_FILE").map(PathBuf::from));
        let key = match &key_file {
            Some(path) => Some(ndds_daemon::keys::load(path)?),
            None => None,
        };
        let seal_mode = if self.integrity_only {
            SealMode::IntegrityOnly
        } else {
            SealMode::Encrypt
        };
        let embedded_explicit = self.embedded_config.is_some();
        let mut embedded_config = self.embedded_config.unwrap_or_else(|| {
            let mut config = DaemonConfig::new(domain, Ipv4Addr::LOCALHOST);
            config.socket = socket.clone();
            config
        });
        if embedded_config.key.is_none() && key.is_some() {
            embedded_config.key.clone_from(&key);
            embedded_config.key_file.clone_from(&key_file);
            embedded_config.seal_mode = seal_mode;
        }
        // The file the keys come from, watched for rotation steps.
        let key_file = key_file.or_else(|| embedded_config.key_file.clone());
        // A key given only in the embedded daemon's configuration serves the participant too.
        let seal = match key {
            Some(keyring) => Some((keyring, seal_mode)),
            None => embedded_config
                .key
                .clone()
                .map(|keyring| (keyring, embedded_config.seal_mode)),
        };
        let max_sample = match (self.max_sample, env("NDDS_MAX_SAMPLE")) {
            (Some(bytes), _) => bytes,
            (None, Some(text)) => text.parse().map_err(|_| {
                ConnectError::Setting(format!("NDDS_MAX_SAMPLE={text:?} is not a number of bytes"))
            })?,
            (None, None) => crate::DEFAULT_MAX_SAMPLE,
        };
        if !(MIN_MAX_SAMPLE..=MAX_MAX_SAMPLE).contains(&max_sample) {
            return Err(ConnectError::Setting(format!(
                "maximum sample size {max_sample} is outside {MIN_MAX_SAMPLE}..={MAX_MAX_SAMPLE} bytes"
            )));
        }
        let recv_buffer = match (self.recv_buffer, env("NDDS_RECV_BUFFER")) {
            (Some(bytes), _) => bytes,
            (None, Some(text)) => text.parse().map_err(|_| {
                ConnectError::Setting(format!(
                    "NDDS_RECV_BUFFER={text:?} is not a number of bytes"
                ))
            })?,
            (None, None) => crate::data_plane::DEFAULT_SOCKET_BUFFER,
        };
        if !(64 * 1024..=1 << 30).contains(&recv_buffer) {
            return Err(ConnectError::Setting(format!(
                "receive buffer {recv_buffer} is outside 64 KiB..=1 GiB"
            )));
        }
        Ok(Settings {
            socket,
            embedded,
            embedded_config,
            embedded_explicit,
            name: self.name.unwrap_or_else(process_name),
            role: self.role.unwrap_or(Role::Client),
            max_sample,
            recv_buffer,
            seal,
            key_file,
        })
    }
}

#[derive(Debug)]
struct Settings {
    socket: PathBuf,
    embedded: EmbeddedPolicy,
    embedded_config: DaemonConfig,
    /// Whether `embedded_config` was the application's choice (not the defaults).
    embedded_explicit: bool,
    name: String,
    role: Role,
    max_sample: usize,
    recv_buffer: usize,
    /// The domain's keys and how to seal, in a sealed domain.
    seal: Option<(Keyring, SealMode)>,
    /// The file the keys were read from (watched for rotation steps).
    key_file: Option<PathBuf>,
}

impl Settings {
    /// The daemon to start when the session's daemon went away for good (see `link`).
    fn takeover(&self) -> Option<Takeover> {
        (self.embedded != EmbeddedPolicy::Never).then(|| Takeover {
            config: self.embedded_config.clone(),
            explicit: self.embedded_explicit,
        })
    }
}

fn process_name() -> String {
    std::env::current_exe()
        .ok()
        .and_then(|path| path.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "ndds-client".to_owned())
}

/// How long a daemon another process is starting on the socket may take to accept sessions.
const CLAIMED_GRACE: Duration = Duration::from_secs(2);

/// An opened session.
type Reached = (std::os::unix::net::UnixStream, Welcome);

/// Shared by the participant and every endpoint handle; dropped with the last of them.
#[derive(Debug)]
pub(crate) struct Inner {
    pub(crate) participant: u64,
    pub(crate) welcome: Welcome,
    session: Arc<Session>,
    pub(crate) data: Arc<DataPlane>,
    endpoints: Arc<LocalEndpoints>,
    /// Runs the callbacks of the participant's callback consumers.
    pub(crate) dispatcher: Dispatcher,
    next_entity: AtomicU32,
    threads: Mutex<Vec<JoinHandle<()>>>,
}

impl Drop for Inner {
    fn drop(&mut self) {
        self.session.shutdown();
        self.dispatcher.close();
        self.data.close();
        let current = std::thread::current().id();
        for thread in lock(&self.threads).drain(..) {
            // The last handle may go on one of the participant's own threads (a direct
            // callback that owned an endpoint): that thread ends by itself once it returns.
            if thread.thread().id() != current {
                thread.thread().unpark();
                let _ = thread.join();
            }
        }
    }
}

/// Keeps the participant alive and withdraws the endpoint when dropped.
#[derive(Debug)]
pub(crate) struct EndpointHandle {
    pub(crate) inner: Arc<Inner>,
    entity: u32,
}

impl EndpointHandle {
    /// The endpoint's global id.
    pub(crate) fn guid(&self) -> ndds_core::wire::Guid {
        ndds_core::wire::Guid {
            participant: self.inner.participant,
            entity: self.entity,
        }
    }
}

impl Drop for EndpointHandle {
    fn drop(&mut self) {
        match self.inner.endpoints.remove(self.entity) {
            Some(Endpoint::Consumer(_)) => self.inner.data.remove_consumer(self.entity),
            Some(Endpoint::Producer(_)) => self.inner.data.remove_producer(self.entity),
            None => {}
        }
        let _ = self.inner.session.send(&ClientMessage::Undeclare {
            entity: self.entity,
        });
    }
}

/// A process's connection to ndds: declares producers and consumers. Cheap to clone.
///
/// ```no_run
/// use std::time::Duration;
/// use ndds_client::{ConsumerQos, Participant, ProducerQos};
///
/// let participant = Participant::connect()?;
/// let producer = participant.producer::<f64>("demo/value", ProducerQos::default())?;
/// let consumer = participant.consumer::<f64>("demo/value", ConsumerQos::default())?;
/// producer.wait_for_consumers(1, Duration::from_secs(1));
/// producer.write(&1.5)?;
/// let sample = consumer.recv_timeout(Duration::from_secs(1))?;
/// assert_eq!(sample.value, 1.5);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct Participant {
    inner: Arc<Inner>,
}

impl Participant {
    /// Connects with the default options (see [`ParticipantBuilder`]): the local daemon of
    /// the domain, else an embedded one.
    pub fn connect() -> Result<Self, ConnectError> {
        ParticipantBuilder::default().connect()
    }

    /// Options for connecting.
    pub fn builder() -> ParticipantBuilder {
        ParticipantBuilder::default()
    }

    fn open(settings: Settings) -> Result<Self, ConnectError> {
        // The daemon chooses the participant id (in a domain with permissions it must be one
        // of the daemon's identity); reconnecting, the client asks for it again.
        let mut hello = Hello {
            ipc_version: IPC_VERSION,
            participant: 0,
            pid: std::process::id(),
            name: settings.name.clone(),
            role: settings.role,
        };
        let (stream, welcome) = Self::reach_daemon(&settings, hello.clone())?;
        let participant = welcome.participant;
        hello.participant = participant;
        let interface = Ipv4Addr::from(welcome.interface);
        let limits = |interface| Limits {
            max_sample: settings.max_sample,
            recv_buffer: settings.recv_buffer,
            ..Limits::for_interface(interface)
        };
        let seal = || {
            settings
                .seal
                .clone()
                .map(|(keyring, mode)| ndds_daemon::keys::setup(keyring, mode))
        };
        let data = match DataPlane::open(
            interface,
            welcome.domain,
            participant,
            limits(interface),
            seal(),
        ) {
            Ok(data) => data,
            // A tool may reach a daemon's socket from where the daemon's interface does not
            // exist (another network namespace); listings need no data socket that works.
            Err(err) if settings.role == Role::Tool => {
                tracing::debug!(%interface, %err, "tool without a usable data socket; using loopback");
                DataPlane::open(
                    Ipv4Addr::LOCALHOST,
                    welcome.domain,
                    participant,
                    limits(Ipv4Addr::LOCALHOST),
                    seal(),
                )
                .map_err(|source| ConnectError::DataSocket { interface, source })?
            }
            Err(source) => return Err(ConnectError::DataSocket { interface, source }),
        };
        if welcome.pairwise && !data.require_pair_keys() {
            tracing::warn!(
                "the domain has a permissions document and this program no domain key: its \
                 samples are not sealed, so no peer opens them; give it the domain's key file \
                 (NDDS_KEY_FILE)"
            );
        }
        let reader = stream.try_clone().map_err(ConnectError::Thread)?;
        let session = Arc::new(Session::new(
            settings.socket.clone(),
            hello,
            (stream, &welcome),
            settings.takeover(),
        ));
        let inner = Arc::new(Inner {
            participant,
            welcome,
            session,
            data: Arc::new(data),
            endpoints: Arc::new(LocalEndpoints::default()),
            dispatcher: Dispatcher::default(),
            next_entity: AtomicU32::new(1),
            threads: Mutex::new(Vec::new()),
        });
        let key_watch = match (&settings.key_file, &settings.seal) {
            (Some(path), Some((keyring, _))) => {
                Some(ndds_daemon::keys::KeyWatch::new(path, keyring.clone()))
            }
            _ => None,
        };
        inner.spawn_threads(reader, key_watch)?;
        tracing::debug!(participant = format_args!("{participant:016x}"), socket = %settings.socket.display(), "participant connected");
        Ok(Participant { inner })
    }

    /// Connects to the daemon at the socket, starting an embedded one as the policy allows.
    fn reach_daemon(settings: &Settings, hello: Hello) -> Result<Reached, ConnectError> {
        if settings.embedded != EmbeddedPolicy::Always {
            match session::handshake(&settings.socket, hello.clone()) {
                Ok(session) => return Ok(session),
                Err(ConnectError::NoDaemon { .. }) if settings.embedded == EmbeddedPolicy::Auto => {
                }
                Err(err) => return Err(err),
            }
        }
        match embedded::ensure(&settings.embedded_config)? {
            Ensured::Ours => session::handshake(&settings.socket, hello),
            Ensured::Theirs if settings.embedded == EmbeddedPolicy::Always => Err(
                ConnectError::Embedded(EmbedError::Daemon(DaemonError::AlreadyRunning {
                    path: settings.socket.clone(),
                    pid: None,
                })),
            ),
            // Another process claimed the path a moment ago: its daemon may still be binding.
            Ensured::Theirs => {
                let deadline = Instant::now() + CLAIMED_GRACE;
                loop {
                    match session::handshake(&settings.socket, hello.clone()) {
                        Err(ConnectError::NoDaemon { .. }) if Instant::now() < deadline => {
                            std::thread::sleep(Duration::from_millis(20));
                        }
                        answer => return answer,
                    }
                }
            }
        }
    }

    /// This participant's id (the sender id of its data datagrams).
    pub fn id(&self) -> u64 {
        self.inner.participant
    }

    /// What the daemon said about itself when the session opened.
    pub fn daemon(&self) -> &Welcome {
        &self.inner.welcome
    }

    /// True while the session with the daemon is open.
    pub fn is_connected(&self) -> bool {
        self.inner.session.is_open()
    }

    /// Counters of this participant's data socket.
    pub fn stats(&self) -> ParticipantStats {
        self.inner.data.snapshot()
    }

    /// The socket of the daemon this participant's session is with.
    pub(crate) fn daemon_socket(&self) -> &std::path::Path {
        self.inner.session.path()
    }

    /// The daemon's current view of the domain (what `ndds topics` and `ndds nodes` show).
    pub fn graph(&self) -> Result<Graph, QueryError> {
        self.inner.session.query_graph()
    }

    /// Declares a producer of `T` on `topic`.
    pub fn producer<T: Serialize + DeserializeOwned>(
        &self,
        topic: &str,
        qos: ProducerQos,
    ) -> Result<Producer<T>, DeclareError> {
        self.raw_producer(topic, TypeDescription::of::<T>(), qos)
            .map(Producer::new)
    }

    /// Declares a producer of `T` announced with an explicit description, for types that
    /// [`TypeDescription::of`] cannot trace completely (see [`TypeDescription::describer`]).
    /// The description must be that of `T`.
    pub fn producer_with_type<T: Serialize>(
        &self,
        topic: &str,
        type_desc: TypeDescription,
        qos: ProducerQos,
    ) -> Result<Producer<T>, DeclareError> {
        self.raw_producer(topic, type_desc, qos).map(Producer::new)
    }

    /// Declares a consumer of `T` announced with an explicit description (see
    /// [`Participant::producer_with_type`]).
    pub fn consumer_with_type<T: DeserializeOwned>(
        &self,
        topic: &str,
        type_desc: TypeDescription,
        qos: ConsumerQos,
    ) -> Result<Consumer<T>, DeclareError> {
        self.raw_consumer(topic, type_desc, qos).map(Consumer::new)
    }

    /// Declares a producer of already-encoded samples of the described type.
    pub fn raw_producer(
        &self,
        topic: &str,
        type_desc: TypeDescription,
        qos: ProducerQos,
    ) -> Result<RawProducer, DeclareError> {
        let entity = self.inner.next_entity.fetch_add(1, Ordering::Relaxed);
        let wire_qos = qos.to_wire();
        let state = Arc::new(ProducerState::new(
            entity,
            topic,
            type_desc,
            qos,
            self.inner.data.clone(),
        ));
        let handle = self.declare(
            entity,
            Endpoint::Producer(state.clone()),
            EndpointQos::Producer(wire_qos),
        )?;
        Ok(RawProducer { handle, state })
    }

    /// Declares a consumer of `T` on `topic`.
    pub fn consumer<T: Serialize + DeserializeOwned>(
        &self,
        topic: &str,
        qos: ConsumerQos,
    ) -> Result<Consumer<T>, DeclareError> {
        self.raw_consumer(topic, TypeDescription::of::<T>(), qos)
            .map(Consumer::new)
    }

    /// Declares a consumer of samples of the described type, delivered undecoded.
    pub fn raw_consumer(
        &self,
        topic: &str,
        type_desc: TypeDescription,
        qos: ConsumerQos,
    ) -> Result<RawConsumer, DeclareError> {
        let entity = self.inner.next_entity.fetch_add(1, Ordering::Relaxed);
        let (delivery, rx) = Delivery::new(&qos);
        let delivery = Arc::new(delivery);
        let reliable = match qos.reliability {
            Reliability::Reliable { depth } => Some(ReaderConfig {
                depth: usize::try_from(depth).unwrap_or(usize::MAX).max(1),
                ..ReaderConfig::default()
            }),
            Reliability::BestEffort => None,
        };
        // A queue limits what reliable streams hand over; a latest-value cell does not.
        let credit = (qos.mode == ConsumerMode::Immediate).then(|| qos.depth.max(1));
        let spec = ConsumerSpec {
            rules: qos.rules(),
            reliable,
            credit,
        };
        let state = Arc::new(ConsumerState::new(
            topic,
            type_desc,
            entity,
            credit.filter(|_| reliable.is_some()),
            delivery.clone(),
            self.inner.data.clone(),
        ));
        self.inner.data.add_consumer(entity, spec, delivery);
        let handle = self.declare(
            entity,
            Endpoint::Consumer(state.clone()),
            EndpointQos::Consumer(qos.to_wire()),
        )?;
        Ok(RawConsumer {
            _handle: handle,
            state,
            rx,
        })
    }

    /// Registers the endpoint locally, then declares it to the daemon.
    fn declare(
        &self,
        entity: u32,
        endpoint: Endpoint,
        qos: EndpointQos,
    ) -> Result<EndpointHandle, DeclareError> {
        let peers = endpoint.peers();
        let decl = EndpointDecl {
            entity,
            topic: peers.topic.clone(),
            type_desc: peers.type_desc.clone(),
            fingerprint: peers.fingerprint,
            qos,
            locator: self.inner.data.locator,
        };
        self.inner.endpoints.insert(endpoint, decl.clone());
        // From here on, dropping the handle undoes the local registration.
        let handle = EndpointHandle {
            inner: self.inner.clone(),
            entity,
        };
        self.inner.session.declare(decl)?;
        Ok(handle)
    }
}

impl Inner {
    fn spawn_threads(
        self: &Arc<Self>,
        reader: std::os::unix::net::UnixStream,
        key_watch: Option<ndds_daemon::keys::KeyWatch>,
    ) -> Result<(), ConnectError> {
        if let Some(mut watch) = key_watch {
            let data = self.data.clone();
            let watcher = std::thread::Builder::new()
                .name("ndds-keys".into())
                .spawn(move || {
                    // Woken early by the participant's drop (unpark).
                    while !data.is_closed() {
                        std::thread::park_timeout(ndds_daemon::keys::KEY_CHECK);
                        if let Some(keyring) = watch.poll() {
                            data.set_keyring(keyring);
                        }
                    }
                })
                .map_err(ConnectError::Thread)?;
            lock(&self.threads).push(watcher);
        }
        let data = self.data.clone();
        let io_thread = std::thread::Builder::new()
            .name("ndds-io".into())
            .spawn(move || data.run())
            .map_err(ConnectError::Thread)?;
        let (session, endpoints) = (self.session.clone(), self.endpoints.clone());
        let session_thread = std::thread::Builder::new()
            .name("ndds-session".into())
            .spawn(move || daemon_link::run(reader, &session, &endpoints))
            .map_err(ConnectError::Thread)?;
        lock(&self.threads).extend([io_thread, session_thread]);
        Ok(())
    }
}

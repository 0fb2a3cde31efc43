//! Binding and running a daemon.
//!
//! [`Daemon::bind`] claims every resource (UDP sockets, Unix socket) and fails with a clear
//! [`DaemonError`] if one is unavailable; [`Daemon::run`] then serves until its shutdown token
//! is cancelled, says `Bye` to the domain, waits for its tasks and removes its socket file.
//! The socket path is claimed first ([`crate::claim`]), so at most one daemon serves a path.

use std::net::{SocketAddr, SocketAddrV4};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use ndds_core::discovery::{Engine, Via};
use ndds_core::wire::{Locator, MAX_DATAGRAM};
use tokio::net::{UdpSocket, UnixListener};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use crate::claim::SocketClaim;
use crate::config::DaemonConfig;
use crate::connection;
use crate::driver::{Counters, Driver, Input};
use crate::keys::{self, KeyWatch};
use crate::local;
use crate::peers::{self, Peer, PeerError};
use crate::sockets::{self, DiscoverySockets, SocketError, UnicastPort};

/// Datagrams and frames queued for the driver before datagrams are dropped (and counted).
const INPUT_QUEUE: usize = 4096;
/// How long shutdown waits for connection tasks.
const SHUTDOWN_GRACE: Duration = Duration::from_secs(2);

/// Why a daemon could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// Another daemon serves (or is starting on) the socket path.
    #[error(
        "a daemon already serves {path}{}; stop it or choose another --socket / --domain",
        pid.map_or(String::new(), |pid| format!(" (pid {pid})"))
    )]
    AlreadyRunning {
        /// The socket path.
        path: PathBuf,
        /// The process that runs it, when known.
        pid: Option<u32>,
    },
    /// Something other than a socket exists at the socket path; it is left alone.
    #[error("{path} exists and is not a socket: choose another --socket path")]
    NotASocket {
        /// The socket path.
        path: PathBuf,
    },
    /// The lock file beside the socket path is not a plain file with one name.
    #[error(
        "{path} is not a plain lock file (a hard link or a special file): remove it or choose \
         another --socket path"
    )]
    BadLockFile {
        /// The lock file.
        path: PathBuf,
    },
    /// The Unix socket could not be created.
    #[error("cannot listen on {path}: {source}")]
    Listen {
        /// The socket path.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A UDP socket could not be set up.
    #[error("cannot set up discovery sockets: {0}")]
    Socket(#[from] SocketError),
    /// A static peer could not be resolved or used.
    #[error(transparent)]
    Peer(#[from] PeerError),
    /// The socket path or its directory is not safe to use (another user's, shared).
    #[error(transparent)]
    Local(#[from] crate::local::LocalError),
    /// The discovery settings are inconsistent (timers, too many peers).
    #[error(transparent)]
    Config(#[from] ndds_core::discovery::ConfigError),
}

/// A daemon whose sockets are bound; call [`Daemon::run`].
#[derive(Debug)]
pub struct Daemon {
    config: DaemonConfig,
    engine: Engine,
    sockets: DiscoverySockets,
    peers: Vec<Peer>,
    listener: UnixListener,
    claim: SocketClaim,
}

impl Daemon {
    /// Resolves the peers, binds the discovery sockets and the Unix socket. Must be called
    /// inside a tokio runtime.
    pub async fn bind(config: DaemonConfig) -> Result<Self, DaemonError> {
        // The socket first: a second daemon is refused before it opens (or logs about) ports.
        let (claim, listener) = SocketClaim::take(&config.socket, config.socket_group)?;
        let peers = peers::resolve(&config.peers, config.domain).await?;
        if config.interface.is_loopback() {
            for peer in peers.iter().filter(|p| p.locator.addr[0] != 127) {
                tracing::warn!(
                    peer = %peer.spec,
                    at = %peer.locator,
                    "this peer is not on this host, but the daemon uses the loopback interface: \
                     it cannot be reached (use --interface)"
                );
            }
        }
        let group = config
            .multicast
            .then(|| SocketAddrV4::new(config.group, config.port));
        let unicast_port = match config.unicast_port {
            Some(port) => UnicastPort::Exact(port),
            None => UnicastPort::Default(ndds_core::domain::unicast_port(config.domain)),
        };
        let sockets = sockets::open(config.interface, group, unicast_port, config.ttl)?;
        let unicast = match sockets.unicast.local_addr() {
            Ok(SocketAddr::V4(addr)) => Locator::from(addr),
            _ => Locator::UNSPECIFIED,
        };
        let mut discovery = config.discovery();
        discovery.seed = config.seed.unwrap_or_else(|| fastrand::u64(..));
        // Never from the seed either: a configured seed must not make probe tokens guessable.
        let secret = crate::keys::random_bytes().map_err(|source| DaemonError::Listen {
            path: PathBuf::from("/dev/urandom"),
            source,
        })?;
        discovery.probe_secret = Some(secret);
        // Never from the seed: two hosts given one seed must still have distinct ids. With
        // permissions, its high bits are the identity's (security::node_id_for).
        discovery.node_id = Some(match &config.security {
            Some(security) => {
                ndds_core::security::node_id_for(&security.identity.public(), fastrand::u64(..))
            }
            None => fastrand::u64(1..),
        });
        discovery.hostname = gethostname::gethostname().to_string_lossy().into_owned();
        discovery.pid = std::process::id();
        discovery.unicast = unicast;
        discovery.version = env!("CARGO_PKG_VERSION").to_owned();
        discovery.peers = peers.iter().map(|peer| peer.locator).collect();
        let mut engine = Engine::new(discovery, Instant::now())?;
        if let Some(keyring) = &config.key {
            engine.seal_with(crate::keys::setup(keyring.clone(), config.seal_mode));
            tracing::info!(
                epochs = ?keyring.epochs().collect::<Vec<_>>(),
                cipher = keyring.cipher().name(),
                mode = ?config.seal_mode,
                "sealed domain: only datagrams sealed with the domain key are accepted"
            );
            if let Some(warning) = crate::keys::slow_cipher_warning(keyring.cipher()) {
                tracing::warn!("{warning}");
            }
        }
        if let Some(security) = &config.security {
            let guard = security.guard().map_err(|source| DaemonError::Listen {
                path: PathBuf::from("/dev/urandom"),
                source,
            })?;
            engine.guard_with(guard);
            let identity = security.identity.public();
            tracing::info!(
                %identity,
                subject = ?engine.subject_of(&identity),
                document = security.permissions.serial,
                file = %security.permissions_file.display(),
                "permissions: discovery is signed, and only what the document allows matches"
            );
            if engine.subject_of(&identity).is_none() {
                tracing::warn!(
                    %identity,
                    "this daemon's identity is not a subject of the permissions document: its clients may declare nothing; add it with `ndds security add NAME {identity} ...` and sign"
                );
            }
        }
        Ok(Daemon {
            config,
            engine,
            sockets,
            peers,
            listener,
            claim,
        })
    }

    /// The node id this daemon announces.
    pub fn node_id(&self) -> u64 {
        self.engine.node_id()
    }

    /// The unicast discovery locator.
    pub fn unicast(&self) -> Locator {
        self.engine.config().unicast
    }

    /// The configuration in use.
    pub fn config(&self) -> &DaemonConfig {
        &self.config
    }

    /// Serves until `shutdown` is cancelled.
    pub async fn run(self, shutdown: CancellationToken) -> Result<(), DaemonError> {
        let Daemon {
            config,
            engine,
            sockets,
            peers,
            listener,
            claim,
        } = self;
        tracing::info!(
            domain = config.domain,
            node = %crate::driver::hex(engine.node_id()),
            socket = %config.socket.display(),
            interface = %config.interface,
            unicast = %engine.config().unicast,
            group = %sockets.group.map_or("off".to_owned(), |g| g.to_string()),
            peers = %peers.iter().map(|p| format!("{} ({})", p.spec, p.locator)).collect::<Vec<_>>().join(", "),
            "ndds-daemon serving"
        );
        if sockets.group.is_none() && peers.is_empty() {
            tracing::warn!(
                "multicast is off and no peers are listed: only daemons that list this one as \
                 a peer will find it"
            );
        }
        let counters = Arc::new(Counters::default());
        let (inputs, mut queue) = mpsc::channel(INPUT_QUEUE);
        let tasks = TaskTracker::new();
        let children = shutdown.child_token();
        let unicast = Arc::new(sockets.unicast);
        let multicast = sockets
            .multicast
            .map(|socket| (Arc::new(socket), Via::Multicast));
        for (socket, via) in multicast
            .into_iter()
            .chain([(unicast.clone(), Via::Unicast)])
        {
            let (inputs, counters, stop) = (inputs.clone(), counters.clone(), children.clone());
            tasks.spawn(receive(socket, via, inputs, counters, stop));
        }
        tasks.spawn(accept(
            listener,
            inputs.clone(),
            counters.clone(),
            children.clone(),
            tasks.clone(),
        ));
        drop(inputs);

        let mut driver = Driver::new(engine, unicast, sockets.group, peers, counters);
        let mut key_watch = match (&config.key_file, &config.key) {
            (Some(path), Some(keyring)) => Some(KeyWatch::new(path, keyring.clone())),
            _ => None,
        };
        #[cfg(feature = "cli")]
        let mut permissions_watch = config
            .security
            .as_ref()
            .map(|security| crate::security::PermissionsWatch::new(security, config.domain));
        let mut key_check = tokio::time::interval(keys::KEY_CHECK);
        key_check.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        driver.flush().await;
        loop {
            let deadline = driver.deadline().map(tokio::time::Instant::from_std);
            // The timer comes before the queue: a flood of datagrams must not starve our own
            // announcements and expiry.
            tokio::select! {
                biased;
                () = shutdown.cancelled() => break,
                () = sleep_until(deadline) => driver.on_timer(),
                _ = key_check.tick(), if key_watch.is_some() => {
                    if let Some(keyring) = key_watch.as_mut().and_then(KeyWatch::poll) {
                        driver.set_keyring(keyring);
                    }
                    #[cfg(feature = "cli")]
                    if let Some(permissions) = permissions_watch
                        .as_mut()
                        .and_then(crate::security::PermissionsWatch::poll)
                    {
                        driver.set_permissions(permissions);
                    }
                }
                input = queue.recv() => match input {
                    Some(input) => driver.on_input(input),
                    None => break,
                },
            }
            driver.flush().await;
        }
        driver.close();
        driver.flush().await;
        children.cancel();
        tasks.close();
        if tokio::time::timeout(SHUTDOWN_GRACE, tasks.wait())
            .await
            .is_err()
        {
            tracing::warn!("some connection tasks did not stop in time");
        }
        // Removes the socket file, then releases the path's lock.
        drop(claim);
        tracing::info!("ndds-daemon stopped");
        Ok(())
    }
}

async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

async fn receive(
    socket: Arc<UdpSocket>,
    via: Via,
    inputs: mpsc::Sender<Input>,
    counters: Arc<Counters>,
    stop: CancellationToken,
) {
    let mut buf = vec![0u8; MAX_DATAGRAM + 1];
    loop {
        let received = tokio::select! {
            () = stop.cancelled() => return,
            received = socket.recv_from(&mut buf) => received,
        };
        match received {
            Ok((len, from)) => {
                let input = Input::Datagram {
                    from,
                    via,
                    bytes: buf[..len].to_vec(),
                };
                match inputs.try_send(input) {
                    Ok(()) => {}
                    Err(mpsc::error::TrySendError::Full(_)) => {
                        counters.input_overflow.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(mpsc::error::TrySendError::Closed(_)) => return,
                }
            }
            Err(err) => tracing::debug!(%err, "discovery receive error"),
        }
    }
}

async fn accept(
    listener: UnixListener,
    inputs: mpsc::Sender<Input>,
    counters: Arc<Counters>,
    stop: CancellationToken,
    tasks: TaskTracker,
) {
    let mut next_client = 1;
    let slots = Arc::new(tokio::sync::Semaphore::new(local::MAX_CLIENTS));
    loop {
        let accepted = tokio::select! {
            () = stop.cancelled() => return,
            accepted = listener.accept() => accepted,
        };
        match accepted {
            Ok((stream, _)) => {
                let Ok(slot) = slots.clone().try_acquire_owned() else {
                    let refused = counters.connections_refused.fetch_add(1, Ordering::Relaxed);
                    if refused.is_power_of_two() || refused == 0 {
                        tracing::warn!(
                            max = local::MAX_CLIENTS,
                            refused = refused + 1,
                            "too many local connections; closing new ones"
                        );
                    }
                    continue;
                };
                let cred = match local::peer_cred(&stream) {
                    Ok(cred) => cred,
                    Err(err) => {
                        counters.connections_refused.fetch_add(1, Ordering::Relaxed);
                        tracing::warn!(%err, "cannot read a client's credentials; closing it");
                        continue;
                    }
                };
                let client = next_client;
                next_client += 1;
                let cancel = stop.child_token();
                let (inputs, counters) = (inputs.clone(), counters.clone());
                tasks.spawn(async move {
                    connection::serve(stream, client, cred, inputs, cancel, counters).await;
                    drop(slot);
                });
            }
            Err(err) => {
                tracing::warn!(%err, "accept failed");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
}

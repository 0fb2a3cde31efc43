//! `ndds studio`: ControlShell's graphical tools in a browser. A web server on loopback (by
//! default) whose page shows the network (hosts, processes, topics, ports, why a pair does not
//! match), the running systems (their data-flow diagrams in execution order, groups and
//! categories colour-coded, configurations that switch, parameters set in place), their state
//! machines (the graph, the current state, stimuli sent from the page) and live plots of any
//! numeric field, and edits description files (the DFE and FSM editor, [`editor`]). The page
//! talks only to this process, which is an ndds participant; the assets are embedded in the
//! binary. See docs/studio.md.
//!
//! Sits above the runtime (it reads the runtime's description, statistics and state-machine
//! topics, uses its command ports, and checks edited files with its loader) and the component
//! library (the editor's palette), and below the CLI.

pub mod editor;
pub mod foxglove;
pub mod hub;
pub mod network;
pub mod plot;
pub mod web;

use std::net::SocketAddr;
use std::sync::Arc;

use ndds_client::Participant;

/// How the studio is served.
#[derive(Clone, Debug)]
pub struct StudioOptions {
    /// Where to listen (port 0: any free port).
    pub addr: SocketAddr,
    /// The token a page presents to change anything (and to see anything when `addr` is not
    /// loopback); a random one when `None`.
    pub token: Option<String>,
    /// Measure every user topic's rate (one consumer per topic).
    pub rates: bool,
    /// The directory whose description files the editor opens and saves (it never leaves
    /// it); `None`: no editor.
    pub files: Option<std::path::PathBuf>,
}

/// Why the studio could not run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StudioError {
    /// The address could not be bound.
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The editor's directory does not exist.
    #[error("cannot edit the files in {}: {source}", root.display())]
    Files {
        /// The directory.
        root: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The server or its threads failed.
    #[error("the studio's server failed: {0}")]
    Io(#[from] std::io::Error),
}

/// A studio bound to its address, not yet serving.
pub struct Studio {
    listener: std::net::TcpListener,
    hub: Arc<hub::Hub>,
    access: web::Access,
}

/// A random token: 128 bits, hex.
fn new_token() -> String {
    let mut rng = fastrand::Rng::new();
    format!("{:016x}{:016x}", rng.u64(..), rng.u64(..))
}

impl Studio {
    /// Binds `options.addr` and starts watching the network through `participant`.
    pub fn bind(participant: Participant, options: StudioOptions) -> Result<Self, StudioError> {
        let listener =
            std::net::TcpListener::bind(options.addr).map_err(|source| StudioError::Bind {
                addr: options.addr,
                source,
            })?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let editor = match &options.files {
            Some(root) => Some(web::EditorSetup {
                root: root.canonicalize().map_err(|source| StudioError::Files {
                    root: root.clone(),
                    source,
                })?,
                participant: participant.clone(),
            }),
            None => None,
        };
        let hub = hub::Hub::new(participant, options.rates);
        hub.start()?;
        Ok(Studio {
            listener,
            hub,
            access: web::Access {
                token: options.token.unwrap_or_else(new_token),
                exposed: !web::is_loopback(&addr),
                editor,
            },
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.listener
            .local_addr()
            .expect("a bound listener has an address")
    }

    /// The URL a Foxglove (or Lichtblick) client connects to (the Foxglove WebSocket
    /// protocol, read-only; off loopback with the token in its query).
    pub fn foxglove_url(&self) -> String {
        if self.access.exposed {
            format!("ws://{}/foxglove?token={}", self.addr(), self.access.token)
        } else {
            format!("ws://{}/foxglove", self.addr())
        }
    }

    /// The URL to open: with the token in its fragment (never sent to a server, kept by the
    /// page).
    pub fn url(&self) -> String {
        format!("http://{}/#token={}", self.addr(), self.access.token)
    }

    /// Serves until `stop` is set (blocking; runs its own async runtime).
    pub fn run(self, stop: Arc<std::sync::atomic::AtomicBool>) -> Result<(), StudioError> {
        let shutdown = async move {
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
        };
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("studio-web")
            .enable_all()
            .build()?;
        let hub = Arc::clone(&self.hub);
        let result = runtime.block_on(async move {
            let listener = tokio::net::TcpListener::from_std(self.listener)?;
            web::serve(listener, self.hub, self.access, shutdown).await
        });
        hub.stop();
        Ok(result?)
    }
}

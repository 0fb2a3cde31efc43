//! Running a daemon inside another process, on a thread of its own.
//!
//! `ndds-client` uses this when no daemon answers on the socket path, so a single program
//! works with no set-up. The embedded daemon is a complete daemon: other processes on the host
//! can connect to it through its socket until it is stopped (or dropped).

use std::thread::JoinHandle;
use std::time::Duration;

use tokio_util::sync::CancellationToken;

use crate::config::DaemonConfig;
use crate::daemon::{Daemon, DaemonError};

/// How long [`EmbeddedDaemon::stop`] waits for the daemon thread.
const STOP_GRACE: Duration = Duration::from_secs(3);

/// A daemon running on a background thread; stopped on drop.
#[derive(Debug)]
pub struct EmbeddedDaemon {
    config: DaemonConfig,
    node_id: u64,
    shutdown: CancellationToken,
    thread: Option<JoinHandle<()>>,
}

/// The embedded daemon could not start.
#[derive(Debug, thiserror::Error)]
pub enum EmbedError {
    /// The daemon itself failed to bind.
    #[error(transparent)]
    Daemon(#[from] DaemonError),
    /// The thread or its runtime could not be created.
    #[error("cannot start the embedded daemon thread: {0}")]
    Thread(std::io::Error),
}

impl EmbeddedDaemon {
    /// Starts a daemon with `config` and returns once it is bound and accepting clients.
    pub fn start(config: DaemonConfig) -> Result<Self, EmbedError> {
        let shutdown = CancellationToken::new();
        let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel(1);
        let token = shutdown.clone();
        let thread_config = config.clone();
        let thread = std::thread::Builder::new()
            .name("ndds-daemon".into())
            .spawn(move || {
                let runtime = match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(runtime) => runtime,
                    Err(err) => {
                        let _ = ready_tx.send(Err(EmbedError::Thread(err)));
                        return;
                    }
                };
                runtime.block_on(async move {
                    match Daemon::bind(thread_config).await {
                        Ok(daemon) => {
                            let _ = ready_tx.send(Ok(daemon.node_id()));
                            if let Err(err) = daemon.run(token).await {
                                tracing::error!(%err, "embedded daemon failed");
                            }
                        }
                        Err(err) => {
                            let _ = ready_tx.send(Err(err.into()));
                        }
                    }
                });
            })
            .map_err(EmbedError::Thread)?;
        let node_id = ready_rx.recv().map_err(|_| {
            EmbedError::Thread(std::io::Error::other("daemon thread exited during start"))
        })??;
        Ok(EmbeddedDaemon {
            config,
            node_id,
            shutdown,
            thread: Some(thread),
        })
    }

    /// The configuration it runs with.
    pub fn config(&self) -> &DaemonConfig {
        &self.config
    }

    /// True while its thread runs (false after `stop`, or if it failed).
    pub fn is_running(&self) -> bool {
        self.thread
            .as_ref()
            .is_some_and(|thread| !thread.is_finished())
    }

    /// Its node id.
    pub fn node_id(&self) -> u64 {
        self.node_id
    }

    /// Stops it: says `Bye`, closes client connections, removes its socket.
    pub fn stop(&mut self) {
        self.shutdown.cancel();
        if let Some(thread) = self.thread.take() {
            let deadline = std::time::Instant::now() + STOP_GRACE;
            while !thread.is_finished() && std::time::Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(5));
            }
            if thread.is_finished() {
                let _ = thread.join();
            } else {
                tracing::warn!("embedded daemon did not stop in time");
            }
        }
    }
}

impl Drop for EmbeddedDaemon {
    fn drop(&mut self) {
        self.stop();
    }
}

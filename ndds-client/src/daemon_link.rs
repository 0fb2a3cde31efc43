//! The session thread: reads the daemon's frames (answers to waiting requests, match events to
//! the router) and, when the daemon goes away, reconnects to its successor on its own.
//!
//! While the daemon is down, samples keep flowing to the peers already known. When a daemon
//! answers on the socket again, the participant opens a new session as the same participant,
//! declares all its endpoints again, and after [`RECONNECT_GRACE`] drops the matches the new
//! daemon did not report (it had that long to rediscover the domain).
//!
//! When no daemon comes back (the process that embedded it exited), a participant whose
//! policy allows embedding starts an embedded daemon itself and declares again there, so the
//! domain keeps a daemon (and `ndds topics` keeps working) while any such participant lives.

use std::io::BufReader;
use std::os::unix::net::UnixStream;
use std::time::{Duration, Instant};

use ndds_core::ipc::DaemonMessage;

use ndds_daemon::DaemonConfig;

use crate::embedded::{self, Ensured};
use crate::error::ConnectError;
use crate::local_endpoints::{Changed, LocalEndpoints};
use crate::session::{self, Session};

/// How long a new daemon has to report the matches of the old one before they are dropped.
pub const RECONNECT_GRACE: Duration = Duration::from_secs(3);
/// Bytes of frames read at once from the daemon (a burst's match events are applied together).
const FRAMES_AT_HAND: usize = 64 * 1024;
/// Most match events recorded before they are applied, however fast they keep coming.
const PUBLISH_EVERY: usize = 1024;
/// First and longest pause between reconnection attempts.
const RETRY_FIRST: Duration = Duration::from_millis(50);
const RETRY_MAX: Duration = Duration::from_millis(500);
/// How long a lost daemon may take to come back (a restart) before a participant that may
/// embed takes its role over; each participant waits between one and two times this.
const TAKEOVER_AFTER: Duration = Duration::from_millis(500);

/// Runs the session thread until the participant ends.
pub(crate) fn run(mut reader: UnixStream, session: &Session, endpoints: &LocalEndpoints) {
    let mut sweep_at: Option<Instant> = None;
    loop {
        read_until_lost(&mut reader, session, endpoints, &mut sweep_at);
        session.mark_closed();
        if session.is_ending() {
            return;
        }
        match reconnect(session) {
            Some(new_reader) => {
                reader = new_reader;
                endpoints.mark_stale();
                for decl in endpoints.declarations() {
                    if let Err(err) = session.declare_async(decl) {
                        tracing::warn!(%err, "re-declaring after reconnection failed");
                    }
                }
                sweep_at = Instant::now().checked_add(RECONNECT_GRACE);
            }
            None => return,
        }
    }
}

/// Reads frames until the connection ends; sweeps stale matches when their time comes.
fn read_until_lost(
    stream: &mut UnixStream,
    session: &Session,
    endpoints: &LocalEndpoints,
    sweep_at: &mut Option<Instant>,
) {
    // Frames that arrived together are applied together: match events are recorded as they
    // are read and applied once the frames at hand are done.
    let mut reader = BufReader::with_capacity(FRAMES_AT_HAND, &*stream);
    let mut changed = Changed::new();
    let mut recorded = 0usize;
    loop {
        // Published when the frames at hand are done, and at least every `PUBLISH_EVERY`
        // events of a stream that never pauses.
        if reader.buffer().is_empty() || recorded >= PUBLISH_EVERY {
            endpoints.publish(&mut changed);
            recorded = 0;
        }
        let timeout = sweep_at.map(|at| {
            at.saturating_duration_since(Instant::now())
                .max(Duration::from_millis(1))
        });
        let _ = reader.get_ref().set_read_timeout(timeout);
        match session::read_frame(&mut reader) {
            Ok(Some(DaemonMessage::Refused { reason })) => {
                tracing::error!(%reason, "the daemon ended the session");
                break;
            }
            Ok(Some(message)) => {
                if let Some(event) = session.complete(message) {
                    endpoints.route(event, &mut changed);
                    recorded += 1;
                }
            }
            Err(err)
                if matches!(
                    err.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Ok(None) | Err(_) if session.is_ending() => return,
            Ok(None) => {
                tracing::warn!(socket = %session.path().display(), "the daemon closed the session; samples keep flowing to known peers; reconnecting");
                break;
            }
            Err(err) => {
                tracing::warn!(%err, "lost the daemon session; samples keep flowing to known peers; reconnecting");
                break;
            }
        }
        if sweep_at.is_some_and(|at| Instant::now() >= at) {
            *sweep_at = None;
            endpoints.publish(&mut changed);
            let swept = endpoints.sweep_stale();
            tracing::info!(swept, "matches the new daemon did not confirm were dropped");
        }
    }
    endpoints.publish(&mut changed);
}

/// Tries to reach a daemon again until one answers or the participant ends. A participant
/// that may embed takes the role over once no daemon answered for [`TAKEOVER_AFTER`] (the
/// daemon's process exited): it starts an embedded daemon on the socket, unless another
/// survivor claimed the path first, in which case it connects to that one.
fn reconnect(session: &Session) -> Option<UnixStream> {
    let mut pause = RETRY_FIRST;
    let lost_at = Instant::now();
    // Spread over a window, so survivors rarely race (when they do, the socket's claim
    // decides: the loser connects to the winner).
    let takeover_at = lost_at + TAKEOVER_AFTER + TAKEOVER_AFTER.mul_f64(fastrand::f64());
    while !session.is_ending() {
        match session.reconnect() {
            Ok((reader, welcome)) => {
                tracing::info!(
                    node = format_args!("{:016x}", welcome.node),
                    "reconnected to the daemon; declaring endpoints again"
                );
                return Some(reader);
            }
            Err(ConnectError::NoDaemon { .. }) if Instant::now() >= takeover_at => {
                if let Some(config) = session.takeover() {
                    take_over(session, &config);
                    continue;
                }
            }
            Err(err) => tracing::debug!(%err, "daemon not back yet"),
        }
        std::thread::sleep(pause);
        pause = (pause * 2).min(RETRY_MAX);
    }
    None
}

/// Starts an embedded daemon in place of the one that went away (see [`reconnect`]).
fn take_over(session: &Session, config: &DaemonConfig) {
    match embedded::ensure(config) {
        Ok(Ensured::Ours) => tracing::info!(
            socket = %session.path().display(),
            interface = %config.interface,
            "the daemon's process is gone: this process now runs the domain's daemon"
        ),
        Ok(Ensured::Theirs) => {
            tracing::debug!("another process took the daemon's role over first");
            // It may still be starting: give it a moment before the next attempt.
            std::thread::sleep(RETRY_FIRST);
        }
        Err(ConnectError::Exiting) => std::thread::sleep(RETRY_MAX),
        Err(err) => {
            tracing::warn!(%err, "cannot take the daemon's role over; waiting for a daemon");
            std::thread::sleep(RETRY_MAX);
        }
    }
}

//! Requests a module's routine makes of its runtime or habitat (switch a configuration, start
//! or stop a habitat, change its rate, reset it). A routine runs on a habitat's thread, or on
//! a thread carrying out a switch, with that habitat's list in use; doing such work there
//! would wait for the routine itself. So the call queues a [`Request`] and returns at once,
//! and the runtime's request thread (started with the first request) carries it out after the
//! routine has returned, logging the outcome. Calls that have no useful queued form (`step`,
//! `install`, `remove`, declaring groups or configurations) are refused with an
//! `InsideRoutine` error instead: never a deadlock.

use std::sync::Weak;
use std::sync::mpsc::{Receiver, Sender};

use super::runtime::{Inner, Runtime};

/// Work queued from inside a routine.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Request {
    /// `Runtime::switch`.
    Switch(String),
    /// `Habitat::start` of this habitat.
    Start(String),
    /// `Habitat::stop`.
    Stop(String),
    /// `Habitat::set_rate`.
    SetRate(String, f64),
    /// `Habitat::reset`.
    Reset(String),
}

/// Starts the request thread of the runtime `inner` points to; it ends when the runtime is
/// dropped (its sender with it).
pub(crate) fn spawn(inner: Weak<Inner>) -> std::io::Result<Sender<Request>> {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("runtime-requests".into())
        .spawn(move || serve(&inner, &rx))?;
    Ok(tx)
}

fn serve(inner: &Weak<Inner>, requests: &Receiver<Request>) {
    while let Ok(request) = requests.recv() {
        let Some(inner) = inner.upgrade() else {
            return;
        };
        let runtime = Runtime::from_inner(inner);
        carry_out(&runtime, &request);
    }
}

/// Carries out one request, logging what went wrong.
pub(crate) fn carry_out(runtime: &Runtime, request: &Request) {
    let habitat = |name: &str| runtime.find_habitat(name);
    let outcome: Result<(), String> = match request {
        Request::Switch(name) => runtime.switch(name).map_err(|e| e.to_string()),
        Request::Start(name) => match habitat(name) {
            Some(h) => h.start().map_err(|e| e.to_string()),
            None => Err(format!("no habitat `{name}`")),
        },
        Request::Stop(name) => habitat(name).map_or(Ok(()), |h| {
            h.stop();
            Ok(())
        }),
        Request::SetRate(name, hz) => match habitat(name) {
            Some(h) => h.set_rate(*hz).map_err(|e| e.to_string()),
            None => Err(format!("no habitat `{name}`")),
        },
        Request::Reset(name) => habitat(name).map_or(Ok(()), |h| {
            h.reset();
            Ok(())
        }),
    };
    match outcome {
        Ok(()) => {
            tracing::debug!(runtime = %runtime.name(), ?request, "request from a routine carried out")
        }
        Err(error) => {
            tracing::warn!(runtime = %runtime.name(), ?request, %error, "request from a routine refused")
        }
    }
}

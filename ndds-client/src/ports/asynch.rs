//! Async forms of the blocking primitives: each runs the blocking form on a thread of its own
//! and returns a future of its result, so an async task never blocks its executor. The
//! timeouts are the same as the blocking forms'.

use std::collections::BTreeMap;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::error::PortError;
use super::owner::{PortOwner, ReplyHandle};
use super::spawn_error;
use super::user::PortUser;
use super::waitfor::Rendezvous;

/// Runs `work` on a new thread; the future resolves to its result.
fn off_thread<T, W>(port: &str, work: W) -> impl Future<Output = Result<T, PortError>> + use<T, W>
where
    T: Send + 'static,
    W: FnOnce() -> Result<T, PortError> + Send + 'static,
{
    let (tx, rx) = flume::bounded(1);
    let port = port.to_owned();
    let thread = format!("port-async-{port}");
    let spawned = std::thread::Builder::new()
        .name(thread.clone())
        .spawn(move || {
            let _ = tx.send(work());
        })
        .map_err(spawn_error(&port, &thread));
    async move {
        spawned?;
        rx.recv_async()
            .await
            .unwrap_or(Err(PortError::ThreadEnded { port }))
    }
}

impl<Q, R> PortUser<Q, R>
where
    Q: Serialize + DeserializeOwned + Send + Sync + 'static,
    R: Serialize + DeserializeOwned + Send + 'static,
{
    /// [`send`](Self::send), as a future.
    pub fn send_async(
        self: &Arc<Self>,
        value: Q,
        timeout: Duration,
    ) -> impl Future<Output = Result<R, PortError>> + use<Q, R> {
        let user = Arc::clone(self);
        off_thread(self.port(), move || user.send(&value, timeout))
    }

    /// [`query`](Self::query), as a future.
    pub fn query_async(
        self: &Arc<Self>,
        value: Q,
        timeout: Duration,
    ) -> impl Future<Output = Result<R, PortError>> + use<Q, R> {
        let user = Arc::clone(self);
        off_thread(self.port(), move || user.query(&value, timeout))
    }

    /// [`receive_all`](Self::receive_all), as a future.
    pub fn receive_all_async<F: FnOnce(&Q) -> R + Send + 'static>(
        self: &Arc<Self>,
        timeout: Duration,
        answer: F,
    ) -> impl Future<Output = Result<Q, PortError>> + use<Q, R, F> {
        let user = Arc::clone(self);
        off_thread(self.port(), move || user.receive_all(timeout, answer))
    }
}

impl<Q, R> PortOwner<Q, R>
where
    Q: Serialize + DeserializeOwned + Send + Sync + 'static,
    R: Serialize + DeserializeOwned + Send + Sync + 'static,
{
    /// [`receive`](Self::receive), as a future (reply through the handle as usual: `reply`
    /// never blocks).
    pub fn receive_async(
        self: &Arc<Self>,
        timeout: Duration,
    ) -> impl Future<Output = Result<(Q, ReplyHandle<R>), PortError>> + use<Q, R> {
        let owner = Arc::clone(self);
        off_thread(self.port(), move || owner.receive(timeout))
    }

    /// [`sendall`](Self::sendall), as a future of the first reply (later replies: use the
    /// blocking form).
    pub fn sendall_async(
        self: &Arc<Self>,
        value: Q,
        timeout: Duration,
    ) -> impl Future<Output = Result<(String, R), PortError>> + use<Q, R>
    where
        R: Clone,
    {
        let owner = Arc::clone(self);
        off_thread(self.port(), move || {
            owner
                .sendall(&value, timeout)
                .map(|replies| replies.first().clone())
        })
    }
}

impl<T> Rendezvous<T>
where
    T: Serialize + DeserializeOwned + Send + Sync + 'static,
{
    /// [`wait`](Self::wait), as a future.
    pub fn wait_async<O, C>(
        self: &Arc<Self>,
        message: T,
        timeout: Duration,
        combine: C,
    ) -> impl Future<Output = Result<O, PortError>> + use<T, O, C>
    where
        O: Send + 'static,
        C: FnOnce(&BTreeMap<String, T>) -> O + Send + 'static,
    {
        let rendezvous = Arc::clone(self);
        off_thread(self.name(), move || {
            rendezvous.wait(&message, timeout, combine)
        })
    }
}

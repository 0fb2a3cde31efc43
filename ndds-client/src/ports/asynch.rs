//! Async forms of the blocking primitives: the same futures the blocking forms run on the
//! calling thread, awaited on the caller's executor instead — no call starts a thread. They
//! sleep on the consumers' queues like the blocking forms; their timeouts are the same, kept
//! by the process's one port timer thread (see `wait`).

use std::collections::BTreeMap;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::error::PortError;
use super::owner::{PortOwner, ReplyHandle};
use super::user::PortUser;
use super::waitfor::Rendezvous;
use super::wire::Usage;

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
    ) -> impl Future<Output = Result<R, PortError>> + Send + use<Q, R> {
        let user = Arc::clone(self);
        async move {
            user.require(Usage::Send)?;
            user.exchange(&value, timeout).await
        }
    }

    /// [`query`](Self::query), as a future.
    pub fn query_async(
        self: &Arc<Self>,
        value: Q,
        timeout: Duration,
    ) -> impl Future<Output = Result<R, PortError>> + Send + use<Q, R> {
        let user = Arc::clone(self);
        async move {
            user.require(Usage::Query)?;
            user.exchange(&value, timeout).await
        }
    }

    /// [`receive_all`](Self::receive_all), as a future.
    pub fn receive_all_async<F: FnOnce(&Q) -> R + Send + 'static>(
        self: &Arc<Self>,
        timeout: Duration,
        answer: F,
    ) -> impl Future<Output = Result<Q, PortError>> + Send + use<Q, R, F> {
        let user = Arc::clone(self);
        async move { user.receive_all_future(timeout, answer).await }
    }

    /// [`receive`](Self::receive), as a future.
    pub fn receive_async<F: FnOnce(&Q) -> R + Send + 'static>(
        self: &Arc<Self>,
        timeout: Duration,
        answer: F,
    ) -> impl Future<Output = Result<Q, PortError>> + Send + use<Q, R, F> {
        let user = Arc::clone(self);
        async move { user.receive_future(timeout, answer).await }
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
    ) -> impl Future<Output = Result<(Q, ReplyHandle<R>), PortError>> + Send + use<Q, R> {
        let owner = Arc::clone(self);
        async move { owner.receive_future(timeout).await }
    }

    /// [`sendall`](Self::sendall), as a future of the first reply (later replies: use the
    /// blocking form).
    pub fn sendall_async(
        self: &Arc<Self>,
        value: Q,
        timeout: Duration,
    ) -> impl Future<Output = Result<(String, R), PortError>> + Send + use<Q, R>
    where
        R: Clone,
    {
        let owner = Arc::clone(self);
        async move {
            let replies = owner.sendall_future(&value, timeout).await?;
            Ok(replies.first().clone())
        }
    }

    /// [`callall`](Self::callall), as a future.
    pub fn callall_async(
        self: &Arc<Self>,
        value: Q,
        timeout: Duration,
    ) -> impl Future<Output = Result<super::Answers<R>, PortError>> + Send + use<Q, R> {
        let owner = Arc::clone(self);
        async move { owner.callall_future(&value, timeout).await }
    }

    /// [`send_to`](Self::send_to), as a future.
    pub fn send_to_async(
        self: &Arc<Self>,
        task: &str,
        value: Q,
        timeout: Duration,
    ) -> impl Future<Output = Result<R, PortError>> + Send + use<Q, R> {
        let (owner, task) = (Arc::clone(self), task.to_owned());
        async move { owner.send_to_future(&task, &value, timeout).await }
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
    ) -> impl Future<Output = Result<O, PortError>> + Send + use<T, O, C>
    where
        O: Send + 'static,
        C: FnOnce(&BTreeMap<String, T>) -> O + Send + 'static,
    {
        let rendezvous = Arc::clone(self);
        async move { rendezvous.wait_future(&message, timeout, combine).await }
    }
}

//! User-written filters (Shin's `FILTER`): a task of the owner's module spliced into the port
//! at the owner's end. It takes each request before the owner does and decides, in its own
//! thread (`port-filter-<P>`), what becomes of it: passed on to the owner (as it came or
//! changed), answered by the filter itself, or refused with a reason the sender gets as
//! [`PortError::Refused`] (restriction `filter`): the filter's exception. Its own module talks
//! to it through the predefined port `FILTER`, here a [`FilterPort`] handed out with the
//! owner.
//!
//! The filter is the owner's: it sees only requests for this owner, from users the port's
//! restrictions admit; withdrawals of requests it passed on reach the owner's queue as for any
//! request. It runs under no lock of the port, and a panic in it refuses the request it was
//! deciding (and is logged) instead of ending the thread.

use std::collections::VecDeque;
use std::marker::PhantomData;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::owner::{OwnerShared, send_refusal, send_reply};
use super::wait::{self, Either};

/// What a filter does with one request.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict<Q, R> {
    /// Pass it on to the owner, with this message (the one that came, or another).
    Pass(Q),
    /// Answer the sender now: the owner never sees the request.
    Answer(R),
    /// Refuse it: the sender's `send` or `query` fails with [`PortError::Refused`]
    /// (restriction `filter`) carrying this reason.
    ///
    /// [`PortError::Refused`]: super::PortError::Refused
    Refuse(String),
}

/// A filter written for a port of requests `Q` and replies `R` (see the module docs).
pub trait RequestFilter<Q, R>: Send + 'static {
    /// What the filter's module sends it through the port `FILTER` ([`FilterPort`]).
    type Message: Send + 'static;

    /// Decides what becomes of `request`, sent by task `sender`.
    fn request(&mut self, sender: &str, request: Q) -> Verdict<Q, R>;

    /// Takes a message from the filter's own module (before the next request is decided).
    fn message(&mut self, message: Self::Message) {
        let _ = message;
    }

    /// The filter's own usages (empty, the default: whatever the port declares). At the
    /// owner's end they are what users must complement, since the filter is what takes their
    /// messages (the paper's BOUNDED_BUFFER declares `USAGE=RECEIVE` while GATE, its owner,
    /// declares `USAGE=SEND` towards it): they replace the restrictions' `usages`, users
    /// whose usages do not complement them are refused at match time.
    fn usages(&self) -> Vec<super::Usage> {
        Vec::new()
    }
}

/// The predefined port `FILTER`: how the owner's module talks to the filter of its port.
/// Sending never blocks; the filter takes the messages in order, before the next request.
pub struct FilterPort<M> {
    /// The owner whose filter thread to wake (`None` at a user's end: its filter runs on the
    /// sender's thread and takes its messages before each request).
    pub(crate) shared: Option<Arc<OwnerShared>>,
    pub(crate) inbox: Arc<Mutex<VecDeque<M>>>,
}

/// Messages waiting for a filter at most; more are refused by [`FilterPort::send`].
pub const FILTER_INBOX: usize = 1024;

impl<M> FilterPort<M> {
    /// Sends `message` to the filter; `false` (and the message is dropped) when
    /// [`FILTER_INBOX`] messages wait already.
    pub fn send(&self, message: M) -> bool {
        let mut inbox = self.inbox.lock().unwrap_or_else(|p| p.into_inner());
        if inbox.len() >= FILTER_INBOX {
            return false;
        }
        inbox.push_back(message);
        drop(inbox);
        if let Some(shared) = &self.shared {
            shared.changed.notify();
        }
        true
    }
}

/// The filter thread: runs until the owner stops.
pub(crate) fn run<Q, R, F>(shared: &OwnerShared, mut filter: F, inbox: &Mutex<VecDeque<F::Message>>)
where
    Q: Serialize + DeserializeOwned,
    R: Serialize,
    F: RequestFilter<Q, R>,
{
    let _types = PhantomData::<fn(Q) -> R>;
    loop {
        // The generation first: a stop after it wakes the wait below.
        let seen = shared.changed.generation();
        if shared.stop.load(Ordering::Acquire) {
            return;
        }
        take_messages(shared, &mut filter, inbox);
        let Some(requests) = shared.requests() else {
            // Replaced: nothing comes here any more (until the replacement goes).
            wait::block_on(shared.changed.changed(seen));
            continue;
        };
        let arrived = wait::block_on(wait::race(
            wait::next_sample(&requests),
            shared.changed.changed(seen),
        ));
        let mut request = match arrived {
            Either::Left(Some(sample)) => sample.value,
            Either::Left(None) => {
                wait::block_on(shared.changed.changed(seen));
                continue;
            }
            Either::Right(()) => continue,
        };
        if !shared.addressed_here(&request) {
            continue;
        }
        if request.withdraw {
            // It may have been passed on: the owner's queue drops it, or remembers it.
            shared.absorb(&mut shared.pending(), request);
            shared.changed.notify();
            continue;
        }
        if !shared.admitted(&request.user) {
            continue; // refused users get no answer: their own side reports the refusal
        }
        let value = match postcard::from_bytes::<Q>(&request.payload) {
            Ok(value) => value,
            Err(err) => {
                tracing::debug!(port = %shared.port, sender = %request.task, error = %err,
                    "a request the filter cannot decode: dropped");
                continue;
            }
        };
        // What the module sent before this request came is taken first.
        take_messages(shared, &mut filter, inbox);
        let verdict = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            filter.request(&request.task, value)
        }))
        .unwrap_or_else(|_| {
            tracing::error!(port = %shared.port, sender = %request.task,
                "the port's filter panicked deciding a request: refused");
            Verdict::Refuse("the port's filter failed (it panicked)".to_owned())
        });
        let answered = match verdict {
            Verdict::Pass(_) if shared.queue_len() >= super::owner::PENDING_LIMIT => {
                send_refusal(shared, &request, "the owner's queue is full".to_owned())
            }
            Verdict::Pass(value) => match postcard::to_stdvec(&value) {
                Ok(payload) => {
                    request.payload = payload;
                    shared.pending().push_back(request);
                    shared.changed.notify();
                    Ok(())
                }
                Err(err) => send_refusal(
                    shared,
                    &request,
                    format!("the filter's message does not encode: {err}"),
                ),
            },
            Verdict::Answer(reply) => match postcard::to_stdvec(&reply) {
                Ok(payload) => {
                    send_reply(shared, &request.user, &request.task, request.id, payload)
                }
                Err(err) => send_refusal(
                    shared,
                    &request,
                    format!("the filter's answer does not encode: {err}"),
                ),
            },
            Verdict::Refuse(reason) => send_refusal(shared, &request, reason),
        };
        if let Err(err) = answered {
            tracing::warn!(port = %shared.port, error = %err, "the filter could not answer a sender");
        }
    }
}

/// A filter at a user's end, as the user calls it: messages from its module first, then the
/// verdict on `request` from `sender`. A panic refuses the request.
pub(crate) type UserFilter<Q, R> = Box<dyn FnMut(&str, &Q) -> Verdict<Q, R> + Send>;

/// `filter` at the user's end of `port`, with the inbox of its FILTER port.
pub(crate) fn at_user<Q, R, F>(
    port: &str,
    mut filter: F,
) -> (UserFilter<Q, R>, FilterPort<F::Message>)
where
    Q: Clone + 'static,
    R: 'static,
    F: RequestFilter<Q, R>,
{
    let inbox = Arc::new(Mutex::new(VecDeque::new()));
    let taken = Arc::clone(&inbox);
    let port = port.to_owned();
    let decide: UserFilter<Q, R> = Box::new(move |sender: &str, request: &Q| {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            loop {
                let next = taken.lock().unwrap_or_else(|p| p.into_inner()).pop_front();
                let Some(message) = next else { break };
                filter.message(message);
            }
            filter.request(sender, request.clone())
        }))
        .unwrap_or_else(|_| {
            tracing::error!(port = %port, sender, "the user's filter panicked: request refused");
            Verdict::Refuse("the user's filter failed (it panicked)".to_owned())
        })
    });
    (
        decide,
        FilterPort {
            shared: None,
            inbox,
        },
    )
}

/// Gives the filter the messages its module sent, in order.
fn take_messages<Q, R, F: RequestFilter<Q, R>>(
    shared: &OwnerShared,
    filter: &mut F,
    inbox: &Mutex<VecDeque<F::Message>>,
) {
    loop {
        let next = inbox.lock().unwrap_or_else(|p| p.into_inner()).pop_front();
        let Some(message) = next else { break };
        let taken =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| filter.message(message)));
        if taken.is_err() {
            tracing::error!(port = %shared.port, "the port's filter panicked taking a message from its module");
        }
    }
}

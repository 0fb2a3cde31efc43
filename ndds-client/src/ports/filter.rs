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

use super::owner::{OwnerShared, PENDING_LIMIT, send_refusal, send_reply};
use super::wait::{self, Either};
use super::wire::Request;

/// What a filter does with one request.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict<Q, R> {
    /// Pass it on to the owner, with this message (the one that came, or another).
    Pass(Q),
    /// Answer the sender now: the owner never sees the request.
    Answer(R),
    /// Pass it on to the owner (with this message) *and* answer the sender now, so that it
    /// goes on without waiting for the owner: the owner's own reply to it is not sent. This
    /// is how a buffer decouples its senders from the owner (see [`BoundedBuffer`]). At a
    /// user's end the request goes out and the sender gets the answer without waiting for
    /// the owner's reply.
    Accept(Q, R),
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

    /// Whether the filter decides the next request now; `queued` is how many requests it
    /// passed on that the owner has not received yet (default: always). While it says no,
    /// requests wait at the filter, in order (read off the port, so that a sender that stops
    /// waiting withdraws its request before it is decided), and their senders wait for
    /// their answers; it is asked again each time the owner receives a request, a message
    /// comes through `FILTER` or a request arrives. Asked only at the owner's end (a user's
    /// filter decides on its sender's thread, which has nothing to wait for).
    fn room(&mut self, queued: usize) -> bool {
        let _ = queued;
        true
    }

    /// The restriction the port declares for this filter, which `ndds ports` shows and users
    /// see (default [`Filter::Task`](super::Filter::Task), a filter of the owner's own).
    fn declared(&self) -> super::Filter {
        super::Filter::Task
    }
}

/// The bounded buffer of Shin's paper, written as an ordinary [`RequestFilter`]: it takes up
/// to `capacity` requests ahead of the owner and answers each sender at once (with
/// `answer()`, `()` for [`BoundedBuffer::new`]), so a `send` returns as soon as the buffer has
/// room; when `capacity` requests wait for the owner, senders wait for room (and time out as
/// their ports say). `Restrictions { filter: Some(Filter::BoundedBuffer { capacity }) }` on
/// [`PortOwner::declare_with`](super::PortOwner::declare_with) splices in this filter.
pub struct BoundedBuffer<R = ()> {
    capacity: usize,
    answer: Box<dyn Fn() -> Option<R> + Send>,
}

impl BoundedBuffer<()> {
    /// A buffer of `capacity` requests (at least 1) answering `()`.
    pub fn new(capacity: usize) -> Self {
        Self::answering(capacity, || ())
    }
}

impl<R: 'static> BoundedBuffer<R> {
    /// A buffer of `capacity` requests (at least 1) that answers each sender with
    /// `answer()`.
    pub fn answering(capacity: usize, answer: impl Fn() -> R + Send + 'static) -> Self {
        BoundedBuffer {
            capacity: capacity.max(1),
            answer: Box::new(move || Some(answer())),
        }
    }

    /// For a reply type whose encoding is empty (`()`-shaped, checked by its type
    /// description): each answer is that empty encoding decoded.
    pub(crate) fn unit_shaped(capacity: usize) -> Self
    where
        R: DeserializeOwned,
    {
        BoundedBuffer {
            capacity: capacity.max(1),
            answer: Box::new(|| postcard::from_bytes(&[]).ok()),
        }
    }
}

impl<R> std::fmt::Debug for BoundedBuffer<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BoundedBuffer")
            .field("capacity", &self.capacity)
            .finish_non_exhaustive()
    }
}

impl<Q, R: 'static> RequestFilter<Q, R> for BoundedBuffer<R> {
    type Message = ();

    fn request(&mut self, _sender: &str, request: Q) -> Verdict<Q, R> {
        match (self.answer)() {
            Some(answer) => Verdict::Accept(request, answer),
            None => Verdict::Refuse("the buffer cannot make its answer".to_owned()),
        }
    }

    /// It receives the users' messages (the paper's BOUNDED_BUFFER: `USAGE=RECEIVE`).
    fn usages(&self) -> Vec<super::Usage> {
        vec![super::Usage::Receive]
    }

    fn room(&mut self, queued: usize) -> bool {
        queued < self.capacity
    }

    fn declared(&self) -> super::Filter {
        super::Filter::BoundedBuffer {
            capacity: u32::try_from(self.capacity).unwrap_or(u32::MAX),
        }
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
    // Read off the port, not decided yet (the filter had no room for them).
    let mut waiting: VecDeque<Request> = VecDeque::new();
    loop {
        // The generation first: a stop or a change after it wakes the waits below.
        let seen = shared.changed.generation();
        if shared.stop.load(Ordering::Acquire) {
            return;
        }
        take_messages(shared, &mut filter, inbox);
        let Some(requests) = shared.requests() else {
            // Replaced: nothing comes here any more (until the replacement goes), and the
            // senders of what waits here send it again to the replacement.
            waiting.clear();
            wait::block_on(shared.changed.changed(seen));
            continue;
        };
        while !waiting.is_empty() && has_room(shared, &mut filter) {
            if let Some(request) = waiting.pop_front() {
                // What the module sent before this request is decided is taken first.
                take_messages(shared, &mut filter, inbox);
                decide(shared, &mut filter, request);
            }
        }
        if waiting.len() >= PENDING_LIMIT {
            // Full: the rest waits on the port until the owner takes something.
            wait::block_on(shared.changed.changed(seen));
            continue;
        }
        let arrived = wait::block_on(wait::race(
            wait::next_sample(&requests),
            shared.changed.changed(seen),
        ));
        let request = match arrived {
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
            // Not decided yet: dropped here. Passed on: the owner's queue drops it, or
            // remembers it if the owner has it already.
            if !shared.drop_withdrawn(&mut waiting, &request) {
                shared.absorb(&mut shared.pending(), request);
                shared.changed.notify();
            }
            continue;
        }
        if !shared.admitted(&request.user) {
            continue; // refused users get no answer: their own side reports the refusal
        }
        waiting.push_back(request);
    }
}

/// Whether `filter` takes a request now (a panic says no, and is logged). Never while the
/// owner's queue is full: what waits is held, not refused.
fn has_room<Q, R, F: RequestFilter<Q, R>>(shared: &OwnerShared, filter: &mut F) -> bool {
    let queued = shared.queue_len();
    if queued >= PENDING_LIMIT {
        return false;
    }
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| filter.room(queued)))
        .unwrap_or_else(|_| {
            tracing::error!(port = %shared.port, "the port's filter panicked saying whether it has room");
            false
        })
}

/// Has `filter` decide `request` and carries its verdict out.
fn decide<Q, R, F>(shared: &OwnerShared, filter: &mut F, mut request: Request)
where
    Q: Serialize + DeserializeOwned,
    R: Serialize,
    F: RequestFilter<Q, R>,
{
    let value = match postcard::from_bytes::<Q>(&request.payload) {
        Ok(value) => value,
        Err(err) => {
            // Another format than the port's: its sender is told rather than left waiting.
            let reason = format!("the request does not decode as the port's message: {err}");
            report(shared, send_refusal(shared, &request, reason));
            return;
        }
    };
    let verdict = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        filter.request(&request.task, value)
    }))
    .unwrap_or_else(|_| {
        tracing::error!(port = %shared.port, sender = %request.task,
            "the port's filter panicked deciding a request: refused");
        Verdict::Refuse("the port's filter failed (it panicked)".to_owned())
    });
    let (passed, answer) = match verdict {
        Verdict::Pass(value) => (Some(value), None),
        Verdict::Answer(reply) => (None, Some(reply)),
        Verdict::Accept(value, reply) => (Some(value), Some(reply)),
        Verdict::Refuse(reason) => {
            report(shared, send_refusal(shared, &request, reason));
            return;
        }
    };
    // Encoded before anything is sent, so that a bad encoding refuses the request whole.
    let (passed, answer) = match (encode(passed, "message"), encode(answer, "answer")) {
        (Ok(passed), Ok(answer)) => (passed, answer),
        (Err(reason), _) | (_, Err(reason)) => {
            report(shared, send_refusal(shared, &request, reason));
            return;
        }
    };
    if passed.is_some() && shared.queue_len() >= PENDING_LIMIT {
        let reason = "the owner's queue is full".to_owned();
        report(shared, send_refusal(shared, &request, reason));
        return;
    }
    // Answered only if the answer went out: else the owner's reply still reaches the sender.
    let mut answered = false;
    if let Some(answer) = answer {
        let sent = send_reply(shared, &request.user, &request.task, request.id, answer);
        answered = sent.is_ok();
        report(shared, sent);
    }
    if let Some(payload) = passed {
        request.payload = payload;
        // Answered already: the owner's reply to it is not sent.
        request.answered = answered;
        shared.pending().push_back(request);
        shared.changed.notify();
    }
}

/// `part` of a verdict (the filter's `what`) encoded, or why it does not encode.
fn encode<T: Serialize>(part: Option<T>, what: &str) -> Result<Option<Vec<u8>>, String> {
    part.map(|value| postcard::to_stdvec(&value))
        .transpose()
        .map_err(|err| format!("the filter's {what} does not encode: {err}"))
}

/// Logs a verdict that could not be carried out.
fn report(shared: &OwnerShared, sent: Result<(), super::PortError>) {
    if let Err(err) = sent {
        tracing::warn!(port = %shared.port, error = %err, "the filter could not answer a sender");
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

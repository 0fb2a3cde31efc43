//! [`PortUser`]: a task that uses a port — `send` blocks until the owner replies (or the
//! timeout). Several threads may send through one user at once; each gets its own reply.

use std::collections::{HashMap, VecDeque};
use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::error::PortError;
use super::sendall::{Broadcast, BroadcastReply};
use super::wait::{self, Either, Notify};
use super::wire::{OwnerInfo, Reply, Request, Usage, UserInfo};
use super::{check_name, declaring_producer, reliable_consumer, reliable_producer, topic};
use crate::{Consumer, Event, Guid, Notification, Participant, Producer, TypeDescription};

/// How long a user of a port with a maximum of active users waits to be admitted once it
/// knows the owner; past that, the port is full.
pub const ADMISSION_WAIT: Duration = Duration::from_secs(1);

/// Messages from the owner a user keeps for its next call when they cannot be answered yet,
/// per operation, at most.
pub const HELD_MESSAGES: usize = 16;

/// A user of a port: sends requests of type `Q`, gets replies of type `R`.
pub struct PortUser<Q, R> {
    usages: Vec<Usage>,
    declared: Instant,
    /// The user's declaration, written once and kept for owners that match later.
    _declaration: Producer<UserInfo>,
    broadcasts: Consumer<Broadcast>,
    /// Messages the owner sends to this user alone (with usage `Receive` or `Response`).
    to_me: Option<Consumer<Broadcast>>,
    broadcast_replies: Producer<BroadcastReply>,
    port: String,
    task: String,
    user: String,
    requests: Producer<Request>,
    replies: Consumer<Reply>,
    owners: Consumer<OwnerInfo>,
    next_id: AtomicU64,
    demux: Mutex<Demux>,
    /// Told when a sender hands a reply it took to the sender waiting for it.
    handed: Notify,
    /// Told when one sender takes an owner's declaration or loss off the topic, so that the
    /// other senders waiting for an owner look again (the event is gone from the queue).
    owners_noted: Notify,
    formats: (u64, u64),
    /// A filter at this user's end, if it was declared with one.
    filter: Option<Mutex<super::filter::UserFilter<Q, R>>>,
    _types: PhantomData<fn(Q) -> R>,
}

#[derive(Default)]
struct Demux {
    /// Replies taken off the topic by one sender for another.
    waiting: HashMap<u64, Reply>,
    /// Requests whose senders still wait, with the incarnation of the owner each is for
    /// (replies to others, and from other owners, are dropped).
    awaiting: HashMap<u64, u64>,
    /// Owners present: their declaration's producer -> their latest declaration.
    owners: HashMap<Guid, OwnerInfo>,
    /// When each owner was first seen (admission takes a moment).
    first_seen: HashMap<Guid, Instant>,
    /// Not admitted yet by a port with a maximum of active users: refused from then on.
    admission_ends: Option<Instant>,
    /// Messages from the owner taken off their topic that could not be answered then (the
    /// owner was in question: a second owner): the next `receive` or `receive_all` tries them
    /// first, while their owner is there (per operation, at most [`HELD_MESSAGES`]).
    held: HashMap<&'static str, VecDeque<Broadcast>>,
}

impl PortUser<super::Encoded, super::Encoded> {
    /// Declares `task` a user of `port` with message types described at run time (a
    /// binding's, see [`Encoded`](super::Encoded)): it matches an owner whose request and
    /// reply types have these descriptions' fingerprints, in any language.
    pub fn declare_described(
        participant: &Participant,
        port: &str,
        task: &str,
        usages: &[Usage],
        request: &TypeDescription,
        reply: &TypeDescription,
    ) -> Result<Self, PortError> {
        let formats = (request.fingerprint(), reply.fingerprint());
        Self::declare_formats(participant, port, task, usages, formats)
    }
}

/// Forgets a request's reply when its sender stops waiting (also when an async `send` is
/// dropped).
struct Awaiting<'a> {
    demux: &'a Mutex<Demux>,
    id: u64,
}

impl Drop for Awaiting<'_> {
    fn drop(&mut self) {
        let mut demux = self.demux.lock().unwrap_or_else(|p| p.into_inner());
        demux.awaiting.remove(&self.id);
        demux.waiting.remove(&self.id);
    }
}

/// A request written and not answered: withdrawn when its sender stops waiting — a
/// timeout, and also an async `send` or `query` dropped before its reply.
struct Outstanding<'a, Q: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned> {
    user: &'a PortUser<Q, R>,
    id: u64,
    owner: u64,
    answered: bool,
}

impl<Q: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned> Drop
    for Outstanding<'_, Q, R>
{
    fn drop(&mut self) {
        if !self.answered {
            self.user.withdraw(self.id, self.owner);
        }
    }
}

impl<Q: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned> PortUser<Q, R> {
    /// Declares `task` a user of `port` that sends (usage [`Usage::Send`]).
    pub fn declare(participant: &Participant, port: &str, task: &str) -> Result<Self, PortError> {
        Self::declare_with(participant, port, task, &[Usage::Send])
    }

    /// Declares `task` a user of `port` with these usages (what the owner's usage restriction
    /// checks; an operation not declared here is refused locally).
    pub fn declare_with(
        participant: &Participant,
        port: &str,
        task: &str,
        usages: &[Usage],
    ) -> Result<Self, PortError> {
        let formats = super::owner::formats_of::<Q, R>(port)?;
        Self::declare_formats(participant, port, task, usages, formats)
    }

    /// [`declare_with`](Self::declare_with) checking the owner's formats against `formats`
    /// (request, reply fingerprints).
    fn declare_formats(
        participant: &Participant,
        port: &str,
        task: &str,
        usages: &[Usage],
        formats: (u64, u64),
    ) -> Result<Self, PortError> {
        check_name(port)?;
        let user = format!("{:016x}", fastrand::u64(..));
        let declaration = declaring_producer::<UserInfo>(participant, port, &topic(port, "users"))?;
        let info = UserInfo {
            user: user.clone(),
            task: task.to_owned(),
            usages: usages.to_vec(),
        };
        declaration
            .write(&info)
            .map_err(|source| PortError::Write {
                port: port.to_owned(),
                what: "the user's declaration".to_owned(),
                source,
            })?;
        Ok(Self {
            usages: usages.to_vec(),
            declared: Instant::now(),
            _declaration: declaration,
            broadcasts: reliable_consumer(participant, port, &topic(port, "all"))?,
            to_me: if usages.contains(&Usage::Receive) || usages.contains(&Usage::Response) {
                Some(reliable_consumer(
                    participant,
                    port,
                    &topic(port, &format!("to/{user}")),
                )?)
            } else {
                None
            },
            broadcast_replies: reliable_producer(participant, port, &topic(port, "all-reply"))?,
            requests: reliable_producer::<Request>(participant, port, &topic(port, "request"))?,
            replies: reliable_consumer::<Reply>(
                participant,
                port,
                &topic(port, &format!("reply/{user}")),
            )?,
            owners: reliable_consumer::<OwnerInfo>(participant, port, &topic(port, "owner"))?,
            port: port.to_owned(),
            task: task.to_owned(),
            user,
            next_id: AtomicU64::new(1),
            demux: Mutex::new(Demux::default()),
            handed: Notify::default(),
            owners_noted: Notify::default(),
            formats,
            filter: None,
            _types: PhantomData,
        })
    }

    /// Declares `task` a user of `port` with these usages and a filter of its own spliced in
    /// at its end (Shin's FILTER at the user's end): every `send` and `query` goes through
    /// `filter` first, which passes it on to the owner (as it came or changed), answers it
    /// itself (the owner never sees it), or refuses it (the caller gets
    /// [`PortError::Refused`] with restriction `filter`). The filter runs on the sending
    /// thread, one request at a time; its module talks to it through the returned
    /// [`FilterPort`](super::FilterPort), whose messages it takes before the next request.
    pub fn declare_filtered<F>(
        participant: &Participant,
        port: &str,
        task: &str,
        usages: &[Usage],
        filter: F,
    ) -> Result<(Self, super::FilterPort<F::Message>), PortError>
    where
        Q: Clone + 'static,
        R: 'static,
        F: super::RequestFilter<Q, R>,
    {
        let mut user = Self::declare_with(participant, port, task, usages)?;
        let (decide, filter_port) = super::filter::at_user(port, filter);
        user.filter = Some(Mutex::new(decide));
        Ok((user, filter_port))
    }

    /// The port's name.
    pub fn port(&self) -> &str {
        &self.port
    }

    fn demux(&self) -> MutexGuard<'_, Demux> {
        self.demux.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Takes an owner's declaration or its loss.
    fn note_owner(demux: &mut Demux, event: Event<OwnerInfo>) {
        match event {
            Event::Sample(sample) => {
                let writer = sample.info.writer;
                demux.first_seen.entry(writer).or_insert_with(Instant::now);
                demux.owners.insert(writer, sample.value);
            }
            Event::Notification(Notification::ProducerLost { writer, .. }) => {
                demux.owners.remove(&writer);
                demux.first_seen.remove(&writer);
            }
            Event::Notification(_) => {}
        }
    }

    /// Waits for the next owner declaration or loss and takes it, or for another sender to
    /// take one (after generation `seen` of `owners_noted`).
    async fn owner_event(&self, seen: u64) {
        let mine = async {
            if let Ok(mut events) = self.owners.events()
                && let Some(event) = wait::next(&mut events).await
            {
                Self::note_owner(&mut self.demux(), event);
                self.owners_noted.notify();
                return;
            }
            std::future::pending::<()>().await;
        };
        wait::race(mine, self.owners_noted.changed(seen)).await;
    }

    /// The owner now — the one of the highest takeover claim — as its task and incarnation,
    /// or an error when two share that claim or the formats differ; `None` while none is
    /// known (or it has not admitted this user yet).
    fn owner(&self, demux: &mut Demux) -> Result<Option<(String, u64)>, PortError> {
        let mut noted = false;
        while let Ok(event) = self.owners.try_recv_event() {
            Self::note_owner(demux, event);
            noted = true;
        }
        if noted {
            self.owners_noted.notify();
        }
        demux.admission_ends = None;
        let top = demux.owners.values().map(|o| o.claim).max();
        let mut owners: Vec<(&Guid, &OwnerInfo)> = demux
            .owners
            .iter()
            .filter(|(_, o)| Some(o.claim) == top)
            .collect();
        owners.sort_by(|(_, a), (_, b)| a.task.cmp(&b.task).then(a.pid.cmp(&b.pid)));
        match owners.as_slice() {
            [] => Ok(None),
            [(writer, owner)] => {
                let refused = |restriction: &'static str, detail: String| PortError::Refused {
                    port: self.port.clone(),
                    owner: owner.task.clone(),
                    user: self.task.clone(),
                    restriction,
                    detail,
                };
                if let Some((what, why)) = owner.restrictions.refusal(&self.task, &self.usages) {
                    return Err(refused(what, why));
                }
                if owner.restrictions.restricted() && !owner.admitted.contains(&self.user) {
                    // The owner admits users as it hears them; past a moment, it is full.
                    let since = demux
                        .first_seen
                        .get(*writer)
                        .copied()
                        .unwrap_or_else(Instant::now)
                        .max(self.declared);
                    if let Some(max) = owner.restrictions.max_users {
                        if since.elapsed() > ADMISSION_WAIT {
                            return Err(refused(
                                "maximum active users",
                                format!("{max} active users already"),
                            ));
                        }
                        demux.admission_ends = Some(since + ADMISSION_WAIT);
                    }
                    return Ok(None);
                }
                if (owner.request_format, owner.reply_format) != self.formats {
                    return Err(PortError::Format {
                        port: self.port.clone(),
                        owner: owner.task.clone(),
                        user: self.task.clone(),
                        owner_formats: format!(
                            "{:016x}/{:016x}",
                            owner.request_format, owner.reply_format
                        ),
                        user_formats: format!("{:016x}/{:016x}", self.formats.0, self.formats.1),
                    });
                }
                Ok(Some((owner.task.clone(), owner.incarnation)))
            }
            [(_, a), (_, b), ..] => Err(PortError::SecondOwner {
                port: self.port.clone(),
                first: format!("{} (pid {})", a.task, a.pid),
                second: format!("{} (pid {})", b.task, b.pid),
            }),
        }
    }

    /// Waits until the owner is known, unique, of our formats and has admitted this user;
    /// its task and incarnation, or `None` when `deadline` passes first. The owner's timeout
    /// restriction, counted from `start`, shortens `deadline`.
    async fn current_owner(
        &self,
        start: Instant,
        deadline: &mut Option<Instant>,
    ) -> Result<Option<(String, u64)>, PortError> {
        loop {
            let seen = self.owners_noted.generation();
            let admission_ends = {
                let mut demux = self.demux();
                if let Some(owner) = self.owner(&mut demux)? {
                    let declared = demux
                        .owners
                        .values()
                        .find(|o| o.incarnation == owner.1)
                        .and_then(|o| o.restrictions.timeout_ms);
                    if let Some(ms) = declared {
                        let limit = wait::deadline(start, Duration::from_millis(ms));
                        *deadline = (*deadline).into_iter().chain(limit).min();
                    }
                    return Ok(Some(owner));
                }
                demux.admission_ends
            };
            if deadline.is_some_and(|at| Instant::now() >= at) {
                return Ok(None);
            }
            let until = (*deadline).into_iter().chain(admission_ends).min();
            wait::timeout_at(until, self.owner_event(seen)).await;
        }
    }

    /// Sends `value` and waits (at most `timeout`, or the port's timeout restriction if
    /// shorter) for the owner's reply.
    pub fn send(&self, value: &Q, timeout: Duration) -> Result<R, PortError> {
        self.require(Usage::Send)?;
        wait::block_on(self.exchange(value, timeout))
    }

    /// Refuses locally an operation this user did not declare.
    pub(crate) fn require(&self, usage: Usage) -> Result<(), PortError> {
        if self.usages.contains(&usage) {
            return Ok(());
        }
        Err(self.undeclared(usage))
    }

    /// The refusal of an operation this user did not declare.
    fn undeclared(&self, usage: Usage) -> PortError {
        PortError::Refused {
            port: self.port.clone(),
            owner: String::new(),
            user: self.task.clone(),
            restriction: "usage",
            detail: format!(
                "{usage:?} was not declared by this user (declared: {:?})",
                self.usages
            ),
        }
    }

    /// One request and its reply: `send` and `query` as a future.
    pub(crate) async fn exchange(&self, value: &Q, timeout: Duration) -> Result<R, PortError> {
        // A filter at this end decides first (under its own lock, no port's).
        let passed;
        let mut accepted = None;
        let value = match &self.filter {
            None => value,
            Some(filter) => {
                let verdict = (filter.lock().unwrap_or_else(|p| p.into_inner()))(&self.task, value);
                match verdict {
                    super::Verdict::Pass(changed) => {
                        passed = changed;
                        &passed
                    }
                    super::Verdict::Accept(changed, answer) => {
                        passed = changed;
                        accepted = Some(answer);
                        &passed
                    }
                    super::Verdict::Answer(answer) => return Ok(answer),
                    super::Verdict::Refuse(reason) => {
                        return Err(PortError::Refused {
                            port: self.port.clone(),
                            owner: format!("{} (its own filter)", self.task),
                            user: self.task.clone(),
                            restriction: "filter",
                            detail: reason,
                        });
                    }
                }
            }
        };
        let start = Instant::now();
        let mut deadline = wait::deadline(start, timeout);
        let timed_out = |owner: Option<String>| PortError::Timeout {
            port: self.port.clone(),
            operation: "send",
            task: self.task.clone(),
            owner,
            waited: start.elapsed(),
        };
        // An owner must be known (and unique, with our formats) before the request goes out.
        let Some((mut owner, mut incarnation)) = self.current_owner(start, &mut deadline).await?
        else {
            return Err(timed_out(None));
        };
        if !wait::matched_by(&self.requests, deadline).await {
            return Err(timed_out(Some(owner)));
        }
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let payload = postcard::to_stdvec(value).map_err(|e| PortError::Codec {
            port: self.port.clone(),
            what: "encoding a request",
            reason: e.to_string(),
        })?;
        self.demux().awaiting.insert(id, incarnation);
        let _awaiting = Awaiting {
            demux: &self.demux,
            id,
        };
        self.write_request(id, incarnation, &payload)?;
        if let Some(answer) = accepted {
            // Answered by the filter: the owner's reply, when it comes, finds nobody waiting.
            return Ok(answer);
        }
        let mut outstanding = Outstanding {
            user: self,
            id,
            owner: incarnation,
            answered: false,
        };
        // A tightly-coupled port's reply is busy-waited for at first.
        let class = self
            .demux()
            .owners
            .values()
            .find(|o| o.incarnation == incarnation)
            .map(|o| o.restrictions.class)
            .unwrap_or_default();
        if !class.spin().is_zero() {
            wait::spin_until(Instant::now() + class.spin());
        }
        // The request is for one owner. If that owner is replaced (taken over) before it
        // replies, the request goes again to the replacement: the replaced owner drops or
        // cannot answer it, and its replies would be dropped here anyway.
        let reply = loop {
            let replaced = self.replaced(incarnation);
            match wait::timeout_at(
                deadline,
                wait::race(self.reply_to(id, incarnation), replaced),
            )
            .await
            {
                None => return Err(timed_out(Some(owner))), // `outstanding` withdraws it
                Some(Either::Left(reply)) => {
                    outstanding.answered = true;
                    break reply;
                }
                Some(Either::Right((task, replacement))) => {
                    tracing::info!(port = %self.port, user = %self.task, from = %owner, to = %task,
                        "the port's owner was replaced while a request waited: sent again to the replacement");
                    self.withdraw(id, incarnation);
                    (owner, incarnation) = (task, replacement);
                    outstanding.owner = incarnation;
                    self.demux().awaiting.insert(id, incarnation);
                    self.write_request(id, incarnation, &payload)?;
                }
            }
        };
        if let Some(reason) = reply.refused {
            return Err(PortError::Refused {
                port: self.port.clone(),
                owner,
                user: self.task.clone(),
                restriction: "filter",
                detail: reason,
            });
        }
        postcard::from_bytes(&reply.payload).map_err(|e| PortError::Codec {
            port: self.port.clone(),
            what: "decoding a reply",
            reason: e.to_string(),
        })
    }

    /// Writes request `id` for the owner of incarnation `owner`.
    fn write_request(&self, id: u64, owner: u64, payload: &[u8]) -> Result<(), PortError> {
        self.requests
            .write(&Request {
                id,
                user: self.user.clone(),
                task: self.task.clone(),
                payload: payload.to_vec(),
                withdraw: false,
                owner,
                answered: false,
            })
            .map_err(|source| PortError::Write {
                port: self.port.clone(),
                what: "a request".to_owned(),
                source,
            })
    }

    /// Waits until the owner of the port is another than the one of incarnation `current`
    /// (which was replaced) and has admitted this user: the replacement's task and
    /// incarnation. A conflict or a refusal keeps it waiting: the request's own deadline
    /// ends that.
    async fn replaced(&self, current: u64) -> (String, u64) {
        loop {
            let seen = self.owners_noted.generation();
            if let Ok(Some((task, incarnation))) = self.owner(&mut self.demux())
                && incarnation != current
            {
                return (task, incarnation);
            }
            self.owner_event(seen).await;
        }
    }

    /// Tells the owner that nobody waits for request `id` any more: it drops the request if
    /// it has not received it yet, so a send that timed out (or an async send dropped) is
    /// not acted on later. Best effort: the owner may have received the request already
    /// (then its reply is dropped here), and a withdrawal that cannot be written is only
    /// logged. The write may wait for the requests' reliable window, at most the producer's
    /// write timeout (1 s by default).
    fn withdraw(&self, id: u64, owner: u64) {
        let withdrawal = Request {
            id,
            user: self.user.clone(),
            task: self.task.clone(),
            payload: Vec::new(),
            withdraw: true,
            owner,
            answered: false,
        };
        if let Err(err) = self.requests.write(&withdrawal) {
            tracing::debug!(port = %self.port, error = %err, "withdrawal of a timed-out request not sent");
        }
    }

    /// Takes the next message the owner sent to all users (`sendall`), waiting at most
    /// `timeout`, and answers it with `answer`; returns the message.
    pub fn receive_all(
        &self,
        timeout: Duration,
        answer: impl FnOnce(&Q) -> R,
    ) -> Result<Q, PortError> {
        wait::block_on(self.receive_all_future(timeout, answer))
    }

    pub(crate) async fn receive_all_future(
        &self,
        timeout: Duration,
        answer: impl FnOnce(&Q) -> R,
    ) -> Result<Q, PortError> {
        self.require(Usage::ReceiveAll)?;
        self.answer_owner(&self.broadcasts, "receive_all", timeout, |q| {
            Some(answer(q))
        })
        .await
    }

    /// [`receive_all`](Self::receive_all) whose `answer` may decline (return `None`): the
    /// message is taken and returned all the same, and the owner gets no reply from this
    /// user (its `callall` lists the user as missing). For answers that can fail, such as a
    /// binding's call into another language: no reply is better than a wrong one.
    pub fn receive_all_or_decline(
        &self,
        timeout: Duration,
        answer: impl FnOnce(&Q) -> Option<R>,
    ) -> Result<Q, PortError> {
        wait::block_on(async {
            self.require(Usage::ReceiveAll)?;
            self.answer_owner(&self.broadcasts, "receive_all", timeout, answer)
                .await
        })
    }

    /// Takes the next message the owner sent to this user alone (`send_to`), waiting at most
    /// `timeout`, and answers it with `answer`; returns the message. The user must have
    /// declared usage [`Receive`](Usage::Receive) (messages) or [`Response`](Usage::Response)
    /// (queries: `answer` is its response handler).
    pub fn receive(&self, timeout: Duration, answer: impl FnOnce(&Q) -> R) -> Result<Q, PortError> {
        wait::block_on(self.receive_future(timeout, answer))
    }

    pub(crate) async fn receive_future(
        &self,
        timeout: Duration,
        answer: impl FnOnce(&Q) -> R,
    ) -> Result<Q, PortError> {
        // Its stream exists when, and only when, the user declared `Receive` or `Response`.
        let Some(to_me) = &self.to_me else {
            return Err(self.undeclared(Usage::Receive));
        };
        self.answer_owner(to_me, "receive", timeout, |q| Some(answer(q)))
            .await
    }

    /// Takes the next message from the owner on `source` and answers it with `answer` (or
    /// not, if `answer` declines).
    async fn answer_owner(
        &self,
        source: &Consumer<Broadcast>,
        operation: &'static str,
        timeout: Duration,
        answer: impl FnOnce(&Q) -> Option<R>,
    ) -> Result<Q, PortError> {
        let (message, value) = self.take_from_owner(source, operation, timeout).await?;
        if let Some(reply) = answer(&value) {
            let payload = self.encode_reply(&reply)?;
            self.answer_message(&message, payload, timeout).await?;
        }
        Ok(value)
    }

    /// The next message the owner sent to this user alone (usage `Receive` or `Response`),
    /// not answered yet: [`answer_message`](Self::answer_message) answers it.
    pub(crate) async fn take_to_me(&self, timeout: Duration) -> Result<(Broadcast, Q), PortError> {
        let Some(to_me) = &self.to_me else {
            return Err(self.undeclared(Usage::Response));
        };
        self.take_from_owner(to_me, "receive", timeout).await
    }

    /// Takes the next message from the owner on `source`, decoded.
    async fn take_from_owner(
        &self,
        source: &Consumer<Broadcast>,
        operation: &'static str,
        timeout: Duration,
    ) -> Result<(Broadcast, Q), PortError> {
        // A user the owner's restrictions refuse takes no part (known owners only: one not
        // heard yet is judged when its message comes).
        self.owner(&mut self.demux())?;
        let start = Instant::now();
        let deadline = wait::deadline(start, timeout);
        let timed_out = || PortError::Timeout {
            port: self.port.clone(),
            operation,
            task: self.task.clone(),
            owner: None,
            waited: start.elapsed(),
        };
        let broadcast = loop {
            let held = self
                .demux()
                .held
                .get_mut(operation)
                .and_then(VecDeque::pop_front);
            let broadcast = match held {
                // Kept from a call that found the owner in question: worth trying again only
                // while its owner is there (not waited for: it was heard already).
                Some(broadcast)
                    if !self
                        .demux()
                        .owners
                        .values()
                        .any(|o| o.incarnation == broadcast.owner) =>
                {
                    tracing::debug!(port = %self.port, user = %self.task,
                        "a kept message from an owner that is gone: dropped");
                    continue;
                }
                Some(broadcast) => broadcast,
                None => {
                    wait::timeout_at(deadline, wait::next_sample(source))
                        .await
                        .flatten()
                        .ok_or_else(timed_out)?
                        .value
                }
            };
            // The owner is known once its message came, but it may not have heard (admitted)
            // this user yet: a reply sent now would be dropped as from a stranger. Refused,
            // the message is not answered; one from an owner replaced meanwhile is skipped.
            // Taken off the topic, the message is answered or lost: whatever the caller's
            // timeout, the owner gets a moment to admit this user.
            let grace = deadline.map(|at| at.max(Instant::now() + super::owner::REPLY_MATCH));
            match self.answerable(&broadcast, operation, start, grace).await {
                Ok(true) => break broadcast,
                Ok(false) => {}
                Err(err @ PortError::SecondOwner { .. }) => {
                    // A conflict between owners passes (one of them goes): kept, not lost, for
                    // the next call, which answers it if its owner is the one that stays.
                    let mut demux = self.demux();
                    let held = demux.held.entry(operation).or_default();
                    if held.len() < HELD_MESSAGES {
                        held.push_back(broadcast);
                        tracing::debug!(port = %self.port, user = %self.task, error = %err,
                            "a message from the owner cannot be answered yet: kept for the next call");
                    } else {
                        tracing::warn!(port = %self.port, user = %self.task,
                            "too many messages from the owner wait to be answered: one dropped");
                    }
                    return Err(err);
                }
                Err(err) => {
                    tracing::warn!(port = %self.port, user = %self.task, error = %err,
                        "a message from the owner could not be answered: dropped");
                    return Err(err);
                }
            }
            tracing::debug!(port = %self.port, user = %self.task,
                "a message from a replaced owner: not answered");
        };
        let value: Q = postcard::from_bytes(&broadcast.payload).map_err(|e| PortError::Codec {
            port: self.port.clone(),
            what: "decoding a message from the owner",
            reason: e.to_string(),
        })?;
        Ok((broadcast, value))
    }

    /// A reply to the owner, encoded.
    pub(crate) fn encode_reply(&self, reply: &R) -> Result<Vec<u8>, PortError> {
        postcard::to_stdvec(reply).map_err(|e| PortError::Codec {
            port: self.port.clone(),
            what: "encoding a reply to the owner",
            reason: e.to_string(),
        })
    }

    /// Answers the owner's `message` with `payload` (an encoded reply).
    pub(crate) async fn answer_message(
        &self,
        message: &Broadcast,
        payload: Vec<u8>,
        timeout: Duration,
    ) -> Result<(), PortError> {
        // The message came, so its owner exists; its reply stream may not have matched this
        // user yet (across hosts discovery is not symmetric in time): a reliable reply written
        // before the match would reach nobody. Wait briefly, as first replies do.
        let briefly = wait::deadline(Instant::now(), super::owner::REPLY_MATCH.min(timeout));
        wait::matched_by(&self.broadcast_replies, briefly).await;
        self.broadcast_replies
            .write(&BroadcastReply {
                owner: message.owner,
                id: message.id,
                task: self.task.clone(),
                user: self.user.clone(),
                payload,
            })
            .map_err(|source| PortError::Write {
                port: self.port.clone(),
                what: "a reply to the owner".to_owned(),
                source,
            })
    }

    /// Whether `broadcast` comes from the owner now (one that admitted this user), waiting
    /// by `deadline` for that owner's declaration if it is not known yet; `false` for one
    /// from an owner replaced meanwhile. A timeout when the owner stays unknown or has not
    /// admitted this user by then; the refusal when it refuses this user.
    async fn answerable(
        &self,
        broadcast: &Broadcast,
        operation: &'static str,
        start: Instant,
        deadline: Option<Instant>,
    ) -> Result<bool, PortError> {
        let timed_out = || PortError::Timeout {
            port: self.port.clone(),
            operation,
            task: self.task.clone(),
            owner: None,
            waited: start.elapsed(),
        };
        loop {
            let seen = self.owners_noted.generation();
            let mut until = deadline;
            let Some((_, incarnation)) = self.current_owner(start, &mut until).await? else {
                return Err(timed_out());
            };
            if incarnation == broadcast.owner {
                return Ok(true);
            }
            let known = self
                .demux()
                .owners
                .values()
                .any(|o| o.incarnation == broadcast.owner);
            if known {
                return Ok(false);
            }
            // Its declaration has not come yet (it may be the replacement of the one known).
            if wait::timeout_at(deadline, self.owner_event(seen))
                .await
                .is_none()
            {
                return Err(timed_out());
            }
        }
    }

    /// Queries the port: the owner's response handler (see [`Responder`](super::Responder))
    /// answers. The same exchange as [`send`](Self::send).
    pub fn query(&self, value: &Q, timeout: Duration) -> Result<R, PortError> {
        self.require(Usage::Query)?;
        wait::block_on(self.exchange(value, timeout))
    }

    /// The reply to request `id` from owner `incarnation` (one from an owner replaced
    /// meanwhile is dropped). Every waiting sender reads the topic; one that takes another's
    /// reply hands it over.
    async fn reply_to(&self, id: u64, incarnation: u64) -> Reply {
        loop {
            let seen = self.handed.generation();
            let handed = self.demux().waiting.remove(&id);
            if let Some(reply) = handed {
                if reply.owner == incarnation {
                    return reply;
                }
                continue;
            }
            match wait::race(wait::next_sample(&self.replies), self.handed.changed(seen)).await {
                Either::Left(Some(sample)) if sample.value.id == id => {
                    if sample.value.owner == incarnation {
                        return sample.value;
                    }
                }
                Either::Left(Some(sample)) => {
                    let mut demux = self.demux();
                    if demux.awaiting.get(&sample.value.id) == Some(&sample.value.owner) {
                        demux.waiting.insert(sample.value.id, sample.value);
                        drop(demux);
                        self.handed.notify();
                    }
                }
                // The topic closed: only a reply another sender took can still come.
                Either::Left(None) => self.handed.changed(seen).await,
                Either::Right(()) => {}
            }
        }
    }
}

//! [`PortOwner`]: the one task that owns a port — `receive` requests, `reply` later and in any
//! order.

use std::collections::HashMap;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::error::PortError;
use super::wire::{Filter, OwnerInfo, Reply, Request, Restrictions, UserInfo};
use super::{
    ANNOUNCE_PERIOD, check_name, reliable_consumer, reliable_producer, spawn_error, topic,
};
use crate::{Consumer, Participant, Producer, TypeDescription};

pub(crate) struct OwnerShared {
    port: String,
    task: String,
    participant: Participant,
    /// Reply streams by user handle, with when each was last used.
    replies: Mutex<HashMap<String, (Producer<Reply>, Instant)>>,
    /// Another owner seen on the port (its task), if any.
    conflict: Mutex<Option<(String, Instant)>>,
    stop: AtomicBool,
    restrictions: Restrictions,
    /// Users heard recently, in the order first heard: (info, last heard).
    active: Mutex<Vec<(UserInfo, Instant)>>,
    /// Refusals so far, in words.
    refused: Mutex<Vec<String>>,
}

impl OwnerShared {
    /// Drops the reply streams of users that went away: no reply consumer matched any more,
    /// and none used for four announcement periods (a user that has just declared is given
    /// that long to match). A domain where tools come and go keeps no stream per past call.
    fn prune_replies(&self) {
        let mut replies = self.replies.lock().unwrap_or_else(|p| p.into_inner());
        replies.retain(|_, (producer, used)| {
            used.elapsed() < ANNOUNCE_PERIOD * 4 || producer.wait_for_consumers(1, Duration::ZERO)
        });
    }

    /// Takes user declarations, forgets users not heard for three periods, and returns the
    /// user handles admitted under `max_users` (all of them without it).
    fn admit(&self, users: &Consumer<UserInfo>) -> Vec<String> {
        let mut active = self.active.lock().unwrap_or_else(|p| p.into_inner());
        while let Ok(sample) = users.try_recv() {
            let info = sample.value;
            let full = active.len() >= ACTIVE_LIMIT;
            match active.iter_mut().find(|(u, _)| u.user == info.user) {
                Some(entry) => entry.1 = Instant::now(),
                None if full => {}
                None => {
                    if let Some(why) = self.refusal(&info) {
                        self.note_refusal(&info, &why);
                    }
                    active.push((info, Instant::now()));
                }
            }
        }
        active.retain(|(_, seen)| seen.elapsed() < ANNOUNCE_PERIOD * 3);
        let limit = self
            .restrictions
            .max_users
            .map_or(usize::MAX, |m| m as usize);
        active
            .iter()
            .filter(|(u, _)| self.refusal(u).is_none())
            .take(limit)
            .map(|(u, _)| u.user.clone())
            .collect()
    }

    /// Why the user list or usage restriction refuses `user`, if it does.
    fn refusal(&self, user: &UserInfo) -> Option<String> {
        self.restrictions
            .refusal(&user.task, &user.usages)
            .map(|(what, why)| format!("{what}: {why}"))
    }

    fn note_refusal(&self, user: &UserInfo, why: &str) {
        let text = format!("`{}` ({}): {why}", user.task, user.user);
        tracing::warn!(port = %self.port, owner = %self.task, refusal = %text, "port user refused");
        let mut refused = self.refused.lock().unwrap_or_else(|p| p.into_inner());
        if refused.len() < 256 && !refused.contains(&text) {
            refused.push(text);
        }
    }

    /// Whether a request from user handle `user` may be served.
    fn admitted(&self, user: &str) -> bool {
        let active = self.active.lock().unwrap_or_else(|p| p.into_inner());
        let limit = self
            .restrictions
            .max_users
            .map_or(usize::MAX, |m| m as usize);
        if !self.restrictions.restricted() {
            return true;
        }
        active
            .iter()
            .filter(|(u, _)| self.refusal(u).is_none())
            .take(limit)
            .any(|(u, _)| u.user == user)
    }
}

/// The owner of a port: receives requests of type `Q` and replies with `R`.
pub struct PortOwner<Q, R> {
    shared: Arc<OwnerShared>,
    broadcast: Producer<super::sendall::Broadcast>,
    broadcast_replies: Consumer<super::sendall::BroadcastReply>,
    broadcasts: std::sync::atomic::AtomicU64,
    sendall_turn: Mutex<()>,
    /// `None` when a filter thread reads the topic.
    requests: Option<Consumer<Request>>,
    /// Requests taken off the topic (by [`select`](super::select) or the filter) and not
    /// received yet.
    pending: Arc<Mutex<std::collections::VecDeque<Request>>>,
    filter: Option<JoinHandle<()>>,
    priority: std::sync::atomic::AtomicI32,
    owners: Consumer<OwnerInfo>,
    incarnation: u64,
    announcer: Option<JoinHandle<()>>,
    _types: PhantomData<fn(Q) -> R>,
}

/// Identifies one request: reply through it (once, whenever, from any thread).
#[must_use = "a sender waits until it is replied to (or times out)"]
pub struct ReplyHandle<R> {
    shared: Arc<OwnerShared>,
    /// The filter answered the sender already: replying does nothing.
    answered: bool,
    id: u64,
    user: String,
    task: String,
    _reply: PhantomData<fn(R)>,
}

impl<Q: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned> PortOwner<Q, R> {
    /// Declares `task` the owner of `port`. Another owner anywhere in the domain is reported
    /// to both (see [`receive`](Self::receive)).
    pub fn declare(participant: &Participant, port: &str, task: &str) -> Result<Self, PortError> {
        Self::declare_with(participant, port, task, Restrictions::default())
    }

    /// The same, with restrictions: users that break them are refused (each user's operations
    /// fail with [`PortError::Refused`] naming the port, the owner and the user; the owner
    /// drops their requests and lists them in [`refusals`](Self::refusals)).
    pub fn declare_with(
        participant: &Participant,
        port: &str,
        task: &str,
        restrictions: Restrictions,
    ) -> Result<Self, PortError> {
        check_name(port)?;
        let users = reliable_consumer::<UserInfo>(participant, port, &topic(port, "users"))?;
        let requests = reliable_consumer::<Request>(participant, port, &topic(port, "request"))?;
        let owners = reliable_consumer::<OwnerInfo>(participant, port, &topic(port, "owner"))?;
        let announce = reliable_producer::<OwnerInfo>(participant, port, &topic(port, "owner"))?;
        let incarnation = fastrand::u64(..);
        let info = OwnerInfo {
            task: task.to_owned(),
            pid: std::process::id(),
            incarnation,
            request_format: TypeDescription::of::<Q>().fingerprint(),
            reply_format: TypeDescription::of::<R>().fingerprint(),
            restrictions: restrictions.clone(),
            admitted: Vec::new(),
            queue: 0,
        };
        let priority = restrictions.priority;
        let shared = Arc::new(OwnerShared {
            port: port.to_owned(),
            task: task.to_owned(),
            participant: participant.clone(),
            replies: Mutex::new(HashMap::new()),
            conflict: Mutex::new(None),
            stop: AtomicBool::new(false),
            restrictions,
            active: Mutex::new(Vec::new()),
            refused: Mutex::new(Vec::new()),
        });
        let pending = Arc::new(Mutex::new(std::collections::VecDeque::new()));
        let (requests, filter) = match shared.restrictions.filter {
            None => (Some(requests), None),
            Some(Filter::BoundedBuffer { capacity: 0 }) => {
                return Err(PortError::ZeroCapacity {
                    port: port.to_owned(),
                });
            }
            Some(Filter::BoundedBuffer { capacity }) => {
                if TypeDescription::of::<R>().fingerprint()
                    != TypeDescription::of::<()>().fingerprint()
                {
                    return Err(PortError::ReplyType {
                        port: port.to_owned(),
                        expected: std::any::type_name::<()>(),
                        got: std::any::type_name::<R>(),
                    });
                }
                let shared = Arc::clone(&shared);
                let buffer = Arc::clone(&pending);
                let name = format!("port-filter-{port}");
                let thread = std::thread::Builder::new()
                    .name(name.clone())
                    .spawn(move || bounded_buffer(&shared, &requests, &buffer, capacity as usize))
                    .map_err(spawn_error(port, &name))?;
                (None, Some(thread))
            }
        };
        let flag = Arc::clone(&shared);
        let queued = Arc::clone(&pending);
        let thread = format!("port-{port}");
        let announcer = std::thread::Builder::new()
            .name(thread.clone())
            .spawn(move || {
                let mut info = info;
                while !flag.stop.load(Ordering::Acquire) {
                    info.admitted = flag.admit(&users);
                    flag.prune_replies();
                    let queue = queued.lock().unwrap_or_else(|p| p.into_inner()).len();
                    info.queue = u32::try_from(queue).unwrap_or(u32::MAX);
                    let _ = announce.write(&info);
                    let until = Instant::now() + ANNOUNCE_PERIOD;
                    while Instant::now() < until && !flag.stop.load(Ordering::Acquire) {
                        std::thread::sleep(Duration::from_millis(10));
                    }
                }
            })
            .map_err(spawn_error(port, &thread))?;
        Ok(Self {
            broadcast: reliable_producer(participant, port, &topic(port, "all"))?,
            broadcast_replies: reliable_consumer(participant, port, &topic(port, "all-reply"))?,
            broadcasts: std::sync::atomic::AtomicU64::new(1),
            sendall_turn: Mutex::new(()),
            shared,
            requests,
            pending,
            filter,
            priority: std::sync::atomic::AtomicI32::new(priority),
            owners,
            incarnation,
            announcer: Some(announcer),
            _types: PhantomData,
        })
    }

    /// The port's name.
    pub fn port(&self) -> &str {
        &self.shared.port
    }

    /// `sendall`: sends `value` to every user of the port and waits (at most `timeout`) for
    /// the first reply; the later replies come from the returned [`Replies`](super::Replies).
    /// Users that declared the port after this call do not get the message.
    pub fn sendall(
        &self,
        value: &Q,
        timeout: Duration,
    ) -> Result<super::Replies<'_, R>, PortError> {
        let start = Instant::now();
        let port = &self.shared.port;
        // One broadcast at a time per owner: they share the reply stream.
        let _turn = self.sendall_turn.lock().unwrap_or_else(|p| p.into_inner());
        let id = self.broadcasts.fetch_add(1, Ordering::Relaxed);
        let payload = postcard::to_stdvec(value).map_err(|e| PortError::Codec {
            port: port.clone(),
            what: "encoding a broadcast",
            reason: e.to_string(),
        })?;
        self.broadcast
            .write(&super::sendall::Broadcast {
                owner: self.incarnation,
                id,
                task: self.shared.task.clone(),
                payload,
            })
            .map_err(|source| PortError::Write {
                port: port.clone(),
                what: "a broadcast".to_owned(),
                source,
            })?;
        let first = super::sendall::next_reply(
            port,
            &self.broadcast_replies,
            self.incarnation,
            id,
            timeout,
        )
        .ok_or_else(|| PortError::Timeout {
            port: port.clone(),
            operation: "sendall",
            task: self.shared.task.clone(),
            owner: None,
            waited: start.elapsed(),
        })??;
        Ok(super::Replies {
            port,
            id,
            owner: self.incarnation,
            source: &self.broadcast_replies,
            first,
            _reply: PhantomData,
        })
    }

    /// Users matched on the broadcast topic now (who a `sendall` reaches).
    pub fn users(&self) -> usize {
        self.broadcast.matched().len()
    }

    /// The users refused so far by the port's restrictions, in words.
    pub fn refusals(&self) -> Vec<String> {
        self.shared
            .refused
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// The port's restrictions.
    pub fn restrictions(&self) -> &Restrictions {
        &self.shared.restrictions
    }

    /// Sets the port's priority for [`select`](super::select) (higher first; default 0).
    pub fn set_priority(&self, priority: i32) {
        self.priority.store(priority, Ordering::Relaxed);
    }

    /// The other owner of this port, if one was seen.
    pub fn conflict(&self) -> Option<String> {
        self.note_other_owners();
        let mut conflict = self
            .shared
            .conflict
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        // The other owner is gone once it has not been heard for three periods.
        if conflict
            .as_ref()
            .is_some_and(|(_, seen)| seen.elapsed() >= ANNOUNCE_PERIOD * 3)
        {
            *conflict = None;
        }
        conflict.as_ref().map(|(other, _)| other.clone())
    }

    fn note_other_owners(&self) {
        while let Ok(sample) = self.owners.try_recv() {
            if sample.value.incarnation != self.incarnation {
                let other = format!("{} (pid {})", sample.value.task, sample.value.pid);
                let mut conflict = self
                    .shared
                    .conflict
                    .lock()
                    .unwrap_or_else(|p| p.into_inner());
                if conflict.is_none() {
                    tracing::warn!(port = %self.shared.port, owner = %self.shared.task, other = %other,
                        "a second owner declared this port");
                }
                *conflict = Some((other, Instant::now()));
            }
        }
    }

    /// [`receive`](Self::receive) for a loop that serves the port: `None` at the timeout, for
    /// a request that does not decode (its sender's problem: the next one is taken at once),
    /// and for a failure that lasts (a second owner), which is logged as an error when it
    /// begins or changes (`failing` remembers it between calls) and then waited out for
    /// `timeout`.
    pub fn serve_next(
        &self,
        timeout: Duration,
        failing: &mut Option<String>,
    ) -> Option<(Q, ReplyHandle<R>)> {
        match self.receive(timeout) {
            Ok(request) => {
                *failing = None;
                Some(request)
            }
            Err(PortError::Timeout { .. } | PortError::Codec { .. }) => None,
            Err(err) => {
                let text = err.to_string();
                if failing.as_ref() != Some(&text) {
                    tracing::error!(port = %self.shared.port, "{text}; requests wait until it is resolved");
                    *failing = Some(text);
                }
                std::thread::sleep(timeout);
                None
            }
        }
    }

    /// Waits for the next request (at most `timeout`): the message and the handle to reply
    /// with. Fails while another owner of the port exists.
    pub fn receive(&self, timeout: Duration) -> Result<(Q, ReplyHandle<R>), PortError> {
        let start = Instant::now();
        loop {
            if let Some(other) = self.conflict() {
                return Err(PortError::SecondOwner {
                    port: self.shared.port.clone(),
                    first: self.shared.task.clone(),
                    second: other,
                });
            }
            let left = timeout.saturating_sub(start.elapsed());
            let slice = left.min(Duration::from_millis(50));
            let buffered = self
                .pending
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .pop_front();
            let next = match buffered {
                Some(request) => Ok(request),
                None => match &self.requests {
                    Some(requests) => requests
                        .recv_timeout(slice)
                        .map(|s| s.value)
                        .map_err(|_| ()),
                    None => {
                        std::thread::sleep(slice.min(Duration::from_millis(2)));
                        Err(())
                    }
                },
            };
            match next {
                Ok(request) if !self.shared.admitted(&request.user) => {
                    tracing::debug!(port = %self.shared.port, user = %request.task,
                        "request from a user the port's restrictions refuse: dropped");
                    if left.is_zero() {
                        return Err(PortError::Timeout {
                            port: self.shared.port.clone(),
                            operation: "receive",
                            task: self.shared.task.clone(),
                            owner: None,
                            waited: start.elapsed(),
                        });
                    }
                }
                Ok(request) => {
                    let value = postcard::from_bytes::<Q>(&request.payload).map_err(|e| {
                        PortError::Codec {
                            port: self.shared.port.clone(),
                            what: "decoding a request",
                            reason: e.to_string(),
                        }
                    })?;
                    return Ok((
                        value,
                        ReplyHandle {
                            shared: Arc::clone(&self.shared),
                            answered: self.filter.is_some(),
                            id: request.id,
                            user: request.user,
                            task: request.task,
                            _reply: PhantomData,
                        },
                    ));
                }
                Err(_) if left.is_zero() => {
                    return Err(PortError::Timeout {
                        port: self.shared.port.clone(),
                        operation: "receive",
                        task: self.shared.task.clone(),
                        owner: None,
                        waited: start.elapsed(),
                    });
                }
                Err(_) => {}
            }
        }
    }
}

impl<Q: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned> super::Selectable
    for PortOwner<Q, R>
{
    fn port(&self) -> &str {
        &self.shared.port
    }

    fn priority(&self) -> i32 {
        self.priority.load(Ordering::Relaxed)
    }

    fn waiting(&self) -> usize {
        let mut pending = self.pending.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(requests) = &self.requests {
            // Taken off the topic up to a bound; the rest waits there (flow control).
            while pending.len() < PENDING_LIMIT {
                match requests.try_recv() {
                    Ok(sample) => pending.push_back(sample.value),
                    Err(_) => break,
                }
            }
        }
        pending.len()
    }
}

impl<Q, R> Drop for PortOwner<Q, R> {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        for thread in [self.announcer.take(), self.filter.take()]
            .into_iter()
            .flatten()
        {
            let _ = thread.join();
        }
    }
}

/// Requests `select` takes off the topic ahead of `receive`, at most.
const PENDING_LIMIT: usize = 1024;
/// Users whose reply streams an owner keeps at most (the least recently used goes first).
const REPLY_STREAMS: usize = 1024;
/// Users an owner tracks at most.
const ACTIVE_LIMIT: usize = 1024;

/// How long an owner waits for a new user's reply topic to match before replying anyway.
pub(crate) const REPLY_MATCH: Duration = Duration::from_secs(2);

impl<R> std::fmt::Debug for ReplyHandle<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReplyHandle")
            .field("port", &self.shared.port)
            .field("id", &self.id)
            .field("sender", &self.task)
            .finish()
    }
}

impl<R: Serialize> ReplyHandle<R> {
    /// The task that sent the request.
    pub fn sender(&self) -> &str {
        &self.task
    }

    /// Replies (does not wait for the sender).
    pub fn reply(self, value: &R) -> Result<(), PortError> {
        if self.answered {
            return Ok(());
        }
        let payload = postcard::to_stdvec(value).map_err(|e| PortError::Codec {
            port: self.shared.port.clone(),
            what: "encoding a reply",
            reason: e.to_string(),
        })?;
        send_reply(&self.shared, &self.user, &self.task, self.id, payload)
    }
}

/// Writes a reply to user handle `user`. The first reply to a user waits (at most
/// [`REPLY_MATCH`]) until its reply stream matches — outside the lock, so other replies go on.
fn send_reply(
    shared: &OwnerShared,
    user: &str,
    task: &str,
    id: u64,
    payload: Vec<u8>,
) -> Result<(), PortError> {
    let reply = Reply { id, payload };
    let write = |producer: &Producer<Reply>| {
        producer.write(&reply).map_err(|source| PortError::Write {
            port: shared.port.clone(),
            what: format!("the reply to `{task}`"),
            source,
        })
    };
    {
        let mut replies = shared.replies.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((producer, used)) = replies.get_mut(user) {
            *used = Instant::now();
            return write(producer);
        }
    }
    if check_name(user).is_err() {
        return Err(PortError::BadReplyId {
            port: shared.port.clone(),
            sender: task.to_owned(),
            id: user.to_owned(),
        });
    }
    let name = topic(&shared.port, &format!("reply/{user}"));
    let producer = reliable_producer::<Reply>(&shared.participant, &shared.port, &name)?;
    // A reliable stream starts at the match: wait for the sender's reply consumer.
    producer.wait_for_consumers(1, REPLY_MATCH);
    let result = write(&producer);
    let mut replies = shared.replies.lock().unwrap_or_else(|p| p.into_inner());
    if replies.len() >= REPLY_STREAMS
        && let Some(oldest) = replies
            .iter()
            .min_by_key(|(_, (_, used))| *used)
            .map(|(k, _)| k.clone())
    {
        replies.remove(&oldest);
    }
    replies.insert(user.to_owned(), (producer, Instant::now()));
    result
}

/// The bounded-buffer filter: takes requests off the topic while the buffer has room and
/// answers each at once (so the sender goes on); when the buffer is full, it stops taking
/// them, and senders wait for room.
fn bounded_buffer(
    shared: &OwnerShared,
    requests: &Consumer<Request>,
    buffer: &Mutex<std::collections::VecDeque<Request>>,
    capacity: usize,
) {
    let empty = postcard::to_stdvec(&()).unwrap_or_default();
    while !shared.stop.load(Ordering::Acquire) {
        let room = buffer.lock().unwrap_or_else(|p| p.into_inner()).len() < capacity;
        if !room {
            std::thread::sleep(Duration::from_millis(1));
            continue;
        }
        let Ok(sample) = requests.recv_timeout(Duration::from_millis(20)) else {
            continue;
        };
        let request = sample.value;
        if !shared.admitted(&request.user) {
            continue; // refused users get no answer: their own side reports the refusal
        }
        if let Err(err) = send_reply(
            shared,
            &request.user,
            &request.task,
            request.id,
            empty.clone(),
        ) {
            tracing::warn!(port = %shared.port, error = %err, "filter could not answer a sender");
        }
        buffer
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push_back(request);
    }
}

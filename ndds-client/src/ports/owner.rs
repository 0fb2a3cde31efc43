//! [`PortOwner`]: the one task that owns a port — `receive` requests, `reply` later and in any
//! order.

use std::collections::{HashMap, VecDeque};
use std::future::Future;
use std::marker::PhantomData;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::declaration::{Declaration, Presence};
use super::error::PortError;
use super::sendall::{Broadcast, BroadcastReply};
use super::wait::{self, Either, Notify};
use super::wire::{Filter, OwnerInfo, Reply, Request, Restrictions, UserInfo};
use super::{
    Encoded, check_name, declaring_producer, reliable_consumer, reliable_producer, spawn_error,
    topic,
};
use crate::{Consumer, Participant, Producer, TypeDescription};

/// A stream to one user, shared by the calls that use it, with when it was last used.
type Stream<T> = (Arc<Producer<T>>, Instant);

/// A port without a priority, as stored (no `i32` is this).
const UNPRIORITISED: i64 = i64::MIN;

pub(crate) struct OwnerShared {
    pub(crate) port: String,
    pub(crate) task: String,
    /// This owner's incarnation (random) and takeover claim (see [`OwnerInfo::claim`]).
    incarnation: u64,
    claim: u64,
    participant: Participant,
    /// Reply streams by user handle, with when each was last used.
    replies: Mutex<HashMap<String, (Producer<Reply>, Instant)>>,
    /// Streams to single users (`send_to`) by user handle, with when each was last used.
    to_users: Mutex<HashMap<String, Stream<Broadcast>>>,
    /// Told when the users present change (the declaration thread heard one come or go).
    pub(crate) users_changed: Notify,
    pub(crate) stop: AtomicBool,
    /// Told when the owner stops, another owner comes or goes, and `pending` changes.
    pub(crate) changed: Notify,
    restrictions: Restrictions,
    presence: Mutex<Presence>,
    /// Requests taken off the topic (by [`select`](super::select) or the filter) and not
    /// received yet.
    pending: Mutex<VecDeque<Request>>,
    /// Requests withdrawn by their senders after they were received (the most recent
    /// [`WITHDRAWALS_KEPT`]), for [`ReplyHandle::is_withdrawn`].
    withdrawn_late: Mutex<VecDeque<(String, u64)>>,
    /// Requests dropped unreceived because their senders stopped waiting.
    withdrawn: AtomicU64,
    /// Replies to `sendall` dropped because the restrictions refuse their users.
    refused_replies: AtomicU64,
    /// Requests dropped because they are for another owner of the port.
    misaddressed: AtomicU64,
    /// The requests topic, while this owner is not replaced: a replaced owner lets go of it
    /// at once (its declaration thread does, however the task that serves the port is doing)
    /// so that a hung owner does not hold its users' flow-control window. It takes the topic
    /// again if its replacement goes away.
    requests: Mutex<Option<Arc<Consumer<Request>>>>,
}

impl OwnerShared {
    pub(crate) fn presence(&self) -> MutexGuard<'_, Presence> {
        self.presence.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn pending(&self) -> MutexGuard<'_, VecDeque<Request>> {
        self.pending.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn queue_len(&self) -> usize {
        self.pending().len()
    }

    /// Takes `request`, just read off the topic, into `pending`; a withdrawal drops the
    /// request it names from there, or is remembered if that request was received already.
    pub(crate) fn absorb(&self, pending: &mut VecDeque<Request>, request: Request) {
        if !self.addressed_here(&request) {
            return;
        }
        if !request.withdraw {
            pending.push_back(request);
            return;
        }
        if !self.drop_withdrawn(pending, &request) {
            let mut late = self
                .withdrawn_late
                .lock()
                .unwrap_or_else(|p| p.into_inner());
            if late.len() >= WITHDRAWALS_KEPT {
                late.pop_front();
            }
            late.push_back((request.user, request.id));
        }
    }

    /// Whether `request` is for this owner; one for another owner of the port is counted
    /// and dropped.
    pub(crate) fn addressed_here(&self, request: &Request) -> bool {
        if request.owner == self.incarnation {
            return true;
        }
        self.misaddressed.fetch_add(1, Ordering::Relaxed);
        false
    }

    /// Drops from `queue` the request `withdrawal` names; whether it was there.
    pub(crate) fn drop_withdrawn(
        &self,
        queue: &mut VecDeque<Request>,
        withdrawal: &Request,
    ) -> bool {
        let found = queue
            .iter()
            .position(|r| !r.withdraw && r.id == withdrawal.id && r.user == withdrawal.user);
        if let Some(at) = found {
            queue.remove(at);
            self.withdrawn.fetch_add(1, Ordering::Relaxed);
        }
        found.is_some()
    }

    /// Whether the sender of request `id` of user handle `user` withdrew it after it was
    /// received.
    fn withdrawn_after_receipt(&self, user: &str, id: u64) -> bool {
        self.withdrawn_late
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .any(|(u, i)| *i == id && u == user)
    }

    /// Drops the reply stream of a user that went away.
    pub(crate) fn forget_replies(&self, user: &str) {
        self.replies
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(user);
        self.to_users
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(user);
    }

    /// The handle and task of an admitted user of task `task` (any task, with `None`) that
    /// declared one of `usages`, if one is here (the first heard).
    pub(crate) fn admitted_with(
        &self,
        task: Option<&str>,
        usages: &[super::Usage],
    ) -> Option<(String, String)> {
        let admitted = self.admitted_users();
        self.presence()
            .active
            .iter()
            .find(|(u, _)| {
                task.is_none_or(|t| u.task == t)
                    && u.usages.iter().any(|d| usages.contains(d))
                    && admitted.contains(&u.user)
            })
            .map(|(u, _)| (u.user.clone(), u.task.clone()))
    }

    /// Refuses locally an operation the owner's usages do not allow (it needs one of `any`).
    pub(crate) fn require(&self, operation: &str, any: &[super::Usage]) -> Result<(), PortError> {
        if self.restrictions.owner_may(any) {
            return Ok(());
        }
        Err(PortError::Refused {
            port: self.port.clone(),
            owner: self.task.clone(),
            user: self.task.clone(),
            restriction: "usage",
            detail: format!(
                "the owner's {operation} needs the usage {}; it declared {:?}",
                any.iter()
                    .map(|u| format!("{u:?}"))
                    .collect::<Vec<_>>()
                    .join(" or "),
                self.restrictions.usages
            ),
        })
    }

    /// The tasks of the users present, for messages.
    pub(crate) fn present_users(&self) -> Vec<String> {
        let mut tasks: Vec<String> = self
            .presence()
            .active
            .iter()
            .map(|(u, _)| format!("{} {:?}", u.task, u.usages))
            .collect();
        tasks.sort();
        tasks
    }

    /// The stream to user handle `user` (created on first use: it waits, at most
    /// [`REPLY_MATCH`], until the user's end matches — outside the lock).
    pub(crate) fn to_user(&self, user: &str) -> Result<Arc<Producer<Broadcast>>, PortError> {
        {
            let mut streams = self.to_users.lock().unwrap_or_else(|p| p.into_inner());
            if let Some((producer, used)) = streams.get_mut(user) {
                *used = Instant::now();
                return Ok(Arc::clone(producer));
            }
        }
        let name = topic(&self.port, &format!("to/{user}"));
        let producer = Arc::new(reliable_producer::<Broadcast>(
            &self.participant,
            &self.port,
            &name,
        )?);
        producer.wait_for_consumers(1, REPLY_MATCH);
        let mut streams = self.to_users.lock().unwrap_or_else(|p| p.into_inner());
        if streams.len() >= REPLY_STREAMS
            && let Some(oldest) = streams
                .iter()
                .min_by_key(|(_, (_, used))| *used)
                .map(|(k, _)| k.clone())
        {
            streams.remove(&oldest);
        }
        streams.insert(user.to_owned(), (Arc::clone(&producer), Instant::now()));
        Ok(producer)
    }

    /// Why the user list or usage restriction refuses `user`, if it does.
    pub(crate) fn refusal(&self, user: &UserInfo) -> Option<String> {
        self.restrictions
            .refusal(&user.task, &user.usages)
            .map(|(what, why)| format!("{what}: {why}"))
    }

    pub(crate) fn note_refusal(&self, presence: &mut Presence, user: &UserInfo, why: &str) {
        let text = format!("`{}` ({}): {why}", user.task, user.user);
        tracing::warn!(port = %self.port, owner = %self.task, refusal = %text, "port user refused");
        if presence.refused.len() < 256 && !presence.refused.contains(&text) {
            presence.refused.push(text);
        }
    }

    /// The user handles admitted now: the present users the restrictions allow, first heard
    /// first, up to `max_users` (all of them without it).
    pub(crate) fn admitted_users(&self) -> Vec<String> {
        let presence = self.presence();
        let limit = self
            .restrictions
            .max_users
            .map_or(usize::MAX, |m| m as usize);
        presence
            .active
            .iter()
            .filter(|(u, _)| self.refusal(u).is_none())
            .take(limit)
            .map(|(u, _)| u.user.clone())
            .collect()
    }

    /// Whether a reply to a `sendall` comes from a user the restrictions allow and admitted;
    /// one that does not is dropped and counted.
    pub(crate) fn accepts_broadcast_reply(
        &self,
        reply: &BroadcastReply,
        usages: &[super::Usage],
    ) -> bool {
        let refused = self.restrictions.refusal(&reply.task, usages).is_some()
            || !(self.admitted(&reply.user) || self.presence().departed_recently(&reply.user));
        if refused {
            self.refused_replies.fetch_add(1, Ordering::Relaxed);
            tracing::debug!(port = %self.port, user = %reply.task,
                "reply to a sendall from a user the port's restrictions refuse: dropped");
        }
        !refused
    }

    /// Whether a request from user handle `user` may be served.
    pub(crate) fn admitted(&self, user: &str) -> bool {
        !self.restrictions.restricted() || self.admitted_users().iter().any(|u| u == user)
    }

    /// The other owner of the port with this owner's claim, if one is present (owners of a
    /// lower claim were replaced; one of a higher claim replaced this one).
    fn conflict(&self) -> Option<String> {
        self.presence()
            .others
            .values()
            .filter(|(_, claim)| *claim == self.claim)
            .map(|(who, _)| who.clone())
            .min()
    }

    /// The owner that took the port over from this one, if one did.
    fn superseded_by(&self) -> Option<String> {
        self.presence()
            .others
            .values()
            .filter(|(_, claim)| *claim > self.claim)
            .max_by_key(|(_, claim)| *claim)
            .map(|(who, _)| who.clone())
    }

    /// The requests topic, taken again if this owner let go of it and is no longer replaced;
    /// `None` while it is replaced (or the topic cannot be taken: logged).
    pub(crate) fn requests(&self) -> Option<Arc<Consumer<Request>>> {
        // Decided under the slot's lock, as `release_requests_if_replaced` does (the slot's
        // lock before the presence's, in both).
        let mut slot = self.requests.lock().unwrap_or_else(|p| p.into_inner());
        let superseded = self.superseded_by().is_some();
        if superseded {
            *slot = None;
            return None;
        }
        if slot.is_none() {
            let name = topic(&self.port, "request");
            match reliable_consumer::<Request>(&self.participant, &self.port, &name) {
                Ok(consumer) => *slot = Some(Arc::new(consumer)),
                Err(err) => {
                    tracing::warn!(port = %self.port, error = %err, "the requests topic could not be taken again");
                }
            }
        }
        slot.clone()
    }

    /// Lets go of the requests topic if this owner was replaced (see `requests`), and of the
    /// requests it holds: their senders send them again to the replacement.
    pub(crate) fn release_requests_if_replaced(&self) {
        let released = {
            let mut slot = self.requests.lock().unwrap_or_else(|p| p.into_inner());
            if self.superseded_by().is_none() {
                return;
            }
            slot.take()
        };
        drop(released);
        let held = std::mem::take(&mut *self.pending());
        if !held.is_empty() {
            tracing::debug!(port = %self.port, owner = %self.task, requests = held.len(),
                "replaced: the requests held here go to the replacement");
        }
    }

    /// [`PortError::Superseded`] if this owner was replaced.
    fn check_superseded(&self) -> Result<(), PortError> {
        match self.superseded_by() {
            Some(by) => Err(PortError::Superseded {
                port: self.port.clone(),
                owner: self.task.clone(),
                by,
            }),
            None => Ok(()),
        }
    }
}

/// The owner of a port: receives requests of type `Q` and replies with `R`.
pub struct PortOwner<Q, R> {
    shared: Arc<OwnerShared>,
    broadcast: Producer<Broadcast>,
    broadcast_replies: Consumer<BroadcastReply>,
    /// The id of the next message to users (`sendall`, `callall`, `send_to`).
    broadcasts: AtomicU64,
    /// Hands each user's reply to the call that waits for it.
    demux: super::sendall::ReplyDemux,
    /// Whether requests are taken from the topic by `receive` (no filter in between).
    direct: bool,
    filter: Option<JoinHandle<()>>,
    /// The port's priority, or [`UNPRIORITISED`].
    priority: AtomicI64,
    incarnation: u64,
    declaration: Option<JoinHandle<()>>,
    _types: PhantomData<fn(Q) -> R>,
}

impl PortOwner<Encoded, Encoded> {
    /// Declares `task` the owner of `port` with message types described at run time (a
    /// binding's, see [`Encoded`]): the owner announces these descriptions' fingerprints, so
    /// users of the same shapes in any language match it. Restrictions naming a filter are
    /// refused ([`PortError::FilterCode`]): a filter's code is Rust's.
    pub fn declare_described(
        participant: &Participant,
        port: &str,
        task: &str,
        restrictions: Restrictions,
        request: &TypeDescription,
        reply: &TypeDescription,
    ) -> Result<Self, PortError> {
        if restrictions.filter.is_some() {
            return Err(PortError::FilterCode {
                port: port.to_owned(),
            });
        }
        let formats = (request.fingerprint(), reply.fingerprint());
        Self::declare_plain(participant, port, task, restrictions, 0, formats)
    }
}

/// The fingerprints of a port's request and reply types, as owners announce them and users
/// check them; refused for [`Encoded`] messages, which carry no Rust type to trace (they are
/// declared with `declare_described`).
pub(super) fn formats_of<Q: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned>(
    port: &str,
) -> Result<(u64, u64), PortError> {
    let encoded = std::any::type_name::<Encoded>();
    if std::any::type_name::<Q>() == encoded || std::any::type_name::<R>() == encoded {
        return Err(PortError::Undescribed {
            port: port.to_owned(),
        });
    }
    Ok((
        TypeDescription::of::<Q>().fingerprint(),
        TypeDescription::of::<R>().fingerprint(),
    ))
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
    pub fn declare(participant: &Participant, port: &str, task: &str) -> Result<Self, PortError>
    where
        Q: Send + 'static,
        R: Send + 'static,
    {
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
    ) -> Result<Self, PortError>
    where
        Q: Send + 'static,
        R: Send + 'static,
    {
        Self::declare_claiming(participant, port, task, restrictions, 0)
    }

    /// Declares `task` the owner of `port` with a filter of its own spliced in at its end
    /// (see [`RequestFilter`](super::RequestFilter)): every request goes through `filter`,
    /// which passes it on, answers it or refuses it. Returns the owner and the port `FILTER`
    /// through which the owner's module talks to its filter. The restrictions' `filter` is
    /// set to what the filter declares ([`RequestFilter::declared`](super::RequestFilter::declared):
    /// [`Filter::Task`] unless it says otherwise), so users and `ndds ports` see that a filter
    /// sits there, and its usages (if it has any) replace the restrictions' `usages`.
    pub fn declare_filtered<F>(
        participant: &Participant,
        port: &str,
        task: &str,
        restrictions: Restrictions,
        filter: F,
    ) -> Result<(Self, super::FilterPort<F::Message>), PortError>
    where
        Q: Send + 'static,
        R: Send + 'static,
        F: super::RequestFilter<Q, R>,
    {
        Self::spliced(participant, port, task, restrictions, 0, filter, true)
    }

    /// Declares `task` the owner with `filter` spliced in, with claim `claim`; the filter's
    /// usages (if it has any) replace the restrictions' when `filter_usages` is true.
    fn spliced<F>(
        participant: &Participant,
        port: &str,
        task: &str,
        mut restrictions: Restrictions,
        claim: u64,
        filter: F,
        filter_usages: bool,
    ) -> Result<(Self, super::FilterPort<F::Message>), PortError>
    where
        Q: Send + 'static,
        R: Send + 'static,
        F: super::RequestFilter<Q, R>,
    {
        restrictions.filter = Some(filter.declared());
        // Users deal with the filter: theirs are checked against its usages.
        let usages = filter.usages();
        if filter_usages && !usages.is_empty() {
            restrictions.usages = usages;
        }
        let formats = formats_of::<Q, R>(port)?;
        let mut owner = Self::declare_plain(participant, port, task, restrictions, claim, formats)?;
        let inbox = Arc::new(Mutex::new(VecDeque::new()));
        let (shared, taken) = (Arc::clone(&owner.shared), Arc::clone(&inbox));
        let name = format!("port-filter-{port}");
        let thread = std::thread::Builder::new()
            .name(name.clone())
            .spawn(move || super::filter::run::<Q, R, F>(&shared, filter, &taken))
            .map_err(spawn_error(port, &name))?;
        owner.filter = Some(thread);
        let port = super::FilterPort {
            shared: Some(Arc::clone(&owner.shared)),
            inbox,
        };
        Ok((owner, port))
    }

    /// Takes `port` over from its owner, for a hung or failed one that still holds it: listens
    /// up to `listen` for the owners there are (it stops once it heard the declaration of every
    /// owner its daemon knows of and discovery matched it with), then declares `task` the
    /// owner with a claim above every claim heard. Users send to the highest claim from then
    /// on; the replaced owner is told (its `receive` and replies fail with
    /// [`PortError::Superseded`]), and requests it held time out for their senders. With no
    /// owner heard, it declares the port with claim 1. Two replacements racing with the same
    /// claim are a conflict, reported as two owners are.
    pub fn take_over(
        participant: &Participant,
        port: &str,
        task: &str,
        restrictions: Restrictions,
        listen: Duration,
    ) -> Result<Self, PortError>
    where
        Q: Send + 'static,
        R: Send + 'static,
    {
        check_name(port)?;
        let owner_topic = topic(port, "owner");
        let owners = reliable_consumer::<OwnerInfo>(participant, port, &owner_topic)?;
        let deadline = wait::deadline(Instant::now(), listen);
        // Every owner's declaration is kept for late listeners: once one has come from each
        // declaration producer the daemon knows of (its graph, now) and discovery matched,
        // every claim there is has been heard.
        let known: Vec<crate::Guid> = participant
            .graph()
            .map(|graph| {
                graph
                    .endpoints
                    .iter()
                    .filter(|e| {
                        e.info.topic == owner_topic
                            && e.info.kind() == ndds_core::wire::EndpointKind::Producer
                    })
                    .map(|e| e.info.guid)
                    .collect()
            })
            .unwrap_or_default();
        let mut heard: HashMap<crate::Guid, u64> = HashMap::new();
        loop {
            let matched = owners.matched();
            let waited_for = known.iter().chain(matched.iter().map(|m| &m.guid));
            if !(known.is_empty() && matched.is_empty())
                && waited_for.clone().all(|guid| heard.contains_key(guid))
            {
                break;
            }
            let left = deadline.map_or(Duration::MAX, |at| {
                at.saturating_duration_since(Instant::now())
            });
            if left.is_zero() {
                break;
            }
            if let Ok(sample) = owners.recv_timeout(left.min(Duration::from_millis(20))) {
                heard.insert(sample.info.writer, sample.value.claim);
            }
        }
        let highest = heard.values().copied().max();
        let claim = highest.map_or(1, |h| h.saturating_add(1));
        drop(owners);
        Self::declare_claiming(participant, port, task, restrictions, claim)
    }

    /// Declares the owner with claim `claim`, splicing in the library filter the restrictions
    /// name ([`Filter::BoundedBuffer`]: [`BoundedBuffer`](super::BoundedBuffer)).
    fn declare_claiming(
        participant: &Participant,
        port: &str,
        task: &str,
        restrictions: Restrictions,
        claim: u64,
    ) -> Result<Self, PortError>
    where
        Q: Send + 'static,
        R: Send + 'static,
    {
        // Checked first: `Encoded` messages must not reach a trace (the bounded buffer's
        // reply check below traces `R`).
        let formats = formats_of::<Q, R>(port)?;
        match restrictions.filter {
            None => Self::declare_plain(participant, port, task, restrictions, claim, formats),
            // `declare_filtered` brings the filter's code.
            Some(Filter::Task) => Err(PortError::FilterCode {
                port: port.to_owned(),
            }),
            Some(Filter::BoundedBuffer { capacity: 0 }) => Err(PortError::ZeroCapacity {
                port: port.to_owned(),
            }),
            Some(Filter::BoundedBuffer { capacity }) => {
                // It answers each sender with `()` before the owner replies.
                if TypeDescription::of::<R>().fingerprint()
                    != TypeDescription::of::<()>().fingerprint()
                    || postcard::from_bytes::<R>(&[]).is_err()
                {
                    return Err(PortError::ReplyType {
                        port: port.to_owned(),
                        expected: std::any::type_name::<()>(),
                        got: std::any::type_name::<R>(),
                    });
                }
                // The port's usages stay the owner's, as they were declared.
                let buffer = super::BoundedBuffer::<R>::unit_shaped(capacity as usize);
                let (owner, _) =
                    Self::spliced(participant, port, task, restrictions, claim, buffer, false)?;
                Ok(owner)
            }
        }
    }

    /// Declares the owner with claim `claim` and no filter thread (a filter's caller starts
    /// it), announcing message formats `formats` (request, reply fingerprints).
    fn declare_plain(
        participant: &Participant,
        port: &str,
        task: &str,
        restrictions: Restrictions,
        claim: u64,
        formats: (u64, u64),
    ) -> Result<Self, PortError> {
        check_name(port)?;
        let users = reliable_consumer::<UserInfo>(participant, port, &topic(port, "users"))?;
        let requests = reliable_consumer::<Request>(participant, port, &topic(port, "request"))?;
        let owners = reliable_consumer::<OwnerInfo>(participant, port, &topic(port, "owner"))?;
        let announce = declaring_producer::<OwnerInfo>(participant, port, &topic(port, "owner"))?;
        let incarnation = fastrand::u64(..);
        let info = OwnerInfo {
            task: task.to_owned(),
            pid: std::process::id(),
            incarnation,
            request_format: formats.0,
            reply_format: formats.1,
            restrictions: restrictions.clone(),
            admitted: Vec::new(),
            queue: 0,
            claim,
        };
        let priority = restrictions.priority;
        let shared = Arc::new(OwnerShared {
            port: port.to_owned(),
            task: task.to_owned(),
            incarnation,
            claim,
            participant: participant.clone(),
            replies: Mutex::new(HashMap::new()),
            to_users: Mutex::new(HashMap::new()),
            users_changed: Notify::default(),
            stop: AtomicBool::new(false),
            changed: Notify::default(),
            restrictions,
            presence: Mutex::new(Presence::default()),
            pending: Mutex::new(VecDeque::new()),
            withdrawn_late: Mutex::new(VecDeque::new()),
            withdrawn: AtomicU64::new(0),
            refused_replies: AtomicU64::new(0),
            misaddressed: AtomicU64::new(0),
            requests: Mutex::new(Some(Arc::new(requests))),
        });
        // With a filter, requests reach `receive` through it (its caller starts its thread).
        let direct = shared.restrictions.filter.is_none();
        let declaring = Arc::clone(&shared);
        let thread = format!("port-{port}");
        let declaration = Declaration {
            users,
            owners,
            announce,
            info,
        };
        let declaration = std::thread::Builder::new()
            .name(thread.clone())
            .spawn(move || declaration.run(&declaring))
            .map_err(spawn_error(port, &thread))?;
        Ok(Self {
            broadcast: reliable_producer(participant, port, &topic(port, "all"))?,
            broadcast_replies: reliable_consumer(participant, port, &topic(port, "all-reply"))?,
            broadcasts: AtomicU64::new(1),
            demux: super::sendall::ReplyDemux::default(),
            shared,
            direct,
            filter: None,
            priority: AtomicI64::new(priority.map_or(UNPRIORITISED, i64::from)),
            incarnation,
            declaration: Some(declaration),
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
        wait::block_on(self.sendall_future(value, timeout))
    }

    pub(crate) async fn sendall_future(
        &self,
        value: &Q,
        timeout: Duration,
    ) -> Result<super::Replies<'_, R>, PortError> {
        self.shared.require("sendall", &[super::Usage::SendAll])?;
        let start = Instant::now();
        let port = &self.shared.port;
        let awaited = self.broadcast_message(&self.broadcast, value, "a broadcast")?;
        let shared = &self.shared;
        let first = wait::timeout_at(
            wait::deadline(start, timeout),
            self.demux
                .next(&self.broadcast_replies, self.incarnation, awaited.id, |r| {
                    shared.accepts_broadcast_reply(r, &[super::Usage::ReceiveAll])
                }),
        )
        .await
        .flatten()
        .ok_or_else(|| PortError::Timeout {
            port: port.clone(),
            operation: "sendall",
            task: self.shared.task.clone(),
            owner: None,
            waited: start.elapsed(),
        })?;
        Ok(super::Replies {
            port,
            awaited,
            owner: self.incarnation,
            source: &self.broadcast_replies,
            shared: &self.shared,
            first: super::sendall::decode(port, first)?,
            _reply: PhantomData,
        })
    }

    /// Writes `value` on `topic` as the next message to users, its replies awaited.
    fn broadcast_message(
        &self,
        topic: &Producer<Broadcast>,
        value: &Q,
        what: &str,
    ) -> Result<super::sendall::Awaited<'_>, PortError> {
        let port = &self.shared.port;
        self.shared.check_superseded()?;
        let payload = postcard::to_stdvec(value).map_err(|e| PortError::Codec {
            port: port.clone(),
            what: "encoding a message to users",
            reason: e.to_string(),
        })?;
        let id = self.broadcasts.fetch_add(1, Ordering::Relaxed);
        let awaited = self.demux.await_replies(id);
        topic
            .write(&Broadcast {
                owner: self.incarnation,
                id,
                task: self.shared.task.clone(),
                payload,
            })
            .map_err(|source| PortError::Write {
                port: port.clone(),
                what: what.to_owned(),
                source,
            })?;
        Ok(awaited)
    }

    /// `callall`: sends `value` to every user of the port that takes messages to all users
    /// (usage [`ReceiveAll`](super::Usage::ReceiveAll)) and is admitted now, and waits (at
    /// most `timeout`) until each has answered: the answers, and the users that did not
    /// answer in time. Users that declared the port after this call are not asked.
    pub fn callall(&self, value: &Q, timeout: Duration) -> Result<super::Answers<R>, PortError> {
        wait::block_on(self.callall_future(value, timeout))
    }

    pub(crate) async fn callall_future(
        &self,
        value: &Q,
        timeout: Duration,
    ) -> Result<super::Answers<R>, PortError> {
        self.shared.require("callall", &[super::Usage::CallAll])?;
        let deadline = wait::deadline(Instant::now(), timeout);
        let port = &self.shared.port;
        // Who is asked: admitted users that declared `ReceiveAll`, by handle.
        let admitted = self.shared.admitted_users();
        let mut asked: HashMap<String, String> = self
            .shared
            .presence()
            .active
            .iter()
            .filter(|(u, _)| {
                admitted.contains(&u.user) && u.usages.contains(&super::Usage::ReceiveAll)
            })
            .map(|(u, _)| (u.user.clone(), u.task.clone()))
            .collect();
        let awaited = self.broadcast_message(&self.broadcast, value, "a broadcast query")?;
        let shared = &self.shared;
        let mut replies = Vec::new();
        while !asked.is_empty() {
            let next =
                self.demux
                    .next(&self.broadcast_replies, self.incarnation, awaited.id, |r| {
                        shared.accepts_broadcast_reply(r, &[super::Usage::ReceiveAll])
                    });
            let Some(reply) = wait::timeout_at(deadline, next).await.flatten() else {
                break;
            };
            // One answer per user asked; a user that came after the query is not waited for.
            if asked.remove(&reply.user).is_some() {
                replies.push(super::sendall::decode(port, reply)?);
            }
        }
        let mut missing: Vec<String> = asked.into_values().collect();
        missing.sort();
        Ok(super::Answers { replies, missing })
    }

    /// `send` the other way round: sends `value` to the user of the port whose task is `task`
    /// (it must take such messages: usage [`Receive`](super::Usage::Receive) or
    /// [`Response`](super::Usage::Response)) and waits (at
    /// most `timeout`) for its reply. A user that is not there within the timeout is
    /// [`PortError::NoSuchUser`], naming the users that are.
    pub fn send_to(&self, task: &str, value: &Q, timeout: Duration) -> Result<R, PortError> {
        wait::block_on(self.send_to_future(task, value, timeout))
    }

    pub(crate) async fn send_to_future(
        &self,
        task: &str,
        value: &Q,
        timeout: Duration,
    ) -> Result<R, PortError> {
        self.to_one_user(Some(task), value, timeout).await
    }

    /// `query` the other way round: sends `value` to one user that answers the owner's
    /// queries (usage [`Response`](super::Usage::Response)) — the first admitted, as the
    /// paper lets any one of them answer — and waits (at most `timeout`) for its answer. With
    /// no such user within the timeout: [`PortError::NoSuchUser`].
    pub fn query(&self, value: &Q, timeout: Duration) -> Result<R, PortError> {
        wait::block_on(self.query_future(value, timeout))
    }
    pub(crate) async fn query_future(&self, value: &Q, timeout: Duration) -> Result<R, PortError> {
        self.to_one_user(None, value, timeout).await
    }

    /// `send` the other way round, to whichever user takes the owner's messages (usage
    /// [`Receive`](super::Usage::Receive); the first admitted): for a port of one user
    /// (`max_users: Some(1)`) whose task may be replaced under another name. With no such
    /// user within the timeout: [`PortError::NoSuchUser`].
    pub fn send_any(&self, value: &Q, timeout: Duration) -> Result<R, PortError> {
        wait::block_on(self.send_any_future(value, timeout))
    }

    pub(crate) async fn send_any_future(
        &self,
        value: &Q,
        timeout: Duration,
    ) -> Result<R, PortError> {
        self.to_one_user(Some(""), value, timeout).await
    }
    /// Sends `value` to the user of task `task` (with `Some("")`, to the first admitted user
    /// with usage `Receive`; with `None`, to the first admitted user with usage `Response`)
    /// and waits for its answer.
    async fn to_one_user(
        &self,
        task: Option<&str>,
        value: &Q,
        timeout: Duration,
    ) -> Result<R, PortError> {
        use super::Usage;
        let (operation, owner_usages, user_usages): (&str, &[Usage], &[Usage]) = match task {
            Some("") => ("send", &[Usage::Send], &[Usage::Receive]),
            Some(_) => (
                "send_to",
                &[Usage::Send, Usage::Query],
                &[Usage::Receive, Usage::Response],
            ),
            None => ("query", &[Usage::Query], &[Usage::Response]),
        };
        let task = task.filter(|t| !t.is_empty());
        self.shared.require(operation, owner_usages)?;
        let start = Instant::now();
        let deadline = wait::deadline(start, timeout);
        let port = &self.shared.port;
        // The user, once the owner has heard (and admitted) it.
        let (user, task) = loop {
            let seen = self.shared.users_changed.generation();
            if let Some(found) = self.shared.admitted_with(task, user_usages) {
                break found;
            }
            if wait::timeout_at(deadline, self.shared.users_changed.changed(seen))
                .await
                .is_none()
            {
                return Err(PortError::NoSuchUser {
                    port: port.clone(),
                    owner: self.shared.task.clone(),
                    user: task.unwrap_or("(any)").to_owned(),
                    usage: match operation {
                        "send_to" => "Receive or Response",
                        "send" => "Receive",
                        _ => "Response",
                    },
                    present: self.shared.present_users(),
                });
            }
        };
        let task = task.as_str();
        let stream = self.shared.to_user(&user)?;
        let awaited = self.broadcast_message(&stream, value, &format!("a message to `{task}`"))?;
        drop(stream);
        let shared = &self.shared;
        let reply = wait::timeout_at(
            deadline,
            self.demux
                .next(&self.broadcast_replies, self.incarnation, awaited.id, |r| {
                    // The user was chosen for its usage: only the user list is judged again.
                    r.user == user && shared.accepts_broadcast_reply(r, &[])
                }),
        )
        .await
        .flatten()
        .ok_or_else(|| PortError::Timeout {
            port: port.clone(),
            operation: match operation {
                "query" => "owner's query",
                "send" => "owner's send",
                _ => "send_to",
            },
            task: self.shared.task.clone(),
            owner: Some(task.to_owned()),
            waited: start.elapsed(),
        })?;
        Ok(super::sendall::decode(port, reply)?.1)
    }

    /// The users the owner has heard and admitted now, as task names with their usages
    /// (for example `arm [Send, Receive]`), sorted: those `send_to` and `callall` reach.
    pub fn present_users(&self) -> Vec<String> {
        let admitted = self.shared.admitted_users();
        let mut users: Vec<String> = self
            .shared
            .presence()
            .active
            .iter()
            .filter(|(u, _)| admitted.contains(&u.user))
            .map(|(u, _)| format!("{} {:?}", u.task, u.usages))
            .collect();
        users.sort();
        users
    }

    /// Users matched on the broadcast topic now (who a `sendall` reaches; those the
    /// restrictions refuse do not answer, and their replies would be dropped).
    pub fn users(&self) -> usize {
        self.broadcast.matched().len()
    }

    /// Replies to `sendall` dropped because their users are refused or not admitted.
    pub fn refused_replies(&self) -> u64 {
        self.shared.refused_replies.load(Ordering::Relaxed)
    }

    /// Requests dropped because they were for another owner of the port (during a takeover,
    /// each request is for one owner: the one its sender knew as the port's owner).
    pub fn misaddressed(&self) -> u64 {
        self.shared.misaddressed.load(Ordering::Relaxed)
    }

    /// Requests dropped because their senders stopped waiting (their timeouts passed while
    /// the requests waited here, or queued for a [`Responder`](super::Responder)'s handler).
    pub fn withdrawn(&self) -> u64 {
        self.shared.withdrawn.load(Ordering::Relaxed)
    }

    /// The users refused so far by the port's restrictions, in words.
    pub fn refusals(&self) -> Vec<String> {
        self.shared.presence().refused.clone()
    }

    /// The port's restrictions.
    pub fn restrictions(&self) -> &Restrictions {
        &self.shared.restrictions
    }

    /// Sets the port's priority for [`select`](super::select) (higher first); `None` ranks
    /// it below every port with a priority (the default, unless its restrictions give one).
    pub fn set_priority(&self, priority: impl Into<Option<i32>>) {
        self.priority.store(
            priority.into().map_or(UNPRIORITISED, i64::from),
            Ordering::Relaxed,
        );
    }

    /// The other owner of this port, while one is present (its declaration matched).
    pub fn conflict(&self) -> Option<String> {
        self.shared.conflict()
    }

    /// The owner that took this port over from this one, if one did.
    pub fn superseded_by(&self) -> Option<String> {
        self.shared.superseded_by()
    }

    /// This owner's takeover claim (0: declared; see [`PortOwner::take_over`]).
    pub fn claim(&self) -> u64 {
        self.shared.claim
    }

    /// [`receive`](Self::receive) for a loop that serves the port: `None` at the timeout, for
    /// a request that does not decode (its sender's problem: the next one is taken at once),
    /// and for a failure that lasts (a second owner), which is logged as an error when it
    /// begins or changes (`failing` remembers it between calls) and then waited out for
    /// `timeout` (or until the other owner goes).
    pub fn serve_next(
        &self,
        timeout: Duration,
        failing: &mut Option<String>,
    ) -> Option<(Q, ReplyHandle<R>)> {
        let start = Instant::now();
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
                let shared = &self.shared;
                wait::block_on(wait::timeout_at(wait::deadline(start, timeout), async {
                    loop {
                        let seen = shared.changed.generation();
                        // A replaced owner waits the timeout out too (no busy loop).
                        let lasting =
                            shared.conflict().is_some() || shared.superseded_by().is_some();
                        if !lasting || shared.stop.load(Ordering::Acquire) {
                            return;
                        }
                        shared.changed.changed(seen).await;
                    }
                }));
                None
            }
        }
    }

    /// Waits for the next request (at most `timeout`): the message and the handle to reply
    /// with. Fails while another owner of the port exists.
    pub fn receive(&self, timeout: Duration) -> Result<(Q, ReplyHandle<R>), PortError> {
        wait::block_on(self.receive_future(timeout))
    }

    pub(crate) async fn receive_future(
        &self,
        timeout: Duration,
    ) -> Result<(Q, ReplyHandle<R>), PortError> {
        self.shared
            .require("receive", &[super::Usage::Receive, super::Usage::Response])?;
        let start = Instant::now();
        let at = wait::deadline(start, timeout);
        // A tightly-coupled port's next request is busy-waited for at first.
        let spin = self.shared.restrictions.class.spin();
        if !spin.is_zero() {
            wait::spin_until(start + spin.min(timeout));
        }
        match wait::timeout_at(at, self.next_request()).await {
            Some(Ok(request)) => self.handle(request),
            Some(Err(err)) => Err(err),
            None => {
                self.shared.check_superseded()?;
                // At the deadline, what is already there is still taken.
                match self.take_request() {
                    Some(request) => self.handle(request),
                    None => Err(PortError::Timeout {
                        port: self.shared.port.clone(),
                        operation: "receive",
                        task: self.shared.task.clone(),
                        owner: None,
                        waited: start.elapsed(),
                    }),
                }
            }
        }
    }

    /// The requests topic when `receive` reads it itself (no filter), and this owner is not
    /// replaced.
    fn direct_requests(&self) -> Option<Arc<Consumer<Request>>> {
        if self.direct {
            self.shared.requests()
        } else {
            None
        }
    }

    /// The next request from an admitted user, as soon as there is one.
    async fn next_request(&self) -> Result<Request, PortError> {
        loop {
            let seen = self.shared.changed.generation();
            self.shared.check_superseded()?;
            if let Some(other) = self.shared.conflict() {
                return Err(PortError::SecondOwner {
                    port: self.shared.port.clone(),
                    first: self.shared.task.clone(),
                    second: other,
                });
            }
            if let Some(request) = self.take_request() {
                return Ok(request);
            }
            let arrived = match self.direct_requests().as_deref() {
                Some(requests) => {
                    match wait::race(
                        wait::next_sample(requests),
                        self.shared.changed.changed(seen),
                    )
                    .await
                    {
                        Either::Left(Some(sample)) => Some(sample.value),
                        // The topic closed: only a change can help now.
                        Either::Left(None) => {
                            self.shared.changed.changed(seen).await;
                            None
                        }
                        Either::Right(()) => None,
                    }
                }
                None => {
                    self.shared.changed.changed(seen).await;
                    None
                }
            };
            // Through the queue, so that a withdrawal right behind it is seen first.
            if let Some(request) = arrived {
                self.shared.absorb(&mut self.shared.pending(), request);
            }
        }
    }

    /// A request waiting now, buffered or on the topic, from an admitted user. What waits on
    /// the topic is read first (up to the buffer's bound), so that a request whose sender
    /// withdrew it is never received.
    fn take_request(&self) -> Option<Request> {
        loop {
            let requests = self.direct_requests();
            let request = {
                let mut pending = self.shared.pending();
                if let Some(requests) = requests {
                    while pending.len() < PENDING_LIMIT {
                        match requests.try_recv() {
                            Ok(sample) => self.shared.absorb(&mut pending, sample.value),
                            Err(_) => break,
                        }
                    }
                }
                pending.pop_front()?
            };
            self.shared.changed.notify();
            if self.admit(&request) {
                return Some(request);
            }
        }
    }

    /// Whether `request` comes from an admitted user (else it is dropped).
    fn admit(&self, request: &Request) -> bool {
        if self.shared.admitted(&request.user) {
            return true;
        }
        tracing::debug!(port = %self.shared.port, user = %request.task,
            "request from a user the port's restrictions refuse: dropped");
        false
    }

    fn handle(&self, request: Request) -> Result<(Q, ReplyHandle<R>), PortError> {
        let value = postcard::from_bytes::<Q>(&request.payload).map_err(|e| PortError::Codec {
            port: self.shared.port.clone(),
            what: "decoding a request",
            reason: e.to_string(),
        })?;
        Ok((
            value,
            ReplyHandle {
                shared: Arc::clone(&self.shared),
                answered: request.answered,
                id: request.id,
                user: request.user,
                task: request.task,
                _reply: PhantomData,
            },
        ))
    }
}

impl<Q: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned> super::Selectable
    for PortOwner<Q, R>
{
    fn port(&self) -> &str {
        &self.shared.port
    }

    fn priority(&self) -> Option<i32> {
        let stored = self.priority.load(Ordering::Relaxed);
        (stored != UNPRIORITISED).then_some(stored as i32)
    }

    fn waiting(&self) -> usize {
        let requests = self.direct_requests();
        let mut pending = self.shared.pending();
        let before = pending.len();
        if let Some(requests) = requests {
            // Taken off the topic up to a bound; the rest waits there (flow control).
            while pending.len() < PENDING_LIMIT {
                match requests.try_recv() {
                    Ok(sample) => self.shared.absorb(&mut pending, sample.value),
                    Err(_) => break,
                }
            }
        }
        let waiting = pending.len();
        drop(pending);
        if waiting != before {
            self.shared.changed.notify();
        }
        waiting
    }

    fn arrival(&self) -> Pin<Box<dyn Future<Output = ()> + '_>> {
        Box::pin(async move {
            let seen = self.shared.changed.generation();
            let room = self.shared.queue_len() < PENDING_LIMIT;
            match self.direct_requests().as_deref() {
                Some(requests) if room => {
                    let arrived = wait::race(
                        wait::next_sample(requests),
                        self.shared.changed.changed(seen),
                    );
                    match arrived.await {
                        Either::Left(Some(sample)) => {
                            self.shared.absorb(&mut self.shared.pending(), sample.value);
                            self.shared.changed.notify();
                        }
                        Either::Left(None) => self.shared.changed.changed(seen).await,
                        Either::Right(()) => {}
                    }
                }
                _ => self.shared.changed.changed(seen).await,
            }
        })
    }
}

impl<Q, R> Drop for PortOwner<Q, R> {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        self.shared.changed.notify();
        for thread in [self.declaration.take(), self.filter.take()]
            .into_iter()
            .flatten()
        {
            let _ = thread.join();
        }
    }
}

/// Requests `select` takes off the topic ahead of `receive`, at most.
pub(crate) const PENDING_LIMIT: usize = 1024;
/// Withdrawals of requests already received that an owner remembers, at most.
const WITHDRAWALS_KEPT: usize = 1024;
/// Users whose reply streams an owner keeps at most (the least recently used goes first).
const REPLY_STREAMS: usize = 1024;

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

    /// Whether the sender stopped waiting for the reply (its timeout passed after this
    /// request was received): a reply now reaches nobody. A responder skips such queries.
    pub fn is_withdrawn(&self) -> bool {
        self.shared.withdrawn_after_receipt(&self.user, self.id)
    }

    /// Counts this request among those dropped for their senders (a responder skipped it).
    pub(crate) fn count_withdrawn(&self) {
        self.shared.withdrawn.fetch_add(1, Ordering::Relaxed);
    }

    /// Replies (does not wait for the sender).
    pub fn reply(self, value: &R) -> Result<(), PortError> {
        if self.answered {
            return Ok(());
        }
        self.shared.check_superseded()?;
        let payload = postcard::to_stdvec(value).map_err(|e| PortError::Codec {
            port: self.shared.port.clone(),
            what: "encoding a reply",
            reason: e.to_string(),
        })?;
        self.reply_encoded(payload)
    }

    /// Replies with `payload`, a reply encoded already (a module's response handler's).
    pub(crate) fn reply_encoded(self, payload: Vec<u8>) -> Result<(), PortError> {
        if self.answered {
            return Ok(());
        }
        self.shared.check_superseded()?;
        send_reply(&self.shared, &self.user, &self.task, self.id, payload)
    }
}

/// Writes a reply to user handle `user`. The first reply to a user waits (at most
/// [`REPLY_MATCH`]) until its reply stream matches — outside the lock, so other replies go on.
pub(crate) fn send_reply(
    shared: &OwnerShared,
    user: &str,
    task: &str,
    id: u64,
    payload: Vec<u8>,
) -> Result<(), PortError> {
    let reply = Reply {
        id,
        owner: shared.incarnation,
        payload,
        refused: None,
    };
    write_reply(shared, user, task, &reply)
}

/// Refuses `request` (a filter's exception): its sender's call fails with `reason`.
pub(crate) fn send_refusal(
    shared: &OwnerShared,
    request: &Request,
    reason: String,
) -> Result<(), PortError> {
    let reply = Reply {
        id: request.id,
        owner: shared.incarnation,
        payload: Vec::new(),
        refused: Some(reason),
    };
    write_reply(shared, &request.user, &request.task, &reply)
}

fn write_reply(
    shared: &OwnerShared,
    user: &str,
    task: &str,
    reply: &Reply,
) -> Result<(), PortError> {
    let write = |producer: &Producer<Reply>| {
        producer.write(reply).map_err(|source| PortError::Write {
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

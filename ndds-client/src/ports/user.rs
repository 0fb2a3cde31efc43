//! [`PortUser`]: a task that uses a port — `send` blocks until the owner replies (or the
//! timeout). Several threads may send through one user at once; each gets its own reply.

use std::collections::HashMap;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::error::PortError;
use super::wire::{OwnerInfo, Reply, Request, Usage, UserInfo};
use super::{
    ANNOUNCE_PERIOD, check_name, reliable_consumer, reliable_producer, spawn_error, topic,
};
use crate::{Consumer, Participant, Producer, TypeDescription};

/// A user of a port: sends requests of type `Q`, gets replies of type `R`.
pub struct PortUser<Q, R> {
    usages: Vec<Usage>,
    declared: Instant,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    announcer: Option<std::thread::JoinHandle<()>>,
    broadcasts: Consumer<super::sendall::Broadcast>,
    broadcast_replies: Producer<super::sendall::BroadcastReply>,
    port: String,
    task: String,
    user: String,
    requests: Producer<Request>,
    replies: Consumer<Reply>,
    owners: Consumer<OwnerInfo>,
    next_id: AtomicU64,
    demux: Mutex<Demux>,
    arrived: Condvar,
    formats: (u64, u64),
    _types: PhantomData<fn(Q) -> R>,
}

#[derive(Default)]
struct Demux {
    /// Replies taken off the topic by one sender for another.
    waiting: HashMap<u64, Reply>,
    /// Requests whose senders still wait (replies to others are dropped).
    awaiting: std::collections::HashSet<u64>,
    /// A sender is reading the reply topic now.
    reading: bool,
    /// Owners seen recently: incarnation -> (description, when last seen).
    owners: HashMap<u64, (OwnerInfo, Instant)>,
    /// When each owner incarnation was first seen (admission takes a few announcements).
    first_seen: HashMap<u64, Instant>,
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
        check_name(port)?;
        let user = format!("{:016x}", fastrand::u64(..));
        let announce = reliable_producer::<UserInfo>(participant, port, &topic(port, "users"))?;
        let info = UserInfo {
            user: user.clone(),
            task: task.to_owned(),
            usages: usages.to_vec(),
        };
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = std::sync::Arc::clone(&stop);
        let thread = format!("port-user-{port}");
        let announcer = std::thread::Builder::new()
            .name(thread.clone())
            .spawn(move || {
                while !flag.load(Ordering::Acquire) {
                    let _ = announce.write(&info);
                    let until = Instant::now() + ANNOUNCE_PERIOD;
                    while Instant::now() < until && !flag.load(Ordering::Acquire) {
                        std::thread::sleep(Duration::from_millis(10));
                    }
                }
            })
            .map_err(spawn_error(port, &thread))?;
        Ok(Self {
            usages: usages.to_vec(),
            declared: Instant::now(),
            stop,
            announcer: Some(announcer),
            broadcasts: reliable_consumer(participant, port, &topic(port, "all"))?,
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
            arrived: Condvar::new(),
            formats: (
                TypeDescription::of::<Q>().fingerprint(),
                TypeDescription::of::<R>().fingerprint(),
            ),
            _types: PhantomData,
        })
    }

    /// The port's name.
    pub fn port(&self) -> &str {
        &self.port
    }

    /// The owner now: its task, or an error when there are two or the formats differ; `None`
    /// while none is known.
    fn owner(&self, demux: &mut Demux) -> Result<Option<String>, PortError> {
        while let Ok(sample) = self.owners.try_recv() {
            demux
                .first_seen
                .entry(sample.value.incarnation)
                .or_insert_with(Instant::now);
            demux
                .owners
                .insert(sample.value.incarnation, (sample.value, Instant::now()));
        }
        let known: Vec<u64> = demux.owners.keys().copied().collect();
        demux.first_seen.retain(|k, _| known.contains(k));
        // An owner not heard for three announcement periods is gone.
        demux
            .owners
            .retain(|_, (_, seen)| seen.elapsed() < ANNOUNCE_PERIOD * 3);
        let mut owners: Vec<&OwnerInfo> = demux.owners.values().map(|(o, _)| o).collect();
        owners.sort_by(|a, b| a.task.cmp(&b.task).then(a.pid.cmp(&b.pid)));
        match owners.as_slice() {
            [] => Ok(None),
            [owner] => {
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
                    // The owner admits users on its next announcements; past that, it is full.
                    let since = demux
                        .first_seen
                        .get(&owner.incarnation)
                        .copied()
                        .unwrap_or_else(Instant::now)
                        .max(self.declared);
                    if let Some(max) = owner.restrictions.max_users
                        && since.elapsed() > ANNOUNCE_PERIOD * 4
                    {
                        return Err(refused(
                            "maximum active users",
                            format!("{max} active users already"),
                        ));
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
                Ok(Some(owner.task.clone()))
            }
            [a, b, ..] => Err(PortError::SecondOwner {
                port: self.port.clone(),
                first: format!("{} (pid {})", a.task, a.pid),
                second: format!("{} (pid {})", b.task, b.pid),
            }),
        }
    }

    /// Sends `value` and waits (at most `timeout`, or the port's timeout restriction if
    /// shorter) for the owner's reply.
    pub fn send(&self, value: &Q, timeout: Duration) -> Result<R, PortError> {
        self.require(Usage::Send)?;
        self.exchange(value, timeout)
    }

    /// Refuses locally an operation this user did not declare.
    fn require(&self, usage: Usage) -> Result<(), PortError> {
        if self.usages.contains(&usage) {
            return Ok(());
        }
        Err(PortError::Refused {
            port: self.port.clone(),
            owner: String::new(),
            user: self.task.clone(),
            restriction: "usage",
            detail: format!(
                "{usage:?} was not declared by this user (declared: {:?})",
                self.usages
            ),
        })
    }

    fn exchange(&self, value: &Q, timeout: Duration) -> Result<R, PortError> {
        let start = Instant::now();
        let mut timeout = timeout;
        let timed_out = |owner: Option<String>| PortError::Timeout {
            port: self.port.clone(),
            operation: "send",
            task: self.task.clone(),
            owner,
            waited: start.elapsed(),
        };
        // An owner must be known (and unique, with our formats) before the request goes out.
        let owner = loop {
            let mut demux = self.demux.lock().unwrap_or_else(|p| p.into_inner());
            if let Some(owner) = self.owner(&mut demux)? {
                let declared = demux
                    .owners
                    .values()
                    .find_map(|(o, _)| o.restrictions.timeout_ms);
                if let Some(ms) = declared {
                    timeout = timeout.min(Duration::from_millis(ms));
                }
                break owner;
            }
            drop(demux);
            if start.elapsed() >= timeout {
                return Err(timed_out(None));
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        let left = timeout.saturating_sub(start.elapsed());
        if !self.requests.wait_for_consumers(1, left) {
            return Err(timed_out(Some(owner)));
        }
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let payload = postcard::to_stdvec(value).map_err(|e| PortError::Codec {
            port: self.port.clone(),
            what: "encoding a request",
            reason: e.to_string(),
        })?;
        self.demux
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .awaiting
            .insert(id);
        let written = self.requests.write(&Request {
            id,
            user: self.user.clone(),
            task: self.task.clone(),
            payload,
        });
        let deadline = start
            .checked_add(timeout)
            .unwrap_or(start + Duration::from_secs(86_400 * 365));
        let reply = match written {
            Ok(()) => self.wait_reply(id, deadline),
            Err(_) => None,
        };
        {
            let mut demux = self.demux.lock().unwrap_or_else(|p| p.into_inner());
            demux.awaiting.remove(&id);
            demux.waiting.remove(&id);
        }
        if let Err(source) = written {
            return Err(PortError::Write {
                port: self.port.clone(),
                what: "a request".to_owned(),
                source,
            });
        }
        let reply = reply.ok_or_else(|| timed_out(Some(owner)))?;
        postcard::from_bytes(&reply.payload).map_err(|e| PortError::Codec {
            port: self.port.clone(),
            what: "decoding a reply",
            reason: e.to_string(),
        })
    }

    /// Takes the next message the owner sent to all users (`sendall`), waiting at most
    /// `timeout`, and answers it with `answer`; returns the message.
    pub fn receive_all(
        &self,
        timeout: Duration,
        answer: impl FnOnce(&Q) -> R,
    ) -> Result<Q, PortError> {
        self.require(Usage::ReceiveAll)?;
        let start = Instant::now();
        let broadcast = self
            .broadcasts
            .recv_timeout(timeout)
            .map_err(|_| PortError::Timeout {
                port: self.port.clone(),
                operation: "receive_all",
                task: self.task.clone(),
                owner: None,
                waited: start.elapsed(),
            })?
            .value;
        let value: Q = postcard::from_bytes(&broadcast.payload).map_err(|e| PortError::Codec {
            port: self.port.clone(),
            what: "decoding a broadcast",
            reason: e.to_string(),
        })?;
        let payload = postcard::to_stdvec(&answer(&value)).map_err(|e| PortError::Codec {
            port: self.port.clone(),
            what: "encoding a broadcast reply",
            reason: e.to_string(),
        })?;
        // The broadcast came, so its owner exists; its reply stream may not have matched this
        // user yet (across hosts discovery is not symmetric in time): a reliable reply written
        // before the match would reach nobody. Wait briefly, as first replies do.
        if self.broadcast_replies.matched().is_empty() {
            let _ = self
                .broadcast_replies
                .wait_for_consumers(1, super::owner::REPLY_MATCH.min(timeout));
        }
        self.broadcast_replies
            .write(&super::sendall::BroadcastReply {
                owner: broadcast.owner,
                id: broadcast.id,
                task: self.task.clone(),
                payload,
            })
            .map_err(|source| PortError::Write {
                port: self.port.clone(),
                what: "a broadcast reply".to_owned(),
                source,
            })?;
        Ok(value)
    }

    /// Queries the port: the owner's response handler (see [`Responder`](super::Responder))
    /// answers. The same exchange as [`send`](Self::send).
    pub fn query(&self, value: &Q, timeout: Duration) -> Result<R, PortError> {
        self.require(Usage::Query)?;
        self.exchange(value, timeout)
    }

    /// The reply to request `id`: one waiting sender reads the topic at a time and hands the
    /// others their replies.
    fn wait_reply(&self, id: u64, deadline: Instant) -> Option<Reply> {
        let mut demux = self.demux.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            if let Some(reply) = demux.waiting.remove(&id) {
                return Some(reply);
            }
            let now = Instant::now();
            if now >= deadline {
                return None;
            }
            if demux.reading {
                demux = self
                    .arrived
                    .wait_timeout(demux, deadline - now)
                    .unwrap_or_else(|p| p.into_inner())
                    .0;
                continue;
            }
            demux.reading = true;
            drop(demux);
            let got = self
                .replies
                .recv_timeout((deadline - now).min(Duration::from_millis(20)));
            demux = self.demux.lock().unwrap_or_else(|p| p.into_inner());
            demux.reading = false;
            if let Ok(sample) = got
                && demux.awaiting.contains(&sample.value.id)
            {
                demux.waiting.insert(sample.value.id, sample.value);
            }
            self.arrived.notify_all();
        }
    }
}

impl<Q, R> Drop for PortUser<Q, R> {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.announcer.take() {
            let _ = thread.join();
        }
    }
}

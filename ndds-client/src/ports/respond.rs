//! Query / response: response handlers registered by the owner run in the owner's process and
//! answer queries ([`PortUser::query`](super::PortUser::query)). Handlers have priorities — the
//! order statement's equivalent: one worker runs one handler at a time, always the pending
//! query of the highest-priority port first (FIFO within a port), so an urgent section is
//! never queued behind less urgent queries that arrived earlier.
//!
//! The worker is the responder's only thread: before each handler it takes every query that
//! has arrived on any port into a [`PrioritySelect`] (up to [`PENDING_PER_PORT`] a port; the
//! rest waits on the topic), runs the first the select gives, and when none is left sleeps
//! on all the ports' request topics at once.

use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use ndds_core::ports::PrioritySelect;
use serde::Serialize;
use serde::de::DeserializeOwned;

use super::Selectable;
use super::error::PortError;
use super::owner::PortOwner;
use super::wait::{self, Notify};
use super::wire::Restrictions;
use crate::Participant;

type Job = Box<dyn FnOnce() + Send>;

/// One port a responder answers, with its handler.
trait Served: Send + Sync {
    fn name(&self) -> &str;
    /// The next query waiting on the port now, as the job that answers it.
    fn take(self: Arc<Self>) -> Option<Job>;
    /// Resolves once a query may be waiting.
    fn arrival(&self) -> Pin<Box<dyn Future<Output = ()> + '_>>;
}

struct Handler<Q, R, F> {
    owner: PortOwner<Q, R>,
    handler: Mutex<F>,
    /// The failure being logged (a second owner), so it is logged once.
    failing: Mutex<Option<String>>,
}

impl<Q, R, F> Served for Handler<Q, R, F>
where
    Q: Serialize + DeserializeOwned + Send + 'static,
    R: Serialize + DeserializeOwned + Send + 'static,
    F: FnMut(Q) -> R + Send + 'static,
{
    fn name(&self) -> &str {
        self.owner.port()
    }

    fn take(self: Arc<Self>) -> Option<Job> {
        let (query, reply) = match self.owner.receive(Duration::ZERO) {
            Ok(pending) => {
                *self.failing.lock().unwrap_or_else(|p| p.into_inner()) = None;
                pending
            }
            Err(PortError::Timeout { .. }) => return None,
            Err(err) => {
                let text = err.to_string();
                let mut failing = self.failing.lock().unwrap_or_else(|p| p.into_inner());
                if failing.as_ref() != Some(&text) {
                    tracing::warn!(port = %self.owner.port(), error = %err, "query not served");
                    *failing = Some(text);
                }
                return None;
            }
        };
        Some(Box::new(move || {
            // Its sender stopped waiting while it queued behind other handlers: not run.
            if reply.is_withdrawn() {
                reply.count_withdrawn();
                return;
            }
            let answer = (self.handler.lock().unwrap_or_else(|p| p.into_inner()))(query);
            if let Err(err) = reply.reply(&answer) {
                tracing::warn!(port = %self.owner.port(), error = %err, "response not sent");
            }
        }))
    }

    fn arrival(&self) -> Pin<Box<dyn Future<Output = ()> + '_>> {
        self.owner.arrival()
    }
}

struct Queue {
    select: PrioritySelect<Job>,
    ports: Vec<Arc<dyn Served>>,
}

struct Shared {
    queue: Mutex<Queue>,
    /// Told when a handler is added and when the responder stops.
    changed: Notify,
    stop: AtomicBool,
}

impl Shared {
    fn queue(&self) -> MutexGuard<'_, Queue> {
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Pending queries each port holds at most before the rest waits on its topic.
pub const PENDING_PER_PORT: usize = 1024;

/// Response handlers of one task, served by one worker in priority order.
pub struct Responder {
    shared: Arc<Shared>,
    worker: Option<JoinHandle<()>>,
    participant: Participant,
    task: String,
}

impl Responder {
    /// A responder for `task` (no handlers yet; the worker starts at once).
    pub fn new(participant: &Participant, task: &str) -> Result<Self, PortError> {
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue {
                select: PrioritySelect::new(),
                ports: Vec::new(),
            }),
            changed: Notify::default(),
            stop: AtomicBool::new(false),
        });
        let worker = Arc::clone(&shared);
        let name = format!("respond-{task}");
        let thread = std::thread::Builder::new()
            .name(name.clone())
            .spawn(move || serve(&worker))
            .map_err(|source| PortError::Spawn {
                port: None,
                thread: name,
                source,
            })?;
        Ok(Self {
            shared,
            worker: Some(thread),
            participant: participant.clone(),
            task: task.to_owned(),
        })
    }

    /// Owns `port` and answers each query on it with `handler`, at `priority` (higher runs
    /// first).
    pub fn handle<Q, R, F>(
        &mut self,
        port: &str,
        priority: i32,
        handler: F,
    ) -> Result<(), PortError>
    where
        Q: Serialize + DeserializeOwned + Send + 'static,
        R: Serialize + DeserializeOwned + Send + 'static,
        F: FnMut(Q) -> R + Send + 'static,
    {
        let restrictions = Restrictions {
            priority: Some(priority),
            ..Restrictions::default()
        };
        self.handle_with(port, restrictions, handler)
    }

    /// Owns `port` with `restrictions` and answers each query on it with `handler`: users the
    /// user list, usages or maximum of active users refuse are refused as by any owner, a
    /// timeout restriction bounds the users' queries, and the priority orders this port's
    /// queries against the responder's other ports (without one, after every port with one).
    pub fn handle_with<Q, R, F>(
        &mut self,
        port: &str,
        restrictions: Restrictions,
        handler: F,
    ) -> Result<(), PortError>
    where
        Q: Serialize + DeserializeOwned + Send + 'static,
        R: Serialize + DeserializeOwned + Send + 'static,
        F: FnMut(Q) -> R + Send + 'static,
    {
        let priority = restrictions.priority;
        let owner =
            PortOwner::<Q, R>::declare_with(&self.participant, port, &self.task, restrictions)?;
        let mut queue = self.shared.queue();
        queue
            .select
            .add_port(port, priority, PENDING_PER_PORT)
            .map_err(|source| PortError::Handler {
                port: port.to_owned(),
                source,
            })?;
        queue.ports.push(Arc::new(Handler {
            owner,
            handler: Mutex::new(handler),
            failing: Mutex::new(None),
        }));
        drop(queue);
        self.shared.changed.notify();
        Ok(())
    }
}

/// The worker (see the module docs).
fn serve(shared: &Shared) {
    while !shared.stop.load(Ordering::Acquire) {
        let seen = shared.changed.generation();
        let (job, ports) = {
            let mut queue = shared.queue();
            let Queue { select, ports } = &mut *queue;
            for port in ports.iter() {
                while select.waiting(port.name()) < PENDING_PER_PORT {
                    let Some(job) = Arc::clone(port).take() else {
                        break;
                    };
                    if let Err(full) = select.push(port.name(), job) {
                        // Cannot be full (checked) nor unknown (added with the port).
                        (full.message)();
                        break;
                    }
                }
            }
            (select.pop().map(|(_, job)| job), ports.clone())
        };
        if let Some(job) = job {
            if std::panic::catch_unwind(std::panic::AssertUnwindSafe(job)).is_err() {
                tracing::warn!("a response handler panicked; its query gets no response");
            }
            continue;
        }
        wait::block_on(async {
            let mut arrivals: Vec<_> = ports.iter().map(|p| p.arrival()).collect();
            arrivals.push(Box::pin(shared.changed.changed(seen)));
            super::any(arrivals).await;
        });
    }
}

impl Drop for Responder {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        self.shared.changed.notify();
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
    }
}

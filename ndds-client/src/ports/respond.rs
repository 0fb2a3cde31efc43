//! Query / response: response handlers registered by the owner run in the owner's process and
//! answer queries ([`PortUser::query`](super::PortUser::query)). Handlers have priorities — the
//! order statement's equivalent: one worker runs one handler at a time, always the pending
//! query of the highest-priority port first (FIFO within a port), so an urgent section is
//! never queued behind less urgent queries that arrived earlier.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use ndds_core::ports::PrioritySelect;
use serde::Serialize;
use serde::de::DeserializeOwned;

use super::error::PortError;
use super::owner::PortOwner;
use crate::Participant;

type Job = Box<dyn FnOnce() + Send>;

struct Queue {
    select: PrioritySelect<Job>,
}

struct Shared {
    queue: Mutex<Queue>,
    ready: Condvar,
    stop: AtomicBool,
}

/// Pending queries each port holds at most before its receiver waits.
pub const PENDING_PER_PORT: usize = 1024;

/// Response handlers of one task, served by one worker in priority order.
pub struct Responder {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    participant: Participant,
    task: String,
}

impl Responder {
    /// A responder for `task` (no handlers yet; the worker starts at once).
    pub fn new(participant: &Participant, task: &str) -> Result<Self, PortError> {
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue {
                select: PrioritySelect::new(),
            }),
            ready: Condvar::new(),
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
            threads: vec![thread],
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
        let owner = PortOwner::<Q, R>::declare(&self.participant, port, &self.task)?;
        self.shared
            .queue
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .select
            .add_port(port, priority, PENDING_PER_PORT)
            .map_err(|source| PortError::Handler {
                port: port.to_owned(),
                source,
            })?;
        let handler = Arc::new(Mutex::new(handler));
        let shared = Arc::clone(&self.shared);
        let name = port.to_owned();
        let thread_name = format!("port-rx-{port}");
        let thread = std::thread::Builder::new()
            .name(thread_name.clone())
            .spawn(move || {
                while !shared.stop.load(Ordering::Acquire) {
                    let (query, reply) = match owner.receive(Duration::from_millis(50)) {
                        Ok(pending) => pending,
                        Err(PortError::Timeout { .. }) => continue,
                        Err(err) => {
                            tracing::warn!(port = %name, error = %err, "query not served");
                            std::thread::sleep(Duration::from_millis(50));
                            continue;
                        }
                    };
                    let handler = Arc::clone(&handler);
                    let port = name.clone();
                    let mut job: Job = Box::new(move || {
                        let answer = (handler.lock().unwrap_or_else(|p| p.into_inner()))(query);
                        if let Err(err) = reply.reply(&answer) {
                            tracing::warn!(port = %port, error = %err, "response not sent");
                        }
                    });
                    // Hand it to the worker; wait while this port's queue is full.
                    loop {
                        let mut queue = shared.queue.lock().unwrap_or_else(|p| p.into_inner());
                        match queue.select.push(&name, job) {
                            Ok(()) => {
                                shared.ready.notify_one();
                                break;
                            }
                            Err(full) => {
                                job = full.message;
                                drop(queue);
                                if shared.stop.load(Ordering::Acquire) {
                                    return;
                                }
                                std::thread::sleep(Duration::from_millis(1));
                            }
                        }
                    }
                }
            })
            .map_err(super::spawn_error(port, &thread_name))?;
        self.threads.push(thread);
        Ok(())
    }
}

fn serve(shared: &Shared) {
    loop {
        let job = {
            let mut queue = shared.queue.lock().unwrap_or_else(|p| p.into_inner());
            loop {
                if shared.stop.load(Ordering::Acquire) {
                    return;
                }
                if let Some((_, job)) = queue.select.pop() {
                    break job;
                }
                queue = shared
                    .ready
                    .wait_timeout(queue, Duration::from_millis(50))
                    .unwrap_or_else(|p| p.into_inner())
                    .0;
            }
        };
        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(job)).is_err() {
            tracing::warn!("a response handler panicked; its query gets no response");
        }
    }
}

impl Drop for Responder {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        {
            let _queue = self.shared.queue.lock().unwrap_or_else(|p| p.into_inner());
            self.shared.ready.notify_all();
        }
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

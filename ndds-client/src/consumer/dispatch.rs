//! The participant's callback dispatcher: one thread (`ndds-callbacks`, started with the
//! first callback consumer) runs the callbacks of every callback consumer of the participant,
//! like an executor, instead of one thread per callback. A consumer whose queue gets an event
//! is marked ready; the thread takes the ready consumers in turn and hands each a bounded
//! number of events before the next, so one busy topic does not starve the others.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, Weak};
use std::thread::{JoinHandle, ThreadId};

use super::raw::ConsumerState;
use crate::sample::RawEvent;
use crate::sync::lock;

/// Events handed to one consumer's callback before the next ready consumer gets its turn.
const TURN: usize = 64;

/// A callback of the dispatcher.
pub(crate) type Callback = Box<dyn FnMut(RawEvent) + Send>;

/// One callback consumer, as the dispatcher sees it.
struct Entry {
    rx: flume::Receiver<RawEvent>,
    /// Weak: the consumer's state holds the queue's sender, which must go with the consumer.
    state: Weak<ConsumerState>,
    /// Held while the callback runs, so unregistering waits for a running callback.
    callback: Mutex<Option<Callback>>,
    /// True while the entry is in the ready queue.
    queued: AtomicBool,
    /// True once unregistered: no further event is handed to the callback.
    removed: AtomicBool,
}

#[derive(Default)]
struct Queue {
    ready: VecDeque<u64>,
    entries: HashMap<u64, Arc<Entry>>,
    closed: bool,
}

/// What the dispatcher thread and the consumers' queues share.
#[derive(Default)]
pub(crate) struct Shared {
    queue: Mutex<Queue>,
    wake: Condvar,
    next_id: AtomicU64,
    /// The dispatcher thread, once started.
    thread: Mutex<Option<(ThreadId, JoinHandle<()>)>>,
}

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Dispatcher").finish_non_exhaustive()
    }
}

/// Marks one consumer ready when its queue gets an event.
#[derive(Debug)]
pub(crate) struct Listener {
    shared: Weak<Shared>,
    id: u64,
}

impl Listener {
    pub(crate) fn ready(&self) {
        let Some(shared) = self.shared.upgrade() else {
            return;
        };
        let mut queue = lock(&shared.queue);
        if let Some(entry) = queue.entries.get(&self.id)
            && !entry.queued.swap(true, Ordering::AcqRel)
        {
            queue.ready.push_back(self.id);
            shared.wake.notify_one();
        }
    }
}

/// The dispatcher of one participant.
#[derive(Debug, Default)]
pub(crate) struct Dispatcher {
    shared: Arc<Shared>,
}

/// A registration: dropping it stops the callback (waiting for a running one to finish,
/// unless dropped from within a callback).
#[derive(Debug)]
pub(crate) struct Registration {
    shared: Arc<Shared>,
    id: u64,
}

impl Dispatcher {
    /// Runs `callback` for every event of `state`'s queue, on the dispatcher thread.
    pub(crate) fn register(
        &self,
        state: &Arc<ConsumerState>,
        rx: flume::Receiver<RawEvent>,
        callback: Callback,
    ) -> std::io::Result<Registration> {
        self.start()?;
        let shared = &self.shared;
        let id = shared.next_id.fetch_add(1, Ordering::Relaxed);
        let entry = Arc::new(Entry {
            rx,
            state: Arc::downgrade(state),
            callback: Mutex::new(Some(callback)),
            queued: AtomicBool::new(false),
            removed: AtomicBool::new(false),
        });
        lock(&shared.queue).entries.insert(id, entry);
        state.delivery.signal.listen(Listener {
            shared: Arc::downgrade(shared),
            id,
        });
        // Events queued before the registration are handed over too.
        Listener {
            shared: Arc::downgrade(shared),
            id,
        }
        .ready();
        Ok(Registration {
            shared: Arc::clone(shared),
            id,
        })
    }

    fn start(&self) -> std::io::Result<()> {
        let mut thread = lock(&self.shared.thread);
        if thread.is_some() {
            return Ok(());
        }
        let shared = Arc::clone(&self.shared);
        let handle = std::thread::Builder::new()
            .name("ndds-callbacks".into())
            .spawn(move || run(&shared))?;
        *thread = Some((handle.thread().id(), handle));
        Ok(())
    }

    /// Stops the dispatcher thread (callbacks already running finish first).
    pub(crate) fn close(&self) {
        lock(&self.shared.queue).closed = true;
        self.shared.wake.notify_all();
        let thread = lock(&self.shared.thread).take();
        if let Some((id, handle)) = thread
            && id != std::thread::current().id()
        {
            let _ = handle.join();
        }
    }
}

impl Drop for Registration {
    fn drop(&mut self) {
        let entry = lock(&self.shared.queue).entries.remove(&self.id);
        let Some(entry) = entry else {
            return;
        };
        entry.removed.store(true, Ordering::Release);
        let on_dispatcher = lock(&self.shared.thread)
            .as_ref()
            .is_some_and(|(id, _)| *id == std::thread::current().id());
        if on_dispatcher {
            // Dropped by a callback: the dispatcher lets the entry go when it returns.
            if let Ok(mut callback) = entry.callback.try_lock() {
                callback.take();
            }
            return;
        }
        // Waits for a running callback to return.
        lock(&entry.callback).take();
    }
}

thread_local! {
    /// The dispatcher this thread runs, on a dispatcher thread.
    static CURRENT: std::cell::RefCell<Option<Arc<Shared>>> =
        const { std::cell::RefCell::new(None) };
}

/// True on a participant's callback thread.
pub(crate) fn on_dispatcher_thread() -> bool {
    CURRENT.with(|current| current.borrow().is_some())
}

/// On a callback thread whose callback waits (a reliable write into a full window): runs one
/// turn of another ready callback of the participant, so the one that would take the samples
/// and open the window is not held up behind the waiting one. Returns whether it ran one.
pub(crate) fn help_dispatch() -> bool {
    let Some(shared) = CURRENT.with(|current| current.borrow().clone()) else {
        return false;
    };
    // The waiting callbacks hold their entries' locks: only the others can run.
    let found = {
        let mut queue = lock(&shared.queue);
        let mut found = None;
        for _ in 0..queue.ready.len() {
            let Some(id) = queue.ready.pop_front() else {
                break;
            };
            let Some(entry) = queue.entries.get(&id).cloned() else {
                continue;
            };
            let free = entry.callback.try_lock().is_ok();
            if free {
                found = Some((id, entry));
                break;
            }
            queue.ready.push_back(id);
        }
        found
    };
    match found {
        Some((id, entry)) => {
            turn(&shared, id, &entry);
            true
        }
        None => false,
    }
}

fn run(shared: &Arc<Shared>) {
    CURRENT.with(|current| *current.borrow_mut() = Some(Arc::clone(shared)));
    loop {
        let (id, entry) = {
            let mut queue = lock(&shared.queue);
            loop {
                if queue.closed {
                    CURRENT.with(|current| current.borrow_mut().take());
                    return;
                }
                if let Some(id) = queue.ready.pop_front() {
                    if let Some(entry) = queue.entries.get(&id) {
                        break (id, Arc::clone(entry));
                    }
                    continue;
                }
                queue = shared
                    .wake
                    .wait(queue)
                    .unwrap_or_else(|poison| poison.into_inner());
            }
        };
        turn(shared, id, &entry);
    }
}

/// Hands up to [`TURN`] events of one ready consumer to its callback.
fn turn(shared: &Shared, id: u64, entry: &Entry) {
    // Cleared before taking, so an event queued from now on marks the entry ready again.
    entry.queued.store(false, Ordering::Release);
    let mut callback = lock(&entry.callback);
    let mut handed = 0;
    while handed < TURN {
        let Some(run) = callback.as_mut() else {
            break;
        };
        if entry.removed.load(Ordering::Acquire) {
            break;
        }
        let Ok(event) = entry.rx.try_recv() else {
            break;
        };
        handed += 1;
        // Room was made: a reliable stream waiting for it moves on.
        if let Some(state) = entry.state.upgrade() {
            state.took(&event);
        }
        run(event);
    }
    drop(callback);
    if handed == TURN && !entry.rx.is_empty() && !entry.queued.swap(true, Ordering::AcqRel) {
        let mut queue = lock(&shared.queue);
        if queue.entries.contains_key(&id) {
            queue.ready.push_back(id);
            shared.wake.notify_one();
        }
    }
}

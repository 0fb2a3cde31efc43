//! Where a consumer's accepted samples and notifications go: a bounded queue (immediate
//! mode), a latest-sample cell (polled mode), or a callback on the participant's I/O thread
//! (direct). The I/O thread is the only one that pushes.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use ndds_core::arbitration::Notification;

use crate::error::RecvError;
use crate::qos::{ConsumerMode, ConsumerQos, Reliability};
use crate::sample::{PollStatus, RawEvent, RawSample};
use crate::sync::lock;

/// Notifications a polled consumer keeps until it takes them.
const POLLED_NOTIFICATIONS: usize = 64;

/// Room a queue keeps for notifications beyond its depth: a notification never pushes a
/// sample out (a reliable consumer's queued samples are acknowledged already); past this
/// room, further notifications are dropped and counted as overflow.
const NOTIFICATION_ROOM: usize = 64;

/// A callback run on the participant's I/O thread.
pub(crate) type Direct = Box<dyn FnMut(RawEvent) + Send>;

/// A [`Direct`] callback (opaque to `Debug`).
struct DirectBox(Direct);

impl std::fmt::Debug for DirectBox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("DirectBox")
    }
}

/// The latest accepted sample of a polled consumer.
#[derive(Debug, Default)]
pub(crate) struct Latest {
    sample: Option<RawSample>,
    fresh: bool,
    stale: bool,
    notifications: VecDeque<Notification>,
}

impl Latest {
    /// The latest sample and its status; marks it as seen.
    pub(crate) fn take_view(&mut self) -> (Option<RawSample>, PollStatus) {
        let status = match (&self.sample, self.fresh, self.stale) {
            (None, _, _) => PollStatus::NeverReceived,
            (Some(_), true, _) => PollStatus::Fresh,
            (Some(_), false, true) => PollStatus::NoNewData,
            (Some(_), false, false) => PollStatus::Unchanged,
        };
        self.fresh = false;
        (self.sample.clone(), status)
    }

    /// The notifications kept since the last call.
    pub(crate) fn take_notifications(&mut self) -> Vec<Notification> {
        self.notifications.drain(..).collect()
    }
}

#[derive(Debug)]
enum Kind {
    Queue {
        tx: flume::Sender<RawEvent>,
        /// A second receiver, used only to drop the oldest event when a best-effort queue is
        /// full.
        oldest: flume::Receiver<RawEvent>,
        capacity: usize,
    },
    Latest(Mutex<Latest>),
}

/// Wakes threads waiting for a consumer's queue. Waiting on flume's own blocking receive
/// would register (allocate) a waker at each wait; this waits on a condition variable, which
/// allocates nothing, and costs a sender one atomic read when nobody waits.
#[derive(Debug, Default)]
pub(crate) struct Signal {
    waiting: AtomicUsize,
    /// True once the sink is gone.
    closed: Mutex<bool>,
    wake: Condvar,
    /// The participant's callback dispatcher, for a callback consumer.
    listener: std::sync::OnceLock<super::dispatch::Listener>,
}

/// Longest single wait: a waiter looks again at least this often.
const WAIT_SLICE: Duration = Duration::from_millis(250);

impl Signal {
    fn notify(&self) {
        if self.waiting.load(Ordering::SeqCst) > 0 {
            let _closed = lock(&self.closed);
            self.wake.notify_all();
        }
        if let Some(listener) = self.listener.get() {
            listener.ready();
        }
    }

    /// Also tells `listener` of every event queued from now on.
    pub(crate) fn listen(&self, listener: super::dispatch::Listener) {
        let _ = self.listener.set(listener);
    }

    fn close(&self) {
        *lock(&self.closed) = true;
        self.wake.notify_all();
    }

    /// The next event of `rx`, waiting until `until` (forever with `None`).
    pub(crate) fn recv(
        &self,
        rx: &flume::Receiver<RawEvent>,
        until: Option<Instant>,
    ) -> Result<RawEvent, RecvError> {
        let take = || match rx.try_recv() {
            Ok(event) => Some(Ok(event)),
            Err(flume::TryRecvError::Disconnected) => Some(Err(RecvError::Closed)),
            Err(flume::TryRecvError::Empty) => None,
        };
        if let Some(result) = take() {
            return result;
        }
        let mut closed = lock(&self.closed);
        // Counted before looking again under the lock: a sender that queues after this look
        // sees the count and takes the lock to notify, which it gets only once this waits.
        self.waiting.fetch_add(1, Ordering::SeqCst);
        let result = loop {
            if let Some(result) = take() {
                break result;
            }
            if *closed {
                break Err(RecvError::Closed);
            }
            let now = Instant::now();
            let wait = match until {
                Some(at) if at <= now => break Err(RecvError::Timeout),
                Some(at) => (at - now).min(WAIT_SLICE),
                None => WAIT_SLICE,
            };
            closed = self
                .wake
                .wait_timeout(closed, wait)
                .map(|(guard, _)| guard)
                .unwrap_or_else(|poison| poison.into_inner().0);
        };
        self.waiting.fetch_sub(1, Ordering::SeqCst);
        result
    }
}

/// A consumer's delivery end.
#[derive(Debug)]
pub(crate) struct Delivery {
    kind: Kind,
    /// Samples and notifications in the queue (notifications have room of their own).
    samples: AtomicUsize,
    notifications: AtomicUsize,
    /// True for a reliable consumer with a queue: what it is handed spends credit.
    credited: bool,
    /// Samples pushed out whose credit has not been given back yet.
    evicted: AtomicUsize,
    /// Wakes the application's threads waiting for the queue.
    pub(crate) signal: Arc<Signal>,
    direct: Mutex<Option<DirectBox>>,
    has_direct: AtomicBool,
    /// Events dropped because the application did not keep up.
    pub(crate) overflow: AtomicU64,
}

impl Delivery {
    /// A delivery end for `qos`; in immediate mode, also the application's receiver.
    pub(crate) fn new(qos: &ConsumerQos) -> (Self, Option<flume::Receiver<RawEvent>>) {
        let (kind, rx) = match qos.mode {
            ConsumerMode::Immediate => {
                let capacity = qos.depth.max(1);
                let (tx, rx) = flume::bounded(capacity.saturating_add(NOTIFICATION_ROOM));
                let oldest = rx.clone();
                let kind = Kind::Queue {
                    tx,
                    oldest,
                    capacity,
                };
                (kind, Some(rx))
            }
            ConsumerMode::Polled => (Kind::Latest(Mutex::default()), None),
        };
        let sink = Delivery {
            kind,
            samples: AtomicUsize::new(0),
            notifications: AtomicUsize::new(0),
            credited: matches!(qos.reliability, Reliability::Reliable { .. })
                && qos.mode == ConsumerMode::Immediate,
            evicted: AtomicUsize::new(0),
            signal: Arc::default(),
            direct: Mutex::new(None),
            has_direct: AtomicBool::new(false),
            overflow: AtomicU64::new(0),
        };
        (sink, rx)
    }

    /// Sends every later event to `callback`, on the thread that produces it.
    pub(crate) fn set_direct(&self, callback: Direct) {
        *lock(&self.direct) = Some(DirectBox(callback));
        self.has_direct.store(true, Ordering::Release);
    }

    /// The application took `event` from the queue.
    pub(crate) fn took(&self, event: &RawEvent) {
        match event {
            RawEvent::Sample(_) => decrement(&self.samples),
            RawEvent::Notification(_) => decrement(&self.notifications),
        }
    }

    /// The latest-sample cell (polled mode only).
    pub(crate) fn latest(&self) -> Option<&Mutex<Latest>> {
        match &self.kind {
            Kind::Latest(latest) => Some(latest),
            Kind::Queue { .. } => None,
        }
    }

    /// Hands over one event; a full best-effort queue drops its oldest.
    pub(crate) fn push(&self, event: RawEvent) {
        if self.has_direct.load(Ordering::Acquire)
            && let Some(DirectBox(callback)) = lock(&self.direct).as_mut()
        {
            callback(event);
            return;
        }
        match &self.kind {
            Kind::Queue {
                tx,
                oldest,
                capacity,
            } => self.enqueue(tx, oldest, *capacity, event),
            Kind::Latest(latest) => self.replace(&mut lock(latest), event),
        }
    }

    /// Queues `event`. A sample beyond the depth pushes the oldest event out (only a
    /// best-effort consumer gets there: a reliable one is handed samples only while the
    /// application has made room for them); a notification has room of its own and never
    /// takes a sample's place: past that room it is dropped (and counted).
    fn enqueue(
        &self,
        tx: &flume::Sender<RawEvent>,
        oldest: &flume::Receiver<RawEvent>,
        capacity: usize,
        event: RawEvent,
    ) {
        match event {
            RawEvent::Notification(_) => {
                if self.notifications.load(Ordering::Acquire) >= NOTIFICATION_ROOM {
                    self.overflow.fetch_add(1, Ordering::Relaxed);
                    return;
                }
                self.notifications.fetch_add(1, Ordering::AcqRel);
                if tx.try_send(event).is_err() {
                    decrement(&self.notifications);
                    self.overflow.fetch_add(1, Ordering::Relaxed);
                    return;
                }
            }
            RawEvent::Sample(_) => {
                while self.samples.load(Ordering::Acquire) >= capacity {
                    match oldest.try_recv() {
                        Ok(dropped) => {
                            self.took(&dropped);
                            if matches!(dropped, RawEvent::Sample(_)) && self.credited {
                                // Its credit was spent when it was handed over: it comes
                                // back, or the stream would stall with an empty queue.
                                self.evicted.fetch_add(1, Ordering::AcqRel);
                            }
                            self.overflow.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(_) => break,
                    }
                }
                self.samples.fetch_add(1, Ordering::AcqRel);
                // Samples stay within the depth and notifications within their room, so the
                // channel (depth + room) has a place for this one.
                if tx.try_send(event).is_err() {
                    decrement(&self.samples);
                    return;
                }
            }
        }
        self.signal.notify()
    }

    /// Samples waiting in the queue.
    pub(crate) fn queued_samples(&self) -> usize {
        self.samples.load(Ordering::Acquire)
    }

    /// Samples pushed out of the queue since the last call whose credit must come back.
    pub(crate) fn take_evicted(&self) -> usize {
        if self.evicted.load(Ordering::Acquire) == 0 {
            return 0;
        }
        self.evicted.swap(0, Ordering::AcqRel)
    }

    fn replace(&self, latest: &mut Latest, event: RawEvent) {
        match event {
            RawEvent::Sample(sample) => {
                latest.sample = Some(sample);
                latest.fresh = true;
                latest.stale = false;
            }
            RawEvent::Notification(notification) => {
                if matches!(notification, Notification::NoNewData { .. }) {
                    latest.stale = true;
                }
                if latest.notifications.len() == POLLED_NOTIFICATIONS {
                    latest.notifications.pop_front();
                    self.overflow.fetch_add(1, Ordering::Relaxed);
                }
                latest.notifications.push_back(notification);
            }
        }
    }
}

/// Takes one from a counter that never goes below zero.
fn decrement(counter: &AtomicUsize) {
    let _ = counter.fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| n.checked_sub(1));
}

impl Drop for Delivery {
    fn drop(&mut self) {
        self.signal.close();
    }
}

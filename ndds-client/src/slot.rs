//! One consumer's receiving end inside the participant: its arbiter (NDDS semantics, from
//! ndds-core) and where accepted samples and notifications go — a bounded queue (immediate
//! mode) or a latest-sample cell (polled mode).

use std::collections::VecDeque;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use ndds_core::arbitration::{Arbiter, ArbiterStats, Incoming, Notification, Output};
use ndds_core::wire::Guid;
use ndds_core::wire::data::{Gap, Heartbeat};

use crate::plane::{Net, Origin};
use crate::qos::{ConsumerMode, ConsumerQos};
use crate::sample::{PollStatus, RawEvent, RawSample};
use crate::sync::lock;

/// Notifications a polled consumer keeps until it takes them.
const POLLED_NOTIFICATIONS: usize = 64;

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
enum Sink {
    Queue {
        tx: flume::Sender<RawEvent>,
        /// A second receiver, used only to drop the oldest event when the queue is full.
        oldest: flume::Receiver<RawEvent>,
    },
    Latest(Mutex<Latest>),
}

/// A callback run on the participant's receive or timer thread.
pub(crate) type Direct = Box<dyn FnMut(RawEvent) + Send>;

/// A [`Direct`] callback (opaque to `Debug`).
pub(crate) struct DirectBox(Direct);

impl std::fmt::Debug for DirectBox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("DirectBox")
    }
}

/// A consumer's receiving end.
#[derive(Debug)]
pub(crate) struct ConsumerSlot {
    /// The consumer's entity number.
    pub(crate) entity: u32,
    arbiter: Mutex<Arbiter<RawSample>>,
    sink: Sink,
    /// When set, events go to this callback instead of the queue.
    direct: Mutex<Option<DirectBox>>,
    has_direct: std::sync::atomic::AtomicBool,
    /// Samples that arrived for this consumer (before arbitration).
    pub(crate) arrived: AtomicU64,
    /// Events dropped because the application did not keep up.
    pub(crate) overflow: AtomicU64,
}

impl ConsumerSlot {
    /// A slot for a consumer created at `now`; in immediate mode, also the application's
    /// receiver.
    pub(crate) fn new(
        entity: u32,
        qos: ConsumerQos,
        now: Instant,
    ) -> (Self, Option<flume::Receiver<RawEvent>>) {
        let (sink, rx) = match qos.mode {
            ConsumerMode::Immediate => {
                let (tx, rx) = flume::bounded(qos.depth.max(1));
                let oldest = rx.clone();
                (Sink::Queue { tx, oldest }, Some(rx))
            }
            ConsumerMode::Polled => (Sink::Latest(Mutex::default()), None),
        };
        let slot = ConsumerSlot {
            entity,
            arbiter: Mutex::new(Arbiter::new(qos.rules(), now)),
            sink,
            direct: Mutex::new(None),
            has_direct: std::sync::atomic::AtomicBool::new(false),
            arrived: AtomicU64::new(0),
            overflow: AtomicU64::new(0),
        };
        (slot, rx)
    }

    /// Offers an arriving sample; returns the arbiter's next timer.
    pub(crate) fn offer(
        &self,
        now: Instant,
        origin: &Origin,
        meta: Incoming,
        flags: u8,
        sample: RawSample,
        net: &Net,
    ) -> Option<Instant> {
        let _ = (origin, flags, net);
        // Counted first, so a reader woken by the delivery sees the count.
        self.arrived.fetch_add(1, Ordering::Relaxed);
        let mut arbiter = lock(&self.arbiter);
        arbiter.handle_sample(now, meta, sample);
        self.drain(&mut arbiter)
    }

    /// A reliable writer's heartbeat.
    pub(crate) fn on_heartbeat(
        &self,
        now: Instant,
        origin: &Origin,
        heartbeat: Heartbeat,
        net: &Net,
    ) -> Option<Instant> {
        let _ = (now, origin, heartbeat, net);
        None
    }

    /// A reliable writer's gap.
    pub(crate) fn on_gap(
        &self,
        now: Instant,
        origin: &Origin,
        gap: Gap,
        net: &Net,
    ) -> Option<Instant> {
        let _ = (now, origin, gap, net);
        None
    }

    /// Runs the arbiter's due timers; returns its next timer.
    pub(crate) fn timeout(&self, now: Instant) -> Option<Instant> {
        let mut arbiter = lock(&self.arbiter);
        if arbiter.poll_timeout().is_some_and(|due| due <= now) {
            arbiter.handle_timeout(now);
        }
        self.drain(&mut arbiter)
    }

    /// A matched producer went away.
    pub(crate) fn writer_lost(&self, writer: Guid) {
        let mut arbiter = lock(&self.arbiter);
        arbiter.handle_writer_lost(writer);
        self.drain(&mut arbiter);
    }

    /// Hands the application a notification that does not come from arbitration.
    pub(crate) fn notify(&self, notification: Notification) {
        self.push(RawEvent::Notification(notification));
    }

    /// The arbiter's counters.
    pub(crate) fn arbiter_stats(&self) -> ArbiterStats {
        lock(&self.arbiter).stats()
    }

    /// The latest-sample cell (polled mode only).
    pub(crate) fn latest(&self) -> Option<&Mutex<Latest>> {
        match &self.sink {
            Sink::Latest(latest) => Some(latest),
            Sink::Queue { .. } => None,
        }
    }

    fn drain(&self, arbiter: &mut Arbiter<RawSample>) -> Option<Instant> {
        while let Some(output) = arbiter.poll_output() {
            match output {
                Output::Deliver { mut sample, status } => {
                    sample.info.status = status;
                    self.push(RawEvent::Sample(sample));
                }
                Output::Notify(notification) => self.push(RawEvent::Notification(notification)),
            }
        }
        arbiter.poll_timeout()
    }

    /// Sends every later event to `callback`, on the thread that produces it.
    pub(crate) fn set_direct(&self, callback: Direct) {
        *lock(&self.direct) = Some(DirectBox(callback));
        self.has_direct.store(true, Ordering::Release);
    }

    fn push(&self, event: RawEvent) {
        if self.has_direct.load(Ordering::Acquire)
            && let Some(DirectBox(callback)) = lock(&self.direct).as_mut()
        {
            callback(event);
            return;
        }
        match &self.sink {
            Sink::Queue { tx, oldest } => {
                let mut event = event;
                loop {
                    match tx.try_send(event) {
                        Ok(()) => return,
                        Err(flume::TrySendError::Full(back)) => {
                            event = back;
                            if oldest.try_recv().is_ok() {
                                self.overflow.fetch_add(1, Ordering::Relaxed);
                            }
                        }
                        Err(flume::TrySendError::Disconnected(_)) => return,
                    }
                }
            }
            Sink::Latest(latest) => {
                let mut latest = lock(latest);
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
    }
}

//! How port primitives wait: every primitive is a future that sleeps on what it waits for
//! (a consumer's queue, a [`Notify`], a deadline) and is woken by it — never a sleep loop.
//!
//! | piece | what it is |
//! |---|---|
//! | [`block_on`] | the blocking forms: polls one future on the calling thread and parks it in between, until a waker or the nearest [`sleep_until`] deadline unparks it |
//! | [`sleep_until`] | a deadline: inside [`block_on`] it only shortens the park; on another executor, one process-wide timer thread (`ndds-port-timer`) wakes it |
//! | [`Notify`] | a generation counter with wakers: a waiter remembers the generation it saw and wakes when it moved |
//! | [`next`], [`race`], [`timeout_at`] | the few combinators the primitives need |
//!
//! The async forms (`send_async`, ...) are the same futures awaited on the caller's executor,
//! so no call starts a thread.

use std::cell::Cell;
use std::collections::HashMap;
use std::future::Future;
use std::pin::{Pin, pin};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, OnceLock};
use std::task::{Context, Poll, Wake, Waker};
use std::time::{Duration, Instant};

use futures_core::Stream;

use crate::{Producer, Sample};

thread_local! {
    /// Inside [`block_on`]: the earliest deadline a pending [`sleep_until`] asked for in the
    /// current poll (`Some(None)`: none). `None` outside [`block_on`].
    static PARK_UNTIL: Cell<Option<Option<Instant>>> = const { Cell::new(None) };
}

thread_local! {
    /// Inside [`block_on`]: until when a pending future asked to be polled again without
    /// parking ([`spin_until`]).
    static SPIN_UNTIL: Cell<Option<Instant>> = const { Cell::new(None) };
}

/// Asks the [`block_on`] that polls the current future to busy-wait — poll again without
/// parking — until `at`, for a tightly-coupled port (see
/// [`ProcessClass`](super::ProcessClass)). Outside [`block_on`] (an async form) it does
/// nothing.
pub(crate) fn spin_until(at: Instant) {
    if blocking() {
        SPIN_UNTIL.with(|s| s.set(Some(s.get().map_or(at, |old| old.max(at)))));
    }
}

struct Unpark(std::thread::Thread);

impl Wake for Unpark {
    fn wake(self: Arc<Self>) {
        self.0.unpark();
    }

    fn wake_by_ref(self: &Arc<Self>) {
        self.0.unpark();
    }
}

/// Runs `future` to completion on this thread, parked whenever it is pending.
pub(crate) fn block_on<F: Future>(future: F) -> F::Output {
    let mut future = pin!(future);
    let waker = Waker::from(Arc::new(Unpark(std::thread::current())));
    let mut cx = Context::from_waker(&waker);
    let outer = PARK_UNTIL.with(Cell::get);
    let outer_spin = SPIN_UNTIL.with(|s| s.replace(None));
    let result = loop {
        PARK_UNTIL.with(|p| p.set(Some(None)));
        if let Poll::Ready(output) = future.as_mut().poll(&mut cx) {
            break output;
        }
        if SPIN_UNTIL
            .with(Cell::get)
            .is_some_and(|at| Instant::now() < at)
        {
            std::hint::spin_loop();
            continue;
        }
        match PARK_UNTIL.with(Cell::get).flatten() {
            Some(at) => std::thread::park_timeout(at.saturating_duration_since(Instant::now())),
            None => std::thread::park(),
        }
    };
    PARK_UNTIL.with(|p| p.set(outer));
    SPIN_UNTIL.with(|s| s.set(outer_spin));
    result
}

thread_local! {
    /// Set by [`parked_only`]: waits must park in [`block_on`], never block on a condition
    /// variable of their own (a module's thread must stay wakeable by its handlers' events).
    static PARKED_ONLY: Cell<bool> = const { Cell::new(false) };
}

/// Whether the current poll runs inside [`block_on`] (so it may block on a condition
/// variable of its own).
pub(crate) fn blocking() -> bool {
    PARK_UNTIL.with(Cell::get).is_some() && !PARKED_ONLY.with(Cell::get)
}

/// Runs `f` with every wait inside it parking in [`block_on`] (woken by any waker), so that
/// a race with another future (a module's events) stays a race.
pub(crate) fn parked_only<T>(f: impl FnOnce() -> T) -> T {
    let outer = PARKED_ONLY.with(|p| p.replace(true));
    let out = f();
    PARKED_ONLY.with(|p| p.set(outer));
    out
}

/// The deadline `timeout` from `start`; `None` when it is too far to represent.
pub(crate) fn deadline(start: Instant, timeout: Duration) -> Option<Instant> {
    start.checked_add(timeout)
}

/// A future ready at `at` (never, with `None`).
pub(crate) fn sleep_until(at: Option<Instant>) -> Sleep {
    Sleep { at, id: None }
}

/// See [`sleep_until`].
pub(crate) struct Sleep {
    at: Option<Instant>,
    /// Registered with the timer thread under this id.
    id: Option<u64>,
}

impl Future for Sleep {
    type Output = ();

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        let Some(at) = self.at else {
            return Poll::Pending;
        };
        if Instant::now() >= at {
            return Poll::Ready(());
        }
        let inside = PARK_UNTIL.with(|p| match p.get() {
            Some(earliest) => {
                p.set(Some(Some(earliest.map_or(at, |e| e.min(at)))));
                true
            }
            None => false,
        });
        if !inside {
            let id = *self
                .id
                .get_or_insert_with(|| NEXT_SLEEP.fetch_add(1, Ordering::Relaxed));
            timer().register(id, at, cx.waker());
        }
        Poll::Pending
    }
}

impl Drop for Sleep {
    fn drop(&mut self) {
        if let Some(id) = self.id {
            timer().cancel(id);
        }
    }
}

static NEXT_SLEEP: AtomicU64 = AtomicU64::new(1);

/// The deadlines of sleeps awaited outside [`block_on`], and the one thread that wakes them.
struct Timer {
    sleeps: Mutex<HashMap<u64, (Instant, Waker)>>,
    changed: Condvar,
}

fn timer() -> &'static Timer {
    static TIMER: OnceLock<&'static Timer> = OnceLock::new();
    TIMER.get_or_init(|| {
        let timer: &'static Timer = Box::leak(Box::new(Timer {
            sleeps: Mutex::new(HashMap::new()),
            changed: Condvar::new(),
        }));
        let spawned = std::thread::Builder::new()
            .name("ndds-port-timer".to_owned())
            .spawn(move || timer.run());
        if let Err(err) = spawned {
            tracing::error!(error = %err, "port timer thread not started: async port timeouts will not fire");
        }
        timer
    })
}

impl Timer {
    fn register(&self, id: u64, at: Instant, waker: &Waker) {
        let mut sleeps = self.sleeps.lock().unwrap_or_else(|p| p.into_inner());
        let earliest = sleeps.values().all(|(other, _)| at < *other);
        sleeps.insert(id, (at, waker.clone()));
        if earliest {
            self.changed.notify_one();
        }
    }

    fn cancel(&self, id: u64) {
        self.sleeps
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&id);
    }

    fn run(&self) {
        let mut sleeps = self.sleeps.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            let now = Instant::now();
            let due: Vec<u64> = sleeps
                .iter()
                .filter(|(_, (at, _))| *at <= now)
                .map(|(id, _)| *id)
                .collect();
            for id in due {
                if let Some((_, waker)) = sleeps.remove(&id) {
                    waker.wake();
                }
            }
            let next = sleeps.values().map(|(at, _)| *at).min();
            sleeps = match next {
                Some(at) => {
                    self.changed
                        .wait_timeout(sleeps, at.saturating_duration_since(now))
                        .unwrap_or_else(|p| p.into_inner())
                        .0
                }
                None => self.changed.wait(sleeps).unwrap_or_else(|p| p.into_inner()),
            };
        }
    }
}

/// Something changed: whoever waits for a change since the generation it saw wakes.
#[derive(Default)]
pub(crate) struct Notify {
    generation: AtomicU64,
    /// Wakers of the pending [`Changed`] futures, by registration; a future takes its own out
    /// when it is dropped, so a waiter that gave up leaves nothing behind.
    wakers: Mutex<(u64, Vec<(u64, Waker)>)>,
}

impl Notify {
    /// The generation now: pass it to [`changed`](Self::changed) before looking at the state.
    pub(crate) fn generation(&self) -> u64 {
        self.generation.load(Ordering::SeqCst)
    }

    /// Wakes every waiter.
    pub(crate) fn notify(&self) {
        self.generation.fetch_add(1, Ordering::SeqCst);
        let wakers = std::mem::take(&mut self.wakers.lock().unwrap_or_else(|p| p.into_inner()).1);
        for (_, waker) in wakers {
            waker.wake();
        }
    }

    /// Ready once the generation is no longer `seen`.
    pub(crate) fn changed(&self, seen: u64) -> Changed<'_> {
        Changed {
            notify: self,
            seen,
            registered: None,
        }
    }

    /// Waiters registered now (for tests).
    #[cfg(test)]
    fn waiters(&self) -> usize {
        self.wakers
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .1
            .len()
    }
}

/// [`Notify::changed`]'s future.
pub(crate) struct Changed<'a> {
    notify: &'a Notify,
    seen: u64,
    registered: Option<u64>,
}

impl Future for Changed<'_> {
    type Output = ();

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        let notify = self.notify;
        if notify.generation() != self.seen {
            return Poll::Ready(());
        }
        {
            let mut wakers = notify.wakers.lock().unwrap_or_else(|p| p.into_inner());
            let (next, list) = &mut *wakers;
            match self
                .registered
                .and_then(|id| list.iter_mut().find(|(i, _)| *i == id))
            {
                Some((_, waker)) => {
                    if !waker.will_wake(cx.waker()) {
                        *waker = cx.waker().clone();
                    }
                }
                None => {
                    *next += 1;
                    let id = *next;
                    list.push((id, cx.waker().clone()));
                    drop(wakers);
                    self.registered = Some(id);
                }
            }
        }
        // A notify between the first look and the registration is seen here.
        if notify.generation() != self.seen {
            Poll::Ready(())
        } else {
            Poll::Pending
        }
    }
}

impl Drop for Changed<'_> {
    fn drop(&mut self) {
        if let Some(id) = self.registered {
            let mut wakers = self.notify.wakers.lock().unwrap_or_else(|p| p.into_inner());
            wakers.1.retain(|(i, _)| *i != id);
        }
    }
}

/// The next item of `stream`.
pub(crate) fn next<S: Stream + Unpin>(stream: &mut S) -> impl Future<Output = Option<S::Item>> {
    std::future::poll_fn(move |cx| Pin::new(&mut *stream).poll_next(cx))
}

/// Which of two futures finished first.
pub(crate) enum Either<A, B> {
    Left(A),
    Right(B),
}

/// The first of `a` and `b` to finish (`a` when both are ready); the other is dropped.
pub(crate) async fn race<A: Future, B: Future>(a: A, b: B) -> Either<A::Output, B::Output> {
    let (mut a, mut b) = (pin!(a), pin!(b));
    std::future::poll_fn(move |cx| {
        if let Poll::Ready(out) = a.as_mut().poll(cx) {
            return Poll::Ready(Either::Left(out));
        }
        b.as_mut().poll(cx).map(Either::Right)
    })
    .await
}

/// `future`'s output, or `None` once `at` passes first (never, with `None`).
pub(crate) async fn timeout_at<F: Future>(at: Option<Instant>, future: F) -> Option<F::Output> {
    match race(future, sleep_until(at)).await {
        Either::Left(out) => Some(out),
        Either::Right(()) => None,
    }
}

/// The next sample of `consumer` (notifications skipped); `None` once it closed (or is not
/// an immediate consumer, which ports never declare).
pub(crate) async fn next_sample<T: serde::de::DeserializeOwned>(
    consumer: &crate::Consumer<T>,
) -> Option<Sample<T>> {
    let mut samples = consumer.stream().ok()?;
    next(&mut samples).await
}

/// Whether `producer` has a matched consumer by `at`. Inside [`block_on`] it waits on the
/// producer's match condition; on another executor it sleeps until the match (or `at`).
pub(crate) async fn matched_by(producer: &Producer<impl Sized>, at: Option<Instant>) -> bool {
    if producer.wait_for_consumers(1, Duration::ZERO) {
        return true;
    }
    if blocking() {
        let left = at.map_or(Duration::from_secs(86_400 * 365), |at| {
            at.saturating_duration_since(Instant::now())
        });
        return producer.wait_for_consumers(1, left);
    }
    timeout_at(at, producer.consumers_matched(1))
        .await
        .is_some()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_on_wakes_on_notify_and_at_the_deadline() {
        let notify = Arc::new(Notify::default());
        let seen = notify.generation();
        let other = Arc::clone(&notify);
        let t = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(30));
            other.notify();
        });
        let start = Instant::now();
        let woke = block_on(timeout_at(
            Some(start + Duration::from_secs(10)),
            notify.changed(seen),
        ));
        assert!(woke.is_some());
        assert!(start.elapsed() < Duration::from_secs(5));
        t.join().unwrap();
        let start = Instant::now();
        let seen = notify.generation();
        let timed_out = block_on(timeout_at(
            Some(start + Duration::from_millis(50)),
            notify.changed(seen),
        ));
        assert!(timed_out.is_none());
        assert!(start.elapsed() >= Duration::from_millis(50));
    }

    #[test]
    fn a_sleep_outside_block_on_is_woken_by_the_timer_thread() {
        let (tx, rx) = flume::bounded(1);
        let start = Instant::now();
        std::thread::spawn(move || {
            // A hand-made executor that is not block_on: it only waits for the waker.
            let waker = Waker::from(Arc::new(Unpark(std::thread::current())));
            let mut cx = Context::from_waker(&waker);
            let mut sleep = pin!(sleep_until(Some(
                Instant::now() + Duration::from_millis(40)
            )));
            while sleep.as_mut().poll(&mut cx).is_pending() {
                std::thread::park();
            }
            let _ = tx.send(());
        });
        rx.recv_timeout(Duration::from_secs(10)).unwrap();
        assert!(start.elapsed() >= Duration::from_millis(40));
    }

    #[test]
    fn a_spinning_block_on_polls_without_parking_until_the_spin_ends_then_parks() {
        let notify = Arc::new(Notify::default());
        let seen = notify.generation();
        let other = Arc::clone(&notify);
        let t = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(150));
            other.notify();
        });
        let start = Instant::now();
        let spin_end = start + Duration::from_millis(30);
        let polls = Cell::new(0_u64);
        let late_polls = Cell::new(0_u64);
        let mut changed = pin!(notify.changed(seen));
        block_on(std::future::poll_fn(|cx| {
            if polls.get() == 0 {
                spin_until(spin_end);
            }
            polls.set(polls.get() + 1);
            if Instant::now() >= spin_end {
                late_polls.set(late_polls.get() + 1);
            }
            changed.as_mut().poll(cx)
        }));
        t.join().unwrap();
        assert!(start.elapsed() >= Duration::from_millis(150));
        // Polled over and over while spinning, then parked until the notification woke it:
        // a poll or two after the spin (the last spinning one, the wake-up; a spurious
        // unpark may add one).
        assert!(polls.get() > 100, "{} polls while spinning", polls.get());
        assert!(
            late_polls.get() <= 3,
            "{} polls after the spin",
            late_polls.get()
        );
        // Outside block_on, asking to spin does nothing.
        spin_until(Instant::now() + Duration::from_secs(60));
        assert_eq!(SPIN_UNTIL.with(Cell::get), None);
    }

    #[test]
    fn a_waiter_that_gives_up_leaves_no_waker_behind() {
        let notify = Notify::default();
        for _ in 0..100 {
            let seen = notify.generation();
            let woke = block_on(timeout_at(
                Some(Instant::now() + Duration::from_millis(1)),
                notify.changed(seen),
            ));
            assert!(woke.is_none());
        }
        assert_eq!(notify.waiters(), 0);
        // A pending waiter is there until it is woken or dropped.
        let seen = notify.generation();
        let mut waiting = Box::pin(notify.changed(seen));
        let waker = Waker::from(Arc::new(Unpark(std::thread::current())));
        assert!(
            waiting
                .as_mut()
                .poll(&mut Context::from_waker(&waker))
                .is_pending()
        );
        assert!(
            waiting
                .as_mut()
                .poll(&mut Context::from_waker(&waker))
                .is_pending()
        );
        assert_eq!(notify.waiters(), 1);
        drop(waiting);
        assert_eq!(notify.waiters(), 0);
    }
}

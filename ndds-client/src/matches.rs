//! What a local producer and a local consumer have in common: their topic and type, and the
//! endpoints they are matched with (or incompatible with), kept current by the daemon's match
//! events.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Condvar, Mutex};
use std::task::{Context, Poll, Waker};
use std::time::{Duration, Instant};

use ndds_core::types::{TypeDescription, fingerprint_hex};
use ndds_core::wire::{EndpointInfo, Guid};

use crate::sync::{deadline, lock};

/// The matched endpoints, as [`Peers::publish`] hands them to its `apply` step.
pub(crate) type Matched<'a> = std::collections::btree_map::Values<'a, Guid, EndpointInfo>;

#[derive(Debug, Default)]
struct Maps {
    matched: BTreeMap<Guid, EndpointInfo>,
    incompatible: BTreeMap<Guid, EndpointInfo>,
    /// Matches not yet confirmed by a replacement daemon.
    stale: BTreeSet<Guid>,
    /// Changes recorded and not yet published: invisible to everyone until
    /// [`Peers::publish`] applies them, in order, with the data plane's update.
    pending: Vec<Change>,
}

/// One recorded change of the matches.
#[derive(Debug)]
enum Change {
    Matched(EndpointInfo),
    Incompatible(EndpointInfo),
    Unmatched(Guid),
}

/// Topic, type, and matched and incompatible peers of one local endpoint.
#[derive(Debug)]
pub(crate) struct Peers {
    pub(crate) topic: String,
    pub(crate) type_desc: TypeDescription,
    pub(crate) fingerprint: u64,
    maps: Mutex<Maps>,
    changed: Condvar,
    /// Async waiters for a change (see [`Peers::poll_matched`]), woken after the maps' lock
    /// is released.
    wakers: Mutex<Vec<Waker>>,
}

impl Peers {
    pub(crate) fn new(topic: &str, type_desc: TypeDescription) -> Self {
        Peers {
            topic: topic.to_owned(),
            fingerprint: type_desc.fingerprint(),
            type_desc,
            maps: Mutex::default(),
            changed: Condvar::new(),
            wakers: Mutex::default(),
        }
    }

    /// Records a match. Nobody sees it until [`Peers::publish`] applies it (so a burst of
    /// matches is applied once, not once per match).
    pub(crate) fn record_matched(&self, remote: EndpointInfo) {
        lock(&self.maps).pending.push(Change::Matched(remote));
    }

    /// Records that a peer went away, as [`Peers::record_matched`] records a match.
    pub(crate) fn record_unmatched(&self, remote: Guid) {
        lock(&self.maps).pending.push(Change::Unmatched(remote));
    }

    /// Applies the recorded changes in order; `apply` sees the matched endpoints after them
    /// and runs before anyone waiting for matches is woken, so a woken writer finds its
    /// destinations set. Returns the peers that were matched and went away.
    ///
    /// A burst is applied once, except where a peer matched in it also goes away in it (a
    /// producer that wrote one sample and exited): the set with that peer is applied first,
    /// then the rest, so what the peer sent while it was matched is believed (a consumer
    /// holds samples of producers it has not heard matched yet, and releases them at the
    /// match); it is then lost as any other peer.
    pub(crate) fn publish(&self, mut apply: impl FnMut(Matched<'_>)) -> Vec<Guid> {
        let mut maps = lock(&self.maps);
        // Every peer the data plane has been told is matched: those that are not at the end
        // are lost (a peer unmatched and matched again within one burst is not lost; one that
        // became incompatible is).
        let mut told: BTreeSet<Guid> = maps.matched.keys().copied().collect();
        // Matched in this burst and not applied yet.
        let mut fresh: BTreeSet<Guid> = BTreeSet::new();
        for change in std::mem::take(&mut maps.pending) {
            let leaving = match &change {
                Change::Matched(_) => None,
                Change::Incompatible(remote) => Some(remote.guid),
                Change::Unmatched(remote) => Some(*remote),
            };
            if let Some(guid) = leaving
                && fresh.contains(&guid)
                && maps.matched.contains_key(&guid)
            {
                self.apply(&maps, &mut apply);
                told.extend(maps.matched.keys().copied());
                fresh.clear();
            }
            match change {
                Change::Matched(remote) => {
                    maps.incompatible.remove(&remote.guid);
                    maps.stale.remove(&remote.guid);
                    fresh.insert(remote.guid);
                    maps.matched.insert(remote.guid, remote);
                }
                Change::Incompatible(remote) => {
                    maps.matched.remove(&remote.guid);
                    maps.incompatible.insert(remote.guid, remote);
                }
                Change::Unmatched(remote) => {
                    maps.incompatible.remove(&remote);
                    maps.matched.remove(&remote);
                }
            }
        }
        let lost: Vec<Guid> = told
            .into_iter()
            .filter(|guid| !maps.matched.contains_key(guid))
            .collect();
        self.apply(&maps, apply);
        drop(maps);
        self.wake_async();
        lost
    }

    /// Wakes the async waiters (the maps' lock released).
    fn wake_async(&self) {
        let wakers = std::mem::take(&mut *lock(&self.wakers));
        for waker in wakers {
            waker.wake();
        }
    }

    /// Ready once at least `count` endpoints are matched; otherwise `cx` is woken at the next
    /// change of the matches.
    pub(crate) fn poll_matched(&self, count: usize, cx: &mut Context<'_>) -> Poll<()> {
        let maps = lock(&self.maps);
        if maps.matched.len() >= count {
            return Poll::Ready(());
        }
        // Registered while the maps are held: a change made after this look wakes it.
        let mut wakers = lock(&self.wakers);
        if !wakers.iter().any(|w| w.will_wake(cx.waker())) {
            wakers.push(cx.waker().clone());
        }
        Poll::Pending
    }

    fn apply(&self, maps: &Maps, mut apply: impl FnMut(Matched<'_>)) {
        apply(maps.matched.values());
        self.changed.notify_all();
    }

    /// Records an incompatible peer and logs it.
    pub(crate) fn incompatible(&self, remote: EndpointInfo) {
        let reason = if remote.fingerprint == self.fingerprint {
            "reliability: a reliable consumer needs a reliable producer"
        } else {
            "type"
        };
        tracing::warn!(
            topic = self.topic,
            reason,
            local_type = self.type_desc.shape(),
            local_fingerprint = fingerprint_hex(self.fingerprint),
            remote_type = remote.type_desc.shape(),
            remote_fingerprint = fingerprint_hex(remote.fingerprint),
            remote_pid = remote.pid,
            remote_process = remote.process,
            "incompatible endpoint on topic: samples will not flow between these endpoints"
        );
        lock(&self.maps).pending.push(Change::Incompatible(remote));
    }

    /// Marks every match as unconfirmed; [`Peers::sweep_stale`] later drops those the new
    /// daemon did not report again. Until then, samples keep flowing to them.
    pub(crate) fn mark_stale(&self) {
        let mut maps = lock(&self.maps);
        let guids: Vec<Guid> = maps.matched.keys().copied().collect();
        maps.stale.extend(guids);
        maps.incompatible.clear();
    }

    /// Drops the matches still unconfirmed; returns them. `apply` as in [`Peers::matched`].
    pub(crate) fn sweep_stale(&self, apply: impl FnMut(Matched<'_>)) -> Vec<Guid> {
        let mut maps = lock(&self.maps);
        let stale = std::mem::take(&mut maps.stale);
        for guid in &stale {
            maps.matched.remove(guid);
        }
        if !stale.is_empty() {
            self.apply(&maps, apply);
        }
        drop(maps);
        self.wake_async();
        stale.into_iter().collect()
    }

    /// The matched endpoints.
    pub(crate) fn matched_list(&self) -> Vec<EndpointInfo> {
        lock(&self.maps).matched.values().cloned().collect()
    }

    /// The incompatible endpoints.
    pub(crate) fn incompatible_list(&self) -> Vec<EndpointInfo> {
        lock(&self.maps).incompatible.values().cloned().collect()
    }

    /// Waits until at least `count` endpoints are matched; false at the timeout.
    pub(crate) fn wait_matched(&self, count: usize, timeout: Duration) -> bool {
        let deadline = deadline(timeout);
        let mut maps = lock(&self.maps);
        while maps.matched.len() < count {
            let left = deadline.map_or(Duration::MAX, |d| {
                d.saturating_duration_since(Instant::now())
            });
            if left.is_zero() {
                return false;
            }
            // Wake at least hourly so an unbounded wait never hands the OS an absurd timeout.
            maps = self
                .changed
                .wait_timeout(maps, left.min(Duration::from_secs(3600)))
                .map(|(guard, _)| guard)
                .unwrap_or_else(|poison| poison.into_inner().0);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::task::{Wake, Waker};

    use ndds_core::wire::{ConsumerQosWire, EndpointQos, Locator};

    use super::*;

    struct Counting(AtomicUsize);

    impl Wake for Counting {
        fn wake(self: Arc<Self>) {
            self.0.fetch_add(1, Ordering::SeqCst);
        }
    }

    fn consumer(entity: u32, type_desc: &TypeDescription) -> EndpointInfo {
        EndpointInfo {
            guid: Guid {
                participant: 9,
                entity,
            },
            topic: "t".into(),
            type_desc: type_desc.clone(),
            fingerprint: type_desc.fingerprint(),
            qos: EndpointQos::Consumer(ConsumerQosWire::default()),
            locator: Locator::UNSPECIFIED,
            pid: 1,
            process: "p".into(),
        }
    }

    #[test]
    fn an_async_waiter_for_matches_is_woken_by_the_match_not_by_a_timer() {
        let type_desc = TypeDescription::of::<u32>();
        let peers = Peers::new("t", type_desc.clone());
        let counter = Arc::new(Counting(AtomicUsize::new(0)));
        let waker = Waker::from(Arc::clone(&counter));
        let mut cx = Context::from_waker(&waker);
        assert!(peers.poll_matched(1, &mut cx).is_pending());
        assert!(peers.poll_matched(1, &mut cx).is_pending());
        assert_eq!(
            counter.0.load(Ordering::SeqCst),
            0,
            "nothing wakes it meanwhile"
        );
        peers.record_matched(consumer(1, &type_desc));
        assert!(
            peers.poll_matched(1, &mut cx).is_pending(),
            "not seen before published"
        );
        assert_eq!(
            counter.0.load(Ordering::SeqCst),
            0,
            "not before the match is applied"
        );
        peers.publish(|_| {});
        assert_eq!(
            counter.0.load(Ordering::SeqCst),
            1,
            "woken once by the match"
        );
        assert!(peers.poll_matched(1, &mut cx).is_ready());
        // Waiting for two: woken by the next change too (here, the one match going away).
        assert!(peers.poll_matched(2, &mut cx).is_pending());
        peers.record_unmatched(consumer(1, &type_desc).guid);
        assert_eq!(peers.publish(|_| {}), [consumer(1, &type_desc).guid]);
        assert_eq!(counter.0.load(Ordering::SeqCst), 2);
        assert!(peers.poll_matched(2, &mut cx).is_pending());
    }

    #[test]
    fn a_peer_unmatched_and_matched_again_in_one_burst_is_not_lost() {
        let type_desc = TypeDescription::of::<u32>();
        let peers = Peers::new("t", type_desc.clone());
        let (one, two) = (consumer(1, &type_desc), consumer(2, &type_desc));
        peers.record_matched(one.clone());
        peers.record_matched(two.clone());
        assert!(peers.publish(|_| {}).is_empty());
        // One flaps within a burst; two becomes incompatible.
        peers.record_unmatched(one.guid);
        peers.record_matched(one.clone());
        peers.incompatible(two.clone());
        let mut seen = Vec::new();
        let lost = peers.publish(|all| seen.extend(all.map(|info| info.guid)));
        assert_eq!(lost, [two.guid]);
        assert_eq!(seen, [one.guid]);
    }

    #[test]
    fn a_peer_matched_and_gone_in_one_burst_is_applied_matched_first_then_lost() {
        // A producer that wrote one sample and exited: its match and its leaving arrive
        // together. The data plane must see the match (to release what it sent), then not.
        let type_desc = TypeDescription::of::<u32>();
        let peers = Peers::new("t", type_desc.clone());
        let (one, two, three) = (
            consumer(1, &type_desc),
            consumer(2, &type_desc),
            consumer(3, &type_desc),
        );
        peers.record_matched(one.clone());
        assert!(peers.publish(|_| {}).is_empty());
        peers.record_matched(two.clone());
        peers.record_matched(three.clone());
        peers.record_unmatched(two.guid);
        let mut applied: Vec<Vec<u32>> = Vec::new();
        let lost = peers.publish(|all| applied.push(all.map(|info| info.guid.entity).collect()));
        assert_eq!(applied, [vec![1, 2, 3], vec![1, 3]]);
        assert_eq!(lost, [two.guid]);
        // A burst of matches alone is still applied once.
        let many: Vec<EndpointInfo> = (10..20).map(|e| consumer(e, &type_desc)).collect();
        for info in &many {
            peers.record_matched(info.clone());
        }
        let mut calls = 0;
        assert!(peers.publish(|_| calls += 1).is_empty());
        assert_eq!(calls, 1);
    }
}

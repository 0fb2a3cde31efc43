//! The untyped consumer: its shared state, waiting for events, polling, counters.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use ndds_core::arbitration::Notification;
use ndds_core::types::TypeDescription;
use ndds_core::wire::{EndpointInfo, EndpointQos};

use super::Delivery;
use crate::data_plane::DataPlane;
use crate::error::{Mismatch, RecvError, Unmatched, UnmatchedProducer};
use crate::matches::Peers;
use crate::participant::EndpointHandle;
use crate::qos::ConsumerMode;
use crate::sample::{PollStatus, RawEvent, RawSample};
use crate::sync::{deadline, lock};

/// State of one consumer shared with the participant's event router.
#[derive(Debug)]
pub(crate) struct ConsumerState {
    pub(crate) peers: Peers,
    /// Its entity number in the participant's data plane.
    pub(crate) entity: u32,
    /// `Some` when what the application takes is credited back to the data plane (a reliable
    /// consumer with a queue: its streams deliver only while the queue has room): how many
    /// taken samples are given back at once.
    credit_batch: Option<usize>,
    /// Taken samples not yet given back.
    pending_credit: AtomicUsize,
    pub(crate) delivery: Arc<Delivery>,
    pub(crate) plane: Arc<DataPlane>,
    pub(crate) decoder: Arc<Decoder>,
}

/// What decoding needs; shared with callback threads, which must not keep the queue alive.
#[derive(Debug)]
pub(crate) struct Decoder {
    pub(crate) topic: String,
    pub(crate) errors: AtomicU64,
}

impl ConsumerState {
    pub(crate) fn new(
        topic: &str,
        type_desc: TypeDescription,
        entity: u32,
        credit: Option<usize>,
        delivery: Arc<Delivery>,
        plane: Arc<DataPlane>,
    ) -> Self {
        ConsumerState {
            peers: Peers::new(topic, type_desc),
            entity,
            // A quarter of the depth at once (one lock of the data plane per quarter, not per
            // sample); all of it as soon as the queue is empty, so a stream never waits for
            // credit the application already made.
            credit_batch: credit.map(|depth| (depth / 4).max(1)),
            pending_credit: AtomicUsize::new(0),
            delivery,
            plane,
            decoder: Arc::new(Decoder {
                topic: topic.to_owned(),
                errors: AtomicU64::new(0),
            }),
        }
    }

    /// Sends every later event to `callback` on the participant's I/O thread.
    pub(crate) fn set_direct(&self, callback: super::Direct) {
        self.delivery.set_direct(callback);
        self.plane.set_unlimited(self.entity);
    }

    /// The application took `event` from the queue: a reliable stream waiting for room
    /// moves on.
    pub(crate) fn took(&self, event: &RawEvent) {
        self.delivery.took(event);
        let Some(batch) = self.credit_batch else {
            return;
        };
        if !matches!(event, RawEvent::Sample(_)) {
            return;
        }
        let pending = self.pending_credit.fetch_add(1, Ordering::AcqRel) + 1;
        if pending >= batch || self.delivery.queued_samples() == 0 {
            let samples = self.pending_credit.swap(0, Ordering::AcqRel);
            if samples > 0 {
                self.plane.taken(self.entity, samples);
            }
        }
    }
}

/// Counters of one consumer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ConsumerStats {
    /// Samples that arrived for this consumer (before arbitration).
    pub received: u64,
    /// Samples accepted by arbitration.
    pub accepted: u64,
    /// Samples handed over (queued or made the latest).
    pub delivered: u64,
    /// Samples refused because a stronger producer is in charge.
    pub weaker: u64,
    /// Samples refused as old data (not newer than the last one of their producer).
    pub old_data: u64,
    /// Accepted samples replaced by a newer one within a minimum-separation window.
    pub superseded: u64,
    /// Deadline notifications ("no new data", "never received").
    pub deadline_misses: u64,
    /// Events dropped because the application did not keep up.
    pub overflow: u64,
    /// Samples that did not decode as the consumer's type.
    pub decode_errors: u64,
    /// Samples, heartbeats and gaps dropped because discovery never matched their producer
    /// with this consumer (forged, or from a producer gone long ago).
    pub unmatched: u64,
    /// Dropped because they carried a matched producer's id but came from another address.
    pub wrong_address: u64,
    /// Reliable streams (one per reliable producer heard from since it was matched).
    pub reliable_streams: usize,
    /// Their readers' counters, summed (ordering, repairs requested, seqs lost).
    pub reliable: ndds_core::reliability::ReaderStats,
}

/// How long [`RawConsumer::next_event`] may wait.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Wait {
    Block,
    Try,
    Until(Instant),
}

impl Wait {
    pub(crate) fn at_most(timeout: Duration) -> Self {
        deadline(timeout).map_or(Wait::Block, Wait::Until)
    }
}

/// A consumer of already-encoded samples, as tools use it. Closing (dropping) it withdraws it.
#[derive(Debug)]
pub struct RawConsumer {
    /// Withdraws the consumer when dropped.
    pub(crate) _handle: EndpointHandle,
    pub(crate) state: Arc<ConsumerState>,
    /// The queue (immediate mode); `None` in polled mode.
    pub(crate) rx: Option<flume::Receiver<RawEvent>>,
}

impl RawConsumer {
    pub(crate) fn queue(&self) -> Result<&flume::Receiver<RawEvent>, RecvError> {
        self.rx
            .as_ref()
            .ok_or(RecvError::WrongMode(ConsumerMode::Polled))
    }

    pub(crate) fn next_event(&self, wait: Wait) -> Result<RawEvent, RecvError> {
        let event = self.take_event(wait)?;
        self.state.took(&event);
        Ok(event)
    }

    fn take_event(&self, wait: Wait) -> Result<RawEvent, RecvError> {
        let rx = self.queue()?;
        let signal = &self.state.delivery.signal;
        match wait {
            Wait::Block => signal.recv(rx, None),
            Wait::Try => rx.try_recv().map_err(|err| match err {
                flume::TryRecvError::Empty => RecvError::Empty,
                flume::TryRecvError::Disconnected => RecvError::Closed,
            }),
            Wait::Until(at) => signal.recv(rx, Some(at)),
        }
    }

    fn next_sample(&self, wait: Wait) -> Result<RawSample, RecvError> {
        loop {
            if let RawEvent::Sample(sample) = self.next_event(wait)? {
                return Ok(sample);
            }
        }
    }

    /// Blocks until a sample arrives (notifications are skipped).
    pub fn recv_raw(&self) -> Result<RawSample, RecvError> {
        self.next_sample(Wait::Block)
    }

    /// Returns a queued sample without blocking.
    pub fn try_recv_raw(&self) -> Result<RawSample, RecvError> {
        self.next_sample(Wait::Try)
    }

    /// Blocks until a sample arrives or `timeout` passes. At the timeout, the error names the
    /// producers of the topic this consumer is not matched with, if any
    /// ([`RecvError::TimeoutUnmatched`]).
    pub fn recv_raw_timeout(&self, timeout: Duration) -> Result<RawSample, RecvError> {
        self.next_sample(Wait::at_most(timeout))
            .map_err(|err| self.explain_timeout(err, timeout))
    }

    /// [`recv_raw_timeout`](Self::recv_raw_timeout) with a plain [`RecvError::Timeout`]: for
    /// a loop that polls (a habitat's clock), which must not take the endpoint tables' lock
    /// to explain every empty wait.
    pub fn recv_raw_wait(&self, timeout: Duration) -> Result<RawSample, RecvError> {
        self.next_sample(Wait::at_most(timeout))
    }

    /// Turns a timeout into [`RecvError::TimeoutUnmatched`] when producers of the topic are
    /// not matched with this consumer; any other error is returned as it is.
    pub(crate) fn explain_timeout(&self, err: RecvError, waited: Duration) -> RecvError {
        if err != RecvError::Timeout {
            return err;
        }
        let peers = &self.state.peers;
        let producers: Vec<UnmatchedProducer> = peers
            .incompatible_list()
            .into_iter()
            .filter(|remote| matches!(remote.qos, EndpointQos::Producer(_)))
            .map(|remote| UnmatchedProducer {
                writer: remote.guid,
                pid: remote.pid,
                // Same type: the daemon found the reliability wanting (as the router decides).
                mismatch: if remote.fingerprint == peers.fingerprint {
                    Mismatch::Reliability
                } else {
                    Mismatch::Type {
                        consumer: peers.type_desc.clone(),
                        producer: remote.type_desc,
                    }
                },
                process: remote.process,
            })
            .collect();
        if producers.is_empty() {
            return RecvError::Timeout;
        }
        RecvError::TimeoutUnmatched(Box::new(Unmatched {
            topic: peers.topic.clone(),
            waited,
            producers,
        }))
    }

    /// Blocks until a sample or a notification arrives, or `timeout` passes.
    pub fn recv_raw_event_timeout(&self, timeout: Duration) -> Result<RawEvent, RecvError> {
        self.next_event(Wait::at_most(timeout))
    }

    /// Polled mode: the latest accepted sample and its status, without blocking.
    pub fn poll_raw(&self) -> Result<(Option<RawSample>, PollStatus), RecvError> {
        let latest = self
            .state
            .delivery
            .latest()
            .ok_or(RecvError::WrongMode(ConsumerMode::Immediate))?;
        Ok(lock(latest).take_view())
    }

    /// Polled mode: the notifications raised since the last call (at most the last 64).
    pub fn take_notifications(&self) -> Result<Vec<Notification>, RecvError> {
        let latest = self
            .state
            .delivery
            .latest()
            .ok_or(RecvError::WrongMode(ConsumerMode::Immediate))?;
        Ok(lock(latest).take_notifications())
    }

    /// The topic name.
    pub fn topic(&self) -> &str {
        &self.state.peers.topic
    }

    /// This consumer's global id.
    pub fn guid(&self) -> ndds_core::wire::Guid {
        self._handle.guid()
    }

    /// The type description announced with this consumer.
    pub fn type_description(&self) -> &TypeDescription {
        &self.state.peers.type_desc
    }

    /// The producers currently matched.
    pub fn matched(&self) -> Vec<EndpointInfo> {
        self.state.peers.matched_list()
    }

    /// Producers of this topic whose type differs.
    pub fn incompatible(&self) -> Vec<EndpointInfo> {
        self.state.peers.incompatible_list()
    }

    /// Waits until at least `count` producers are matched; false at the timeout.
    pub fn wait_for_producers(&self, count: usize, timeout: Duration) -> bool {
        self.state.peers.wait_matched(count, timeout)
    }

    /// Counters.
    pub fn stats(&self) -> ConsumerStats {
        let counters = self.state.plane.consumer_counters(self.state.entity);
        let (arbiter, admission) = (counters.arbiter, counters.admission);
        ConsumerStats {
            received: counters.arrived,
            accepted: arbiter.accepted,
            delivered: arbiter.delivered,
            weaker: arbiter.weaker,
            old_data: arbiter.old_data,
            superseded: arbiter.superseded,
            deadline_misses: arbiter.deadline_misses,
            overflow: self.state.delivery.overflow.load(Ordering::Relaxed),
            decode_errors: self.state.decoder.errors.load(Ordering::Relaxed),
            unmatched: admission.unmatched,
            wrong_address: admission.wrong_address,
            reliable_streams: counters.streams,
            reliable: counters.reliable,
        }
    }
}

//! Consumers: receive the samples of a topic, blocking, polling, as an async stream, or
//! through a callback.
//!
//! Received samples wait in a bounded queue of `ConsumerQos::depth` samples; when the
//! application falls behind, the oldest is dropped and counted, so the queue always holds the
//! newest data. A sample that does not decode as `T` is skipped and counted (with a log line),
//! never delivered half-decoded.

use std::marker::PhantomData;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};
use std::thread::JoinHandle;
use std::time::Duration;

use futures_core::Stream;
use ndds_core::types::TypeDescription;
use ndds_core::wire::EndpointInfo;
use serde::de::DeserializeOwned;

use crate::data::ConsumerSlot;
use crate::error::RecvError;
use crate::participant::EndpointHandle;
use crate::peers::Peers;
use crate::sample::{RawSample, Sample};
use crate::sync::deadline;

/// State of one consumer shared with the participant's event router.
#[derive(Debug)]
pub(crate) struct ConsumerState {
    pub(crate) peers: Peers,
    pub(crate) slot: Arc<ConsumerSlot>,
    decoder: Arc<Decoder>,
}

/// What decoding needs; shared with callback threads, which must not keep the queue alive.
#[derive(Debug)]
struct Decoder {
    topic: String,
    errors: AtomicU64,
}

impl ConsumerState {
    pub(crate) fn new(topic: &str, type_desc: TypeDescription, slot: Arc<ConsumerSlot>) -> Self {
        ConsumerState {
            peers: Peers::new(topic, type_desc),
            slot,
            decoder: Arc::new(Decoder {
                topic: topic.to_owned(),
                errors: AtomicU64::new(0),
            }),
        }
    }
}

/// Counters of one consumer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ConsumerStats {
    /// Samples queued for the application.
    pub received: u64,
    /// Samples dropped because the queue was full.
    pub overflow: u64,
    /// Samples skipped because they did not decode.
    pub decode_errors: u64,
}

/// A consumer of already-encoded samples, as tools use it. Closing (dropping) it withdraws it.
#[derive(Debug)]
pub struct RawConsumer {
    /// Withdraws the consumer when dropped.
    pub(crate) _handle: EndpointHandle,
    pub(crate) state: Arc<ConsumerState>,
    pub(crate) rx: flume::Receiver<RawSample>,
}

impl RawConsumer {
    /// Blocks until a sample arrives.
    pub fn recv_raw(&self) -> Result<RawSample, RecvError> {
        self.rx.recv().map_err(|_| RecvError::Closed)
    }

    /// Returns a queued sample without blocking.
    pub fn try_recv_raw(&self) -> Result<RawSample, RecvError> {
        self.rx.try_recv().map_err(|err| match err {
            flume::TryRecvError::Empty => RecvError::Empty,
            flume::TryRecvError::Disconnected => RecvError::Closed,
        })
    }

    /// Blocks until a sample arrives or `timeout` passes.
    pub fn recv_raw_timeout(&self, timeout: Duration) -> Result<RawSample, RecvError> {
        let Some(deadline) = deadline(timeout) else {
            return self.recv_raw();
        };
        self.rx.recv_deadline(deadline).map_err(|err| match err {
            flume::RecvTimeoutError::Timeout => RecvError::Timeout,
            flume::RecvTimeoutError::Disconnected => RecvError::Closed,
        })
    }

    /// The topic name.
    pub fn topic(&self) -> &str {
        &self.state.peers.topic
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
        ConsumerStats {
            received: self.state.slot.received.load(Ordering::Relaxed),
            overflow: self.state.slot.overflow.load(Ordering::Relaxed),
            decode_errors: self.state.decoder.errors.load(Ordering::Relaxed),
        }
    }
}

/// A consumer of samples of type `T` on one topic. Closing (dropping) it withdraws it.
#[derive(Debug)]
pub struct Consumer<T> {
    raw: RawConsumer,
    _type: PhantomData<fn() -> T>,
}

impl<T> std::ops::Deref for Consumer<T> {
    type Target = RawConsumer;

    fn deref(&self) -> &RawConsumer {
        &self.raw
    }
}

impl<T: DeserializeOwned> Consumer<T> {
    pub(crate) fn new(raw: RawConsumer) -> Self {
        Consumer {
            raw,
            _type: PhantomData,
        }
    }

    /// Blocks until a sample arrives.
    pub fn recv(&self) -> Result<Sample<T>, RecvError> {
        loop {
            let raw = self.raw.recv_raw()?;
            if let Some(sample) = decode(&self.raw.state.decoder, raw) {
                return Ok(sample);
            }
        }
    }

    /// Returns a queued sample without blocking (`Err(RecvError::Empty)` if none).
    pub fn try_recv(&self) -> Result<Sample<T>, RecvError> {
        loop {
            let raw = self.raw.try_recv_raw()?;
            if let Some(sample) = decode(&self.raw.state.decoder, raw) {
                return Ok(sample);
            }
        }
    }

    /// Blocks until a sample arrives or `timeout` passes.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Sample<T>, RecvError> {
        let Some(deadline) = deadline(timeout) else {
            return self.recv();
        };
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            let raw = self.raw.recv_raw_timeout(left)?;
            if let Some(sample) = decode(&self.raw.state.decoder, raw) {
                return Ok(sample);
            }
        }
    }

    /// The samples as an async stream (runtime-agnostic). It borrows the consumer and does not
    /// end on its own: stop polling it (or drop it) to stop receiving this way.
    pub fn stream(&self) -> SampleStream<'_, T> {
        SampleStream {
            inner: self.raw.rx.stream(),
            decoder: &self.raw.state.decoder,
            _type: PhantomData,
        }
    }

    /// Hands every sample to `callback` on a thread of its own until the returned handle is
    /// dropped. A slow callback delays only this consumer.
    pub fn on_sample<F>(self, mut callback: F) -> std::io::Result<CallbackConsumer>
    where
        T: Send + 'static,
        F: FnMut(Sample<T>) + Send + 'static,
    {
        let rx = self.raw.rx.clone();
        let decoder = Arc::clone(&self.raw.state.decoder);
        let topic = decoder.topic.clone();
        let thread = std::thread::Builder::new()
            .name(format!("ndds-cb-{topic}"))
            .spawn(move || {
                while let Ok(raw) = rx.recv() {
                    if let Some(sample) = decode::<T>(&decoder, raw) {
                        callback(sample);
                    }
                }
            })?;
        Ok(CallbackConsumer {
            raw: Some(self.raw),
            thread: Some(thread),
        })
    }
}

fn decode<T: DeserializeOwned>(decoder: &Decoder, raw: RawSample) -> Option<Sample<T>> {
    match postcard::from_bytes::<T>(&raw.payload) {
        Ok(value) => Some(Sample {
            value,
            info: raw.info,
        }),
        Err(err) => {
            let count = decoder.errors.fetch_add(1, Ordering::Relaxed) + 1;
            if count.is_power_of_two() {
                tracing::warn!(
                    topic = decoder.topic,
                    writer = %raw.info.writer,
                    %err,
                    count,
                    "sample does not decode as the consumer's type; skipped"
                );
            }
            None
        }
    }
}

/// An async stream of samples, from [`Consumer::stream`].
#[derive(Debug)]
pub struct SampleStream<'a, T> {
    inner: flume::r#async::RecvStream<'a, RawSample>,
    decoder: &'a Decoder,
    _type: PhantomData<fn() -> T>,
}

impl<T: DeserializeOwned> Stream for SampleStream<'_, T> {
    type Item = Sample<T>;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Sample<T>>> {
        loop {
            match Pin::new(&mut self.inner).poll_next(cx) {
                Poll::Ready(Some(raw)) => {
                    if let Some(sample) = decode(self.decoder, raw) {
                        return Poll::Ready(Some(sample));
                    }
                }
                Poll::Ready(None) => return Poll::Ready(None),
                Poll::Pending => return Poll::Pending,
            }
        }
    }
}

/// A consumer delivering to a callback; dropping it withdraws the consumer and stops the
/// callback thread (a callback already running finishes first).
#[derive(Debug)]
pub struct CallbackConsumer {
    raw: Option<RawConsumer>,
    thread: Option<JoinHandle<()>>,
}

impl CallbackConsumer {
    /// The consumer underneath (topic, matches, counters).
    pub fn consumer(&self) -> Option<&RawConsumer> {
        self.raw.as_ref()
    }
}

impl Drop for CallbackConsumer {
    fn drop(&mut self) {
        // Withdrawing drops the queue's sender, which ends the callback thread's loop.
        drop(self.raw.take());
        if let Some(thread) = self.thread.take()
            && thread.thread().id() != std::thread::current().id()
        {
            let _ = thread.join();
        }
    }
}

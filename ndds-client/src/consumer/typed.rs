//! The typed consumer: decoding, blocking and polling access.

use std::marker::PhantomData;
use std::sync::atomic::Ordering;
use std::time::Duration;

use ndds_core::arbitration::Notification;
use serde::de::DeserializeOwned;

use super::raw::{Decoder, RawConsumer, Wait};
use super::stream::{EventStream, SampleStream};
use crate::error::RecvError;
use crate::sample::{Event, Polled, RawEvent, RawSample, Sample};

/// A consumer of samples of type `T` on one topic. Closing (dropping) it withdraws it.
#[derive(Debug)]
pub struct Consumer<T> {
    pub(crate) raw: RawConsumer,
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

    fn next_sample(&self, wait: Wait) -> Result<Sample<T>, RecvError> {
        loop {
            if let RawEvent::Sample(raw) = self.raw.next_event(wait)?
                && let Ok(sample) = decode(&self.raw.state.decoder, raw)
            {
                return Ok(sample);
            }
        }
    }

    /// Blocks until a sample arrives (notifications are skipped).
    pub fn recv(&self) -> Result<Sample<T>, RecvError> {
        self.next_sample(Wait::Block)
    }

    /// Returns a queued sample without blocking (`Err(RecvError::Empty)` if none).
    pub fn try_recv(&self) -> Result<Sample<T>, RecvError> {
        self.next_sample(Wait::Try)
    }

    /// Blocks until a sample arrives or `timeout` passes. At the timeout, the error names the
    /// producers of the topic this consumer is not matched with and why, if there are any
    /// ([`RecvError::TimeoutUnmatched`]: another type, or best effort for a reliable consumer),
    /// else it is [`RecvError::Timeout`].
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Sample<T>, RecvError> {
        self.next_sample(Wait::at_most(timeout))
            .map_err(|err| self.raw.explain_timeout(err, timeout))
    }

    /// Blocks until a sample or a notification arrives.
    pub fn recv_event(&self) -> Result<Event<T>, RecvError> {
        self.raw
            .next_event(Wait::Block)
            .map(|e| decode_event(&self.raw.state.decoder, e))
    }

    /// Returns a queued sample or notification without blocking (`Err(RecvError::Empty)` if
    /// none).
    pub fn try_recv_event(&self) -> Result<Event<T>, RecvError> {
        self.raw
            .next_event(Wait::Try)
            .map(|e| decode_event(&self.raw.state.decoder, e))
    }

    /// Blocks until a sample or a notification arrives, or `timeout` passes.
    pub fn recv_event_timeout(&self, timeout: Duration) -> Result<Event<T>, RecvError> {
        self.raw
            .next_event(Wait::at_most(timeout))
            .map(|e| decode_event(&self.raw.state.decoder, e))
    }

    /// Polled mode: the latest accepted sample and its status, without blocking.
    pub fn poll(&self) -> Result<Polled<T>, RecvError> {
        let (raw, status) = self.raw.poll_raw()?;
        let sample = raw.and_then(|raw| decode(&self.raw.state.decoder, raw).ok());
        Ok(Polled { sample, status })
    }

    /// The samples as an async stream (runtime-agnostic). It borrows the consumer and does not
    /// end on its own: stop polling it (or drop it) to stop receiving this way.
    pub fn stream(&self) -> Result<SampleStream<'_, T>, RecvError> {
        Ok(SampleStream::new(
            self.raw.queue()?.stream(),
            &self.raw.state.decoder,
            &self.raw.state,
        ))
    }

    /// Samples and notifications as an async stream (see [`Consumer::stream`]).
    pub fn events(&self) -> Result<EventStream<'_, T>, RecvError> {
        Ok(EventStream::new(
            self.raw.queue()?.stream(),
            &self.raw.state.decoder,
            &self.raw.state,
        ))
    }
}

/// Decodes a sample; counts and logs a failure.
pub(crate) fn decode<T: DeserializeOwned>(
    decoder: &Decoder,
    raw: RawSample,
) -> Result<Sample<T>, Notification> {
    match postcard::from_bytes::<T>(&raw.payload) {
        Ok(value) => Ok(Sample {
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
            Err(Notification::DeserializationError {
                writer: raw.info.writer,
                seq: raw.info.seq,
                error: err.to_string(),
            })
        }
    }
}

/// Decodes an event; a sample that does not decode becomes a notification.
pub(crate) fn decode_event<T: DeserializeOwned>(decoder: &Decoder, event: RawEvent) -> Event<T> {
    match event {
        RawEvent::Sample(raw) => match decode(decoder, raw) {
            Ok(sample) => Event::Sample(sample),
            Err(notification) => Event::Notification(notification),
        },
        RawEvent::Notification(notification) => Event::Notification(notification),
    }
}

//! Delivering a consumer's samples or events to a callback: on the participant's callback
//! thread, or directly on its I/O thread.

use std::sync::Arc;

use serde::de::DeserializeOwned;

use super::dispatch::Registration;
use super::raw::RawConsumer;
use super::typed::{Consumer, decode_event};
use crate::error::RecvError;
use crate::sample::{Event, RawEvent, RawSample, Sample};

impl<T: DeserializeOwned> Consumer<T> {
    /// Hands every sample to `callback` until the returned handle is dropped (notifications
    /// are skipped; see [`Consumer::on_event`], which says where callbacks run). Fails in
    /// polled mode.
    pub fn on_sample<F>(self, mut callback: F) -> Result<CallbackConsumer, RecvError>
    where
        T: Send + 'static,
        F: FnMut(Sample<T>) + Send + 'static,
    {
        self.on_event(move |event| {
            if let Event::Sample(sample) = event {
                callback(sample);
            }
        })
    }

    /// Hands every sample and notification to `callback` until the returned handle is
    /// dropped. Callbacks run on the participant's callback thread (`ndds-callbacks`, one per
    /// participant, started with its first callback consumer), one consumer's events after
    /// another's: a callback that takes long delays the other callbacks of the participant,
    /// never its I/O. Fails in polled mode.
    pub fn on_event<F>(self, mut callback: F) -> Result<CallbackConsumer, RecvError>
    where
        T: Send + 'static,
        F: FnMut(Event<T>) + Send + 'static,
    {
        let rx = self.raw.queue()?.clone();
        let decoder = Arc::clone(&self.raw.state.decoder);
        let registration = self
            .raw
            ._handle
            .inner
            .dispatcher
            .register(
                &self.raw.state,
                rx,
                Box::new(move |event| callback(decode_event(&decoder, event))),
            )
            .map_err(|err| RecvError::Thread(err.to_string()))?;
        Ok(CallbackConsumer {
            raw: Some(self.raw),
            registration: Some(registration),
        })
    }
}

impl<T: DeserializeOwned + 'static> Consumer<T> {
    /// Hands every sample to `callback` *on the participant's I/O thread* (`ndds-io`), with
    /// no thread switch: the lowest latency ndds offers, as NDDS's immediate consumers had. The callback must be
    /// quick and must not block: every consumer of the participant waits while it runs. It
    /// must not call back into this consumer. It may write with producers (a relay, a pong);
    /// a reliable producer whose window is full then fails at once with
    /// [`crate::WriteError::WouldBlock`] instead of waiting, since the acknowledgements that
    /// would open it arrive on this very thread. Fails in polled mode.
    pub fn on_sample_direct<F>(self, mut callback: F) -> Result<DirectConsumer, RecvError>
    where
        F: FnMut(Sample<T>) + Send + 'static,
    {
        self.raw.queue()?;
        let decoder = Arc::clone(&self.raw.state.decoder);
        self.raw.state.set_direct(Box::new(move |event| {
            if let Event::Sample(sample) = decode_event::<T>(&decoder, event) {
                callback(sample);
            }
        }));
        Ok(DirectConsumer { raw: self.raw })
    }
}

impl RawConsumer {
    /// Hands every sample, still encoded, to `callback` on the participant's I/O thread:
    /// [`Consumer::on_sample_direct`] without decoding, for tools that forward, record or
    /// decode samples their own way (the payload is a view into the received datagram, not a
    /// copy). Notifications are skipped. The same rules as for `on_sample_direct` apply.
    /// Fails in polled mode.
    pub fn on_raw_sample_direct<F>(self, mut callback: F) -> Result<DirectConsumer, RecvError>
    where
        F: FnMut(RawSample) + Send + 'static,
    {
        self.queue()?;
        self.state.set_direct(Box::new(move |event| {
            if let RawEvent::Sample(sample) = event {
                callback(sample);
            }
        }));
        Ok(DirectConsumer { raw: self })
    }
}

/// A consumer delivering to a callback on the I/O thread; dropping it withdraws the
/// consumer (see [`Consumer::on_sample_direct`]).
#[derive(Debug)]
pub struct DirectConsumer {
    raw: RawConsumer,
}

impl DirectConsumer {
    /// The consumer underneath (topic, matches, counters).
    pub fn consumer(&self) -> &RawConsumer {
        &self.raw
    }
}

/// A consumer delivering to a callback; dropping it stops the callback (one already running
/// finishes first, unless the handle is dropped by a callback) and withdraws the consumer.
#[derive(Debug)]
pub struct CallbackConsumer {
    raw: Option<RawConsumer>,
    registration: Option<Registration>,
}

impl CallbackConsumer {
    /// The consumer underneath (topic, matches, counters).
    pub fn consumer(&self) -> Option<&RawConsumer> {
        self.raw.as_ref()
    }
}

impl Drop for CallbackConsumer {
    fn drop(&mut self) {
        drop(self.registration.take());
        drop(self.raw.take());
    }
}

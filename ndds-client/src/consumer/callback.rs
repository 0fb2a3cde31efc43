//! Delivering a consumer's samples or events to a callback on a thread of its own.

use std::sync::Arc;
use std::thread::JoinHandle;

use serde::de::DeserializeOwned;

use super::raw::RawConsumer;
use super::typed::{Consumer, decode_event};
use crate::error::RecvError;
use crate::sample::{Event, RawEvent, RawSample, Sample};

impl<T: DeserializeOwned> Consumer<T> {
    /// Hands every sample to `callback` on a thread of its own until the returned handle is
    /// dropped (notifications are skipped; see [`Consumer::on_event`]). A slow callback delays
    /// only this consumer. Fails in polled mode.
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

    /// Hands every sample and notification to `callback` on a thread of its own until the
    /// returned handle is dropped. Fails in polled mode.
    pub fn on_event<F>(self, mut callback: F) -> Result<CallbackConsumer, RecvError>
    where
        T: Send + 'static,
        F: FnMut(Event<T>) + Send + 'static,
    {
        let rx = self.raw.queue()?.clone();
        let decoder = Arc::clone(&self.raw.state.decoder);
        // Weak: the state holds the queue's sender, which must go when the consumer does.
        let state = Arc::downgrade(&self.raw.state);
        let signal = Arc::clone(&self.raw.state.delivery.signal);
        let thread = std::thread::Builder::new()
            .name(format!("ndds-cb-{}", decoder.topic))
            .spawn(move || {
                while let Ok(event) = signal.recv(&rx, None) {
                    // Room was made: a reliable stream waiting for it moves on.
                    if let Some(state) = state.upgrade() {
                        state.took(&event);
                    }
                    callback(decode_event(&decoder, event));
                }
            })
            .map_err(|err| RecvError::Thread(err.to_string()))?;
        Ok(CallbackConsumer {
            raw: Some(self.raw),
            thread: Some(thread),
        })
    }
}

impl<T: DeserializeOwned + 'static> Consumer<T> {
    /// Hands every sample to `callback` *on the participant's receive thread* (or timer
    /// thread, for samples released by a minimum-separation window), with no thread switch:
    /// the lowest latency ndds offers, as NDDS's immediate consumers had. The callback must be
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
    /// Hands every sample, still encoded, to `callback` on the participant's receive thread:
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

/// A consumer delivering to a callback on the receive thread; dropping it withdraws the
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

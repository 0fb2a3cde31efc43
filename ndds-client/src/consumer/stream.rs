//! Async streams over an immediate consumer's queue.

use std::marker::PhantomData;
use std::pin::Pin;
use std::task::{Context, Poll};

use futures_core::Stream;
use serde::de::DeserializeOwned;

use super::raw::ConsumerState;
use super::raw::Decoder;
use super::typed::{decode, decode_event};
use crate::sample::{Event, RawEvent, Sample};

type Inner<'a> = flume::r#async::RecvStream<'a, RawEvent>;

/// An async stream of samples, from [`super::Consumer::stream`]; notifications and samples
/// that do not decode are skipped.
#[derive(Debug)]
pub struct SampleStream<'a, T> {
    inner: Inner<'a>,
    decoder: &'a Decoder,
    /// Told when an event was taken (a reliable stream may be waiting for room).
    state: &'a ConsumerState,
    _type: PhantomData<fn() -> T>,
}

impl<'a, T> SampleStream<'a, T> {
    pub(crate) fn new(inner: Inner<'a>, decoder: &'a Decoder, state: &'a ConsumerState) -> Self {
        SampleStream {
            inner,
            decoder,
            state,
            _type: PhantomData,
        }
    }
}

impl<T: DeserializeOwned> Stream for SampleStream<'_, T> {
    type Item = Sample<T>;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Sample<T>>> {
        loop {
            let event = Pin::new(&mut self.inner).poll_next(cx);
            if let Poll::Ready(Some(event)) = &event {
                self.state.took(event);
            }
            match event {
                Poll::Ready(Some(RawEvent::Sample(raw))) => {
                    if let Ok(sample) = decode(self.decoder, raw) {
                        return Poll::Ready(Some(sample));
                    }
                }
                Poll::Ready(Some(RawEvent::Notification(_))) => {}
                Poll::Ready(None) => return Poll::Ready(None),
                Poll::Pending => return Poll::Pending,
            }
        }
    }
}

/// An async stream of samples and notifications, from [`super::Consumer::events`].
#[derive(Debug)]
pub struct EventStream<'a, T> {
    inner: Inner<'a>,
    decoder: &'a Decoder,
    /// Told when an event was taken (a reliable stream may be waiting for room).
    state: &'a ConsumerState,
    _type: PhantomData<fn() -> T>,
}

impl<'a, T> EventStream<'a, T> {
    pub(crate) fn new(inner: Inner<'a>, decoder: &'a Decoder, state: &'a ConsumerState) -> Self {
        EventStream {
            inner,
            decoder,
            state,
            _type: PhantomData,
        }
    }
}

impl<T: DeserializeOwned> Stream for EventStream<'_, T> {
    type Item = Event<T>;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Event<T>>> {
        let decoder = self.decoder;
        let event = Pin::new(&mut self.inner).poll_next(cx);
        if let Poll::Ready(Some(event)) = &event {
            self.state.took(event);
        }
        event.map(|event| event.map(|event| decode_event(decoder, event)))
    }
}

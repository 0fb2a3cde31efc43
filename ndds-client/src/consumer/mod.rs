//! Consumers: receive the samples of a topic, with NDDS semantics applied by an arbiter
//! (strength and persistence of producers, minimum separation, deadlines).
//!
//! In **immediate** mode, accepted samples and notifications wait in a bounded queue of
//! `ConsumerQos::depth` events (when the application falls behind, the oldest is dropped and
//! counted, so the queue always holds the newest data); take them blocking, without blocking,
//! as an async stream, or through a callback. `recv` and friends give samples only;
//! `recv_event` and friends give samples and notifications. In **polled** mode, `poll` returns
//! the latest accepted sample and its status without blocking.
//!
//! A sample that does not decode as `T` is never delivered half-decoded: `recv` skips it,
//! `recv_event` reports it as a notification, and both count it.

mod callback;
mod delivery;
mod dispatch;
mod raw;
mod stream;
mod typed;

pub use callback::{CallbackConsumer, DirectConsumer};
pub(crate) use delivery::{Delivery, Direct};
pub(crate) use dispatch::{Dispatcher, help_dispatch, on_dispatcher_thread};
pub(crate) use raw::ConsumerState;
pub use raw::{ConsumerStats, RawConsumer};
pub use stream::{EventStream, SampleStream};
pub use typed::Consumer;

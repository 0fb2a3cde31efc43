//! Reliable streams without IO: a writer's history, heartbeats, repair and flow-control window,
//! and a reader's reordering, duplicate suppression, acknowledgements and loss reports.
//! (Being written.)

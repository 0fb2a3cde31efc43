//! `Bye` (kind 4): the sending daemon leaves the domain.
//!
//! ```text
//! header(kind = 4)            (empty body)
//! ```
//!
//! Receivers forget the node and every endpoint it announced, without waiting for the lease.

use serde::{Deserialize, Serialize};

/// Body of a `Bye` datagram (empty).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Bye;

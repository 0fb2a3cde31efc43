//! # ndds-docs
//!
//! The ndds documentation (`docs/*.md`) and the tests that keep it in step with the code.
//!
//! `docs/protocol.md` specifies the wire and local protocols. Its tables of message and
//! submessage kinds, drop reasons, message layouts, limits and defaults, and its worked
//! examples, are checked against `ndds-core` (and the daemon's defaults) by `docs/tests/`: a
//! change to the code that the document does not follow fails `cargo test -p ndds-docs` with
//! the document line to update.
//!
//! This library holds only what those tests share ([`markdown`], [`report`]); it
//! has no runtime use.
//!
//! ## Layout
//! - `protocol.md`: the protocol specification.
//! - `runtime.md`: the ControlShell runtime guide; `tests/runtime_guide.rs` checks its code
//!   excerpts and tables against the code.
//! - `fsm.md`: the state machine guide; `tests/fsm_guide.rs` checks its example program (it is
//!   the example file, and it verifies), excerpts and tables.
//! - `ports.md`: the ports guide; `tests/ports_guide.rs` checks its excerpts and the
//!   restrictions table.
//! - [`excerpts`]: code excerpts in the guides checked against the files they quote.
//! - [`markdown`]: headings, pipe tables and fenced blocks of a document, with line numbers.
//! - [`report`]: every mismatch found, each naming the document line to update.
//! - `tests/protocol_tables.rs`: message kinds, `Data` and `Feedback` submessage kinds, drop
//!   reasons, header, domains, limits.
//! - `tests/protocol_schema.rs`: every message structure against the types' serde layout.
//! - `tests/protocol_examples.rs`: the worked example bytes (the data-plane ones also parsed
//!   back) and fingerprints.
//! - `tests/support/values.rs`: the documented values as the code has them; limits that are
//!   not public constants are observed through the discovery engine's behaviour.
#![warn(missing_docs)]

pub mod excerpts;
pub mod markdown;
pub mod report;

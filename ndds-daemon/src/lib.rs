//! # ndds-daemon
//!
//! The per-host discovery daemon of ndds: a thin tokio driver around
//! [`ndds_core::discovery::Engine`]. One daemon runs per host and domain. It
//! - exchanges discovery datagrams with the other daemons of its domain over UDP multicast
//!   on one chosen interface, and by unicast with static peers and with daemons that reach it
//!   only by unicast ([`sockets`], [`peers`]); multicast can be turned off,
//! - serves local clients and tools over a Unix socket with length-delimited postcard frames
//!   ([`connection`]), and withdraws a client's endpoints the moment its connection drops,
//! - routes the engine's match events to the clients that own the endpoints ([`driver`]).
//!
//! It never carries user data: samples go directly from producing to consuming processes.
//! It can run as the `ndds-daemon` binary or inside another process ([`embed`]).
//!
//! ## Layout
//! - [`config`]: defaults, config file and their merge; [`iface`]: interface resolution;
//!   [`peers`]: static unicast peers, parsed and resolved.
//! - [`keys`]: domain key files (sealed domains).
//! - [`local`]: where the local socket lives, who may connect, who is at the other end;
//!   [`claim`]: one daemon per socket path; [`daemon`]: bind, run, shutdown; [`driver`]: the task that owns the engine.
//! - `cli`: the binary's command line, usable from other binaries too (feature `cli`, on by
//!   default; the SDK turns it off, so a program embedding a daemon compiles neither clap nor
//!   TOML).
#![warn(missing_docs)]

pub mod claim;
#[cfg(feature = "cli")]
pub mod cli;
pub mod config;
pub mod connection;
pub mod daemon;
pub mod driver;
pub mod embed;
pub mod iface;
pub mod keys;
pub mod local;
pub mod log_budget;
pub mod peers;
pub mod security;
pub mod sockets;

pub use config::{ConfigError, ConfigFile, DaemonConfig};
pub use daemon::{Daemon, DaemonError};
pub use embed::{EmbedError, EmbeddedDaemon};

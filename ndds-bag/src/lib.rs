//! Recordings of ndds topics in MCAP files, the format rosbag2, Foxglove, PlotJuggler and the
//! Python `mcap` package read (docs/recording.md in the repository; the layout in
//! [`format`](mod@format) and docs/protocol.md, "Recordings").
//!
//! - [`record::Recorder`] records topics as they arrive (every producer, reliably where the
//!   producer offers it), counting honestly what it lost;
//! - [`play::Player`] publishes a recording again with its recorded types, QoS and timing;
//! - [`write::BagWriter`] and [`read::BagReader`] write and read the files themselves, and
//!   [`info::BagInfo`] summarizes one, even a truncated one.

pub mod edit;
pub mod format;
pub mod info;
pub mod play;
pub mod read;
pub mod record;
pub mod write;

use std::path::{Path, PathBuf};

pub use info::BagInfo;
pub use play::{PlayOptions, Player};
pub use read::{BagChannel, BagMessage, BagReader, Ending, Merged};
pub use record::{RecordOptions, Recorder, Selection};
pub use write::{BagWriter, Compression, Lost, WriteOptions};

/// What can go wrong with a bag.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// Reading or writing the file failed.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error (in the message, so not also a `source`).
        error: std::io::Error,
    },
    /// The MCAP library refused something.
    #[error("{path}: {error}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// What it said.
        error: String,
    },
    /// A recording would overwrite something.
    #[error("{0} exists: choose another name, or remove it first")]
    Exists(PathBuf),
    /// The writer was finished.
    #[error("the recording is finished")]
    Finished,
    /// The disk was about to fill: the file was finished properly and recording stopped.
    #[error(
        "the disk of {path} has {free} bytes free, less than the {reserve} the recorder keeps: \
         recording stopped and the file was closed properly; free some space and record again"
    )]
    DiskFull {
        /// The file that was finished.
        path: PathBuf,
        /// Bytes free.
        free: u64,
        /// Bytes the recorder keeps free.
        reserve: u64,
    },
    /// A channel that cannot be played.
    #[error("{path}: channel {channel} ({topic}) cannot be played: {why}")]
    Unplayable {
        /// The file.
        path: PathBuf,
        /// The channel id.
        channel: u16,
        /// Its topic.
        topic: String,
        /// Why not.
        why: String,
    },
    /// The participant refused something (declaring a producer or consumer, the graph).
    #[error("{0}")]
    Participant(String),
    /// A bad option.
    #[error("{0}")]
    Usage(String),
}

impl BagError {
    pub(crate) fn io(path: &Path, error: std::io::Error) -> Self {
        BagError::Io {
            path: path.to_owned(),
            error,
        }
    }

    pub(crate) fn mcap(path: &Path, error: mcap::McapError) -> Self {
        match error {
            mcap::McapError::Io(error) => BagError::io(path, error),
            error => BagError::Mcap {
                path: path.to_owned(),
                error: error.to_string(),
            },
        }
    }
}

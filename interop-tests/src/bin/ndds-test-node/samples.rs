//! The sample types a test node can declare: `Telemetry` (everyone's default) and
//! `TelemetryV2`, a different structure under another name, to provoke "incompatible type".

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

/// Which sample type a node declares (`--type`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SampleType {
    /// The tests' default type, `Telemetry`.
    Telemetry,
    /// `TelemetryV2`, another structure: never matches `Telemetry` on the same topic.
    TelemetryV2,
    /// `Blob`: a sequence number and `--payload` bytes whose content depends on it, so a
    /// consumer can check every byte (large samples).
    Blob,
}

/// A sample a test node writes and reports.
pub trait TestSample: Serialize + DeserializeOwned + Send + 'static {
    /// The sample number `seq` of a producer that writes `value` in every sample (and, for
    /// types that carry a payload, `payload` bytes of it).
    fn make(seq: u64, value: i64, payload: usize) -> Self;
    /// The fields a consumer reports (`seq` and `value` at least).
    fn fields(&self) -> Value;
}

/// The sample type of the interop tests.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    seq: u64,
    position: [f64; 3],
    label: String,
    /// Written by the producer (`--value`), so consumers can tell producers apart.
    value: i64,
}

impl TestSample for Telemetry {
    fn make(seq: u64, value: i64, _payload: usize) -> Self {
        Telemetry {
            seq,
            position: [seq as f64, 0.5, -1.0],
            label: format!("sample {seq}"),
            value,
        }
    }

    fn fields(&self) -> Value {
        json!({
            "seq": self.seq,
            "position": self.position,
            "label": self.label,
            "value": self.value,
        })
    }
}

/// A structurally different sample type.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TelemetryV2 {
    seq: u64,
    value: i64,
    healthy: bool,
}

impl TestSample for TelemetryV2 {
    fn make(seq: u64, value: i64, _payload: usize) -> Self {
        TelemetryV2 {
            seq,
            value,
            healthy: true,
        }
    }

    fn fields(&self) -> Value {
        json!({"seq": self.seq, "value": self.value, "healthy": self.healthy})
    }
}

/// A sample with a payload of any size whose bytes follow from its `seq`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Blob {
    seq: u64,
    value: i64,
    #[serde(with = "serde_bytes")]
    data: Vec<u8>,
}

/// Byte `i` of the payload of sample `seq`.
fn blob_byte(seq: u64, i: usize) -> u8 {
    (i as u64)
        .wrapping_mul(31)
        .wrapping_add(seq.wrapping_mul(7)) as u8
}

impl TestSample for Blob {
    fn make(seq: u64, value: i64, payload: usize) -> Self {
        Blob {
            seq,
            value,
            data: (0..payload).map(|i| blob_byte(seq, i)).collect(),
        }
    }

    fn fields(&self) -> Value {
        let intact = self
            .data
            .iter()
            .enumerate()
            .all(|(i, b)| *b == blob_byte(self.seq, i));
        json!({"seq": self.seq, "value": self.value, "len": self.data.len(), "intact": intact})
    }
}

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
}

/// A sample a test node writes and reports.
pub trait TestSample: Serialize + DeserializeOwned + Send + 'static {
    /// The sample number `seq` of a producer that writes `value` in every sample.
    fn make(seq: u64, value: i64) -> Self;
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
    fn make(seq: u64, value: i64) -> Self {
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
    fn make(seq: u64, value: i64) -> Self {
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

//! How ndds samples sit in an MCAP file (docs/protocol.md, "Recordings"): the schema and
//! message encodings, the metadata of channels and of the recording.
//!
//! - **Schema**: name = the type's name, encoding [`SCHEMA_ENCODING`] (`ndds`), data = the
//!   type description in postcard, the same bytes discovery carries, so a replay declares the
//!   very type (and fingerprint) that was recorded.
//! - **Channel**: one per topic and recorded producer, topic = the ndds topic, message
//!   encoding [`MESSAGE_ENCODING`] (`ndds`: the sample's postcard bytes as they travelled),
//!   metadata = the producer's id, strength, persistence and reliability ([`ChannelMeta`]).
//! - **Message**: `log_time` = when the recorder received it, `publish_time` = the producer's
//!   source timestamp (both nanoseconds since the Unix epoch), `sequence` = the low 32 bits of
//!   the producer's sequence number.
//! - **JSON companions** (`ndds record --json`): per topic a channel `json/TOPIC`, message
//!   encoding `json` (each sample as `ndds echo --json` prints its value), schema encoding
//!   `jsonschema` (a draft-07 JSON Schema generated from the type description), metadata
//!   [`JSON_OF`] = the topic; the same log and publish times and sequence as the sample.
//!   Samples over [`MAX_JSON_PAYLOAD`] bytes and opaque types get none.
//! - **Metadata** [`RECORDING_METADATA`]: who recorded, and per topic what was lost.

use std::collections::BTreeMap;
use std::time::Duration;

use ndds_core::types::TypeDescription;
use ndds_core::wire::{Guid, Reliability};

/// The schema encoding of ndds type descriptions.
pub const SCHEMA_ENCODING: &str = "ndds";
/// The message encoding of ndds samples (postcard bytes, as on the wire).
pub const MESSAGE_ENCODING: &str = "ndds";
/// The MCAP profile of files ndds writes.
pub const PROFILE: &str = "ndds";
/// The name of the metadata record that describes a recording.
pub const RECORDING_METADATA: &str = "ndds.recording";
/// The channel metadata key that marks a JSON companion channel (its value: the topic).
pub const JSON_OF: &str = "json_of";
/// Samples larger than this get no JSON companion (a megabyte image as a JSON array of
/// numbers helps no viewer, and costs the recorder several times its size).
pub const MAX_JSON_PAYLOAD: usize = 64 * 1024;
/// The topic prefix of JSON companion channels: `json/arm/pose` for `arm/pose`.
pub const JSON_TOPIC_PREFIX: &str = "json/";
/// Largest type description a schema may carry (discovery's bound for one endpoint).
pub const MAX_SCHEMA_BYTES: usize = 64 * 1024;

/// A schema's data: the type description in postcard.
pub fn encode_schema(desc: &TypeDescription) -> Vec<u8> {
    postcard::to_allocvec(desc).expect("a type description always encodes")
}

/// A type description from a schema's data, validated as discovery validates it.
pub fn decode_schema(data: &[u8]) -> Result<TypeDescription, String> {
    if data.len() > MAX_SCHEMA_BYTES {
        return Err(format!(
            "type description of {} bytes (at most {MAX_SCHEMA_BYTES})",
            data.len()
        ));
    }
    let desc: TypeDescription =
        postcard::from_bytes(data).map_err(|err| format!("not a type description: {err}"))?;
    desc.validate()
        .map_err(|err| format!("invalid type description: {err}"))?;
    Ok(desc)
}

/// What a channel records of its producer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChannelMeta {
    /// The producer whose samples the channel holds (`None` in a file from elsewhere).
    pub writer: Option<Guid>,
    /// Its strength.
    pub strength: i32,
    /// Its persistence.
    pub persistence: Duration,
    /// Its reliability.
    pub reliability: Reliability,
}

impl Default for ChannelMeta {
    fn default() -> Self {
        ChannelMeta {
            writer: None,
            strength: 0,
            persistence: ndds_client::qos::DEFAULT_PERSISTENCE,
            reliability: Reliability::BestEffort,
        }
    }
}

impl ChannelMeta {
    /// As MCAP channel metadata.
    pub fn to_map(&self) -> BTreeMap<String, String> {
        let mut map = BTreeMap::new();
        if let Some(writer) = self.writer {
            map.insert("writer".into(), writer.to_string());
        }
        map.insert("strength".into(), self.strength.to_string());
        map.insert(
            "persistence_us".into(),
            self.persistence.as_micros().to_string(),
        );
        let reliability = match self.reliability {
            Reliability::BestEffort => "best-effort".to_owned(),
            Reliability::Reliable { depth } => format!("reliable/{depth}"),
        };
        map.insert("reliability".into(), reliability);
        map
    }

    /// From MCAP channel metadata; what is missing or unreadable keeps its default.
    pub fn from_map(map: &BTreeMap<String, String>) -> Self {
        let mut meta = ChannelMeta::default();
        if let Some(writer) = map.get("writer").and_then(|w| parse_guid(w)) {
            meta.writer = Some(writer);
        }
        if let Some(strength) = map.get("strength").and_then(|s| s.parse().ok()) {
            meta.strength = strength;
        }
        if let Some(us) = map.get("persistence_us").and_then(|s| s.parse().ok()) {
            meta.persistence = Duration::from_micros(us);
        }
        if let Some(depth) = map
            .get("reliability")
            .and_then(|text| text.strip_prefix("reliable/"))
            .and_then(|d| d.parse().ok())
        {
            meta.reliability = Reliability::Reliable { depth };
        }
        meta
    }
}

/// A producer id as [`Guid`]'s `Display` writes it: `participant-hex.entity`.
pub fn parse_guid(text: &str) -> Option<Guid> {
    let (participant, entity) = text.split_once('.')?;
    Some(Guid {
        participant: u64::from_str_radix(participant, 16).ok()?,
        entity: entity.parse().ok()?,
    })
}

/// Nanoseconds since the Unix epoch (0 before it, saturating after 2554).
pub fn nanos(time: std::time::SystemTime) -> u64 {
    time.duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channel_metadata_and_schemas_read_back() {
        let meta = ChannelMeta {
            writer: Some(Guid {
                participant: 0xabc,
                entity: 7,
            }),
            strength: -3,
            persistence: Duration::from_millis(250),
            reliability: Reliability::Reliable { depth: 32 },
        };
        assert_eq!(ChannelMeta::from_map(&meta.to_map()), meta);
        assert_eq!(
            ChannelMeta::from_map(&BTreeMap::new()),
            ChannelMeta::default()
        );
        let desc = TypeDescription::of::<(f64, String)>();
        assert_eq!(decode_schema(&encode_schema(&desc)).unwrap(), desc);
        assert!(decode_schema(b"\xff\xff").is_err());
        assert!(decode_schema(&vec![0; MAX_SCHEMA_BYTES + 1]).is_err());
    }
}

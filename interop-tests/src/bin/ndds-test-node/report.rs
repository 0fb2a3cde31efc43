//! JSON lines on stdout: one object per line, each with an `"event"` field.

use std::time::{Duration, SystemTime};

use ndds_client::{EndpointInfo, Notification, ParticipantStats, SampleInfo, SampleStatus};
use serde_json::{Value, json};

/// Prints one JSON line (stdout is line-buffered: lines of concurrent threads never mix).
pub fn emit(value: Value) {
    println!("{value}");
}

/// Microseconds since the Unix epoch: every process of the machine shares this clock, so a
/// test can compare a node's timestamps with its own.
pub fn unix_us(time: SystemTime) -> u64 {
    time.duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

fn ms(duration: Duration) -> f64 {
    duration.as_secs_f64() * 1000.0
}

/// A `sample` line: the value's fields, then how it was accepted and from whom.
pub fn sample(topic: &str, fields: Value, info: &SampleInfo) -> Value {
    let mut line = json!({
        "event": "sample",
        "topic": topic,
        "writer": info.writer.to_string(),
        "writer_pid_participant": info.writer.participant,
        "writer_seq": info.seq,
        "strength": info.strength,
        "recv_unix_us": unix_us(info.reception_timestamp),
        "source_unix_us": unix_us(info.source_timestamp),
    });
    match info.status {
        SampleStatus::Fresh => line["status"] = json!("fresh"),
        SampleStatus::TookOver { previous } => {
            line["status"] = json!("took_over");
            line["previous"] = json!(previous.to_string());
        }
    }
    if let (Value::Object(line), Value::Object(fields)) = (&mut line, fields) {
        line.extend(fields);
    }
    line
}

/// A `notification` line: `kind` names the variant, the other fields are its own.
pub fn notification(topic: &str, notification: &Notification) -> Value {
    let (kind, fields) = match notification {
        Notification::NoNewData { silent_for } => {
            ("NoNewData", json!({"silent_ms": ms(*silent_for)}))
        }
        Notification::NeverReceived { waited } => {
            ("NeverReceived", json!({"waited_ms": ms(*waited)}))
        }
        Notification::OldData { writer, seq } => (
            "OldData",
            json!({"writer": writer.to_string(), "writer_seq": seq}),
        ),
        Notification::ProducerLost {
            writer,
            was_current,
        } => (
            "ProducerLost",
            json!({"writer": writer.to_string(), "was_current": was_current}),
        ),
        Notification::Incompatible {
            reason,
            writer,
            type_name,
            fingerprint,
            local_type,
            local_fingerprint,
        } => (
            "Incompatible",
            json!({
                "reason": format!("{reason:?}"),
                "writer": writer.to_string(),
                "type_name": type_name,
                "fingerprint": format!("{fingerprint:016x}"),
                "local_type": local_type,
                "local_fingerprint": format!("{local_fingerprint:016x}"),
            }),
        ),
        Notification::NotPermitted { writer, reason } => (
            "NotPermitted",
            json!({"writer": writer.to_string(), "reason": reason}),
        ),
        Notification::SamplesLost { writer, from, to } => (
            "SamplesLost",
            json!({"writer": writer.to_string(), "from": from, "to": to}),
        ),
        Notification::DeserializationError { writer, seq, error } => (
            "DeserializationError",
            json!({"writer": writer.to_string(), "writer_seq": seq, "error": error}),
        ),
    };
    let mut line = json!({
        "event": "notification",
        "topic": topic,
        "kind": kind,
        "unix_us": unix_us(SystemTime::now()),
    });
    if let (Value::Object(line), Value::Object(fields)) = (&mut line, fields) {
        line.extend(fields);
    }
    line
}

/// An `incompatible` line of a producer: a consumer of its topic declared another type.
pub fn incompatible(topic: &str, local_type: &str, other: &EndpointInfo) -> Value {
    json!({
        "event": "incompatible",
        "topic": topic,
        "consumer": other.guid.to_string(),
        "consumer_pid": other.pid,
        "type_name": other.type_desc.name,
        "fingerprint": format!("{:016x}", other.fingerprint),
        "local_type": local_type,
        "unix_us": unix_us(SystemTime::now()),
    })
}

/// The counters of a participant's data socket, as JSON.
pub fn stats(stats: &ParticipantStats) -> Value {
    let dropped: serde_json::Map<String, Value> = stats
        .dropped
        .iter()
        .map(|(name, count)| ((*name).to_owned(), json!(count)))
        .collect();
    json!({
        "received": stats.received,
        "delivered": stats.delivered,
        "misaddressed": stats.misaddressed,
        "unknown_reader": stats.unknown_reader,
        "unmatched_sender": stats.unmatched_sender,
        "wrong_address": stats.wrong_address,
        "unvalidated_feedback": stats.unvalidated_feedback,
        "pieces_withheld": stats.pieces_withheld,
        "dropped": dropped,
        "seal_opened": stats.seal_opened,
        "seal_dropped": stats
            .seal_dropped
            .iter()
            .map(|(name, count)| ((*name).to_owned(), json!(count)))
            .collect::<serde_json::Map<String, Value>>(),
        "unkeyed": stats.unkeyed,
    })
}

//! What every mode sends: the sample type, its size argument, the clocks stamped into it, and
//! the counting of sequence gaps on the receiving side.

use std::sync::OnceLock;
use std::time::{Instant, SystemTime};

use serde::{Deserialize, Serialize};
use serde_bytes::ByteBuf;

/// Largest sample size `ndds perf` sends: the SDK's default maximum less room for the
/// sequence number, the timestamp and the length prefix.
pub const MAX_SIZE: usize = ndds_client::DEFAULT_MAX_SAMPLE - 64;

/// The benchmark's sample. Its size is the size of `payload`; the payload is one byte string,
/// so encoding and decoding it costs one copy however large it is.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PerfSample {
    /// 1, 2, ... per sender; receivers count the gaps.
    pub seq: u64,
    /// The sender's clock in nanoseconds: since the process started (ping, echoed back by
    /// pong), or since the Unix epoch (pub).
    pub sent_ns: u64,
    /// `--size` bytes.
    pub payload: ByteBuf,
}

/// A received [`PerfSample`] read in place: same encoding, but the payload is borrowed from
/// the datagram instead of copied, so receiving costs what the transport costs.
#[derive(Debug, Deserialize)]
pub struct PerfView<'a> {
    pub seq: u64,
    pub sent_ns: u64,
    #[serde(borrow, with = "serde_bytes")]
    pub payload: &'a [u8],
}

impl<'a> PerfView<'a> {
    /// Reads an encoded `PerfSample`; `None` when the bytes are not one.
    pub fn read(bytes: &'a [u8]) -> Option<Self> {
        postcard::from_bytes(bytes).ok()
    }
}

/// The type description `PerfSample` is announced with.
pub fn perf_type() -> ndds_client::TypeDescription {
    ndds_client::TypeDescription::named::<PerfSample>(ndds_core::types::builtin::PERF_SAMPLE)
}

impl PerfSample {
    /// A sample with a payload of `size` bytes (a recognisable pattern, not zeros).
    pub fn with_size(size: usize) -> Self {
        PerfSample {
            seq: 0,
            sent_ns: 0,
            payload: ByteBuf::from(pattern(size)),
        }
    }
}

/// `size` bytes counting up, wrapping at 251 (a prime, so chunks do not repeat in step).
pub fn pattern(size: usize) -> Vec<u8> {
    (0..size).map(|i| (i % 251) as u8).collect()
}

/// A byte count: a plain number, or one with a `k`/`KiB`/`M`/`MiB` suffix (powers of 1024).
pub fn parse_size(text: &str) -> Result<usize, String> {
    let text = text.trim();
    let split = text
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(text.len());
    let (digits, unit) = text.split_at(split);
    let number: usize = digits
        .parse()
        .map_err(|_| format!("{text:?} is not a size in bytes"))?;
    let scale = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1,
        "k" | "kib" | "kb" => 1024,
        "m" | "mib" | "mb" => 1024 * 1024,
        other => return Err(format!("unknown size unit {other:?} (use k or M)")),
    };
    let size = number
        .checked_mul(scale)
        .filter(|size| *size <= MAX_SIZE)
        .ok_or_else(|| format!("{text} is larger than the {MAX_SIZE}-byte limit"))?;
    Ok(size)
}

/// Nanoseconds since this process first asked; monotonic.
pub fn mono_ns() -> u64 {
    static ORIGIN: OnceLock<Instant> = OnceLock::new();
    let origin = ORIGIN.get_or_init(Instant::now);
    u64::try_from(origin.elapsed().as_nanos()).unwrap_or(u64::MAX)
}

/// Nanoseconds since the Unix epoch.
pub fn wall_ns() -> u64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// Counts what arrived from one sender and what its sequence numbers say went missing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Gaps {
    /// The sequence number expected next (0: nothing seen yet).
    next: u64,
    /// Samples skipped by the sequence numbers.
    pub lost: u64,
    /// Samples at or below one already seen (duplicates or reordered).
    pub late: u64,
}

impl Gaps {
    /// Takes the sequence number of an arriving sample.
    pub fn see(&mut self, seq: u64) {
        if self.next == 0 || seq == self.next {
            self.next = seq + 1;
        } else if seq > self.next {
            self.lost += seq - self.next;
            self.next = seq + 1;
        } else {
            self.late += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes() {
        assert_eq!(parse_size("64"), Ok(64));
        assert_eq!(parse_size("8k"), Ok(8192));
        assert_eq!(parse_size("8KiB"), Ok(8192));
        assert_eq!(parse_size("1MiB"), Ok(1 << 20));
        assert_eq!(parse_size("0"), Ok(0));
        assert!(parse_size("16MiB").is_err());
        assert!(parse_size("12x").is_err() && parse_size("").is_err());
    }

    #[test]
    fn gaps_count_missing_and_late_samples() {
        let mut gaps = Gaps::default();
        for seq in [5, 6, 9, 10, 8, 10, 11] {
            gaps.see(seq);
        }
        assert_eq!((gaps.lost, gaps.late), (2, 2));
    }

    #[test]
    fn the_payload_is_one_byte_string() {
        let sample = PerfSample {
            seq: 1,
            sent_ns: 2,
            payload: ByteBuf::from(pattern(300)),
        };
        let bytes = postcard::to_allocvec(&sample).unwrap();
        // seq, sent_ns, a two-byte length prefix and the bytes themselves.
        assert_eq!(bytes.len(), 1 + 1 + 2 + 300);
        assert_eq!(postcard::from_bytes::<PerfSample>(&bytes).unwrap(), sample);
    }
}

//! # ndds-fuzz
//!
//! What the fuzz targets in `src/bin/` share: a reader that turns the fuzzer's bytes into
//! values and operations ([`Input`]), the writer of the same format for the seed corpus
//! ([`Script`]), fixed keys and identities ([`fixture`]), and the two protocol engines driven
//! by scripts of operations ([`discovery`], [`participant`]).
//!
//! Every target is deterministic: the same input takes the same path, so a saved crash
//! replays. Nothing here reads a clock except to take one base `Instant` per input, from
//! which all virtual time is counted.
//!
//! ## Layout
//! - [`Input`], [`Script`]: the operation format (`op byte | u16le length | bytes`).
//! - [`fixture`]: domain, keys, participant ids and addresses of every target.
//! - [`discovery`]: the discovery engine receiving datagrams, in clear or sealed.
//! - [`participant`]: a participant's data plane receiving data and feedback.
//! - [`roundtrip`]: assertions shared by the decoder targets.

pub mod discovery;
pub mod fixture;
pub mod participant;
pub mod roundtrip;

/// A cursor over the fuzzer's bytes. Reading past the end yields zeros and empty slices, so
/// a target never has to decide what a short input means.
#[derive(Clone, Debug)]
pub struct Input<'a> {
    bytes: &'a [u8],
}

impl<'a> Input<'a> {
    /// A cursor at the start of `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        Input { bytes }
    }

    /// True when every byte was read.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The next byte, or 0 at the end.
    pub fn u8(&mut self) -> u8 {
        match self.bytes.split_first() {
            Some((&byte, rest)) => {
                self.bytes = rest;
                byte
            }
            None => 0,
        }
    }

    /// The next two bytes, little-endian.
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()])
    }

    /// The next `len` bytes, or fewer at the end.
    pub fn take(&mut self, len: usize) -> &'a [u8] {
        let (head, rest) = self.bytes.split_at(len.min(self.bytes.len()));
        self.bytes = rest;
        head
    }

    /// A chunk: a u16le length, then up to that many bytes.
    pub fn chunk(&mut self) -> &'a [u8] {
        let len = usize::from(self.u16());
        self.take(len)
    }

    /// Everything not read yet.
    pub fn rest(&mut self) -> &'a [u8] {
        std::mem::take(&mut self.bytes)
    }
}

/// Writes inputs in the format [`Input`] reads, for the seed corpus.
#[derive(Clone, Debug, Default)]
pub struct Script {
    bytes: Vec<u8>,
}

impl Script {
    /// An empty script.
    pub fn new() -> Self {
        Script::default()
    }

    /// Appends one byte.
    pub fn u8(&mut self, byte: u8) -> &mut Self {
        self.bytes.push(byte);
        self
    }

    /// Appends an operation: its code, then its bytes as a chunk.
    pub fn op(&mut self, code: u8, bytes: &[u8]) -> &mut Self {
        let len = u16::try_from(bytes.len()).expect("a chunk is shorter than 64 KiB");
        self.bytes.push(code);
        self.bytes.extend_from_slice(&len.to_le_bytes());
        self.bytes.extend_from_slice(bytes);
        self
    }

    /// The bytes written.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }
}

/// The `main` of every target. Built by `cargo afl build` (`--cfg fuzzing`), it hands
/// `target` to AFL++'s persistent loop, which turns a panic into a crash. Built with plain
/// cargo, it runs `target` once on each file named on the command line (directories: each
/// file in them), so that a saved crash or the whole corpus replays without AFL++:
/// `cargo run --manifest-path fuzz/Cargo.toml --bin data -- fuzz/crashes/data`.
pub fn main(target: fn(&[u8])) {
    #[cfg(fuzzing)]
    afl::fuzz!(|data: &[u8]| target(data));
    #[cfg(not(fuzzing))]
    replay(target);
}

#[cfg(not(fuzzing))]
fn replay(target: fn(&[u8])) {
    let mut files = Vec::new();
    for arg in std::env::args_os().skip(1) {
        let path = std::path::PathBuf::from(arg);
        match std::fs::read_dir(&path) {
            Ok(entries) => {
                let mut inner: Vec<_> = entries.flatten().map(|e| e.path()).collect();
                inner.sort();
                files.extend(inner.into_iter().filter(|p| p.is_file()));
            }
            Err(_) => files.push(path),
        }
    }
    for file in &files {
        let bytes = std::fs::read(file)
            .unwrap_or_else(|err| panic!("cannot read {}: {err}", file.display()));
        println!("{}", file.display());
        target(&bytes);
    }
    println!("{} inputs ran without a panic", files.len());
}

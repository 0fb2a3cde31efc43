//! The datagrams the core asks its driver to send, and the buffers they are built in.

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddrV4;
use std::ops::Range;
use std::sync::Arc;

use crate::seal::{OVERHEAD, Sealer};

/// Head buffers kept for reuse: a driver that recycles what it sent allocates nothing per
/// datagram once this many exist.
const FREE_HEADS: usize = 256;
/// Spare head buffers larger than this (batches, resent whole samples) are kept only up to
/// [`LARGE_HEADS`], so the spares stay small (at most 256 × 8 KiB + 8 × 64 KiB).
const KEPT_HEAD: usize = 8 * 1024;
const LARGE_HEADS: usize = 8;
/// Spare heads made with the first datagram.
const RESERVED_HEADS: usize = 8;
/// A new head buffer holds at least this much.
const MIN_HEAD: usize = 2 * 1024;
/// A payload up to this size is copied after the head instead of sent from its own buffer:
/// copying it costs less than sharing it (a reference count taken and dropped, a second
/// piece for the kernel to gather).
const COPIED_TAIL: usize = 512;

/// One datagram to send: `head` followed by `tail`, which the driver hands to the kernel
/// together (scatter-gather), so a sample's payload is not copied into the datagram (unless
/// it is 512 bytes or less: copying a payload that small costs less than sharing it).
#[derive(Debug)]
pub struct Transmit {
    /// Where it goes.
    pub to: SocketAddrV4,
    head: Vec<u8>,
    tail: Option<(Arc<Vec<u8>>, Range<usize>)>,
}

impl Transmit {
    /// The encoded header and submessages.
    pub fn head(&self) -> &[u8] {
        &self.head
    }

    /// The payload that follows the head (empty for most datagrams).
    pub fn tail(&self) -> &[u8] {
        match &self.tail {
            Some((bytes, range)) => bytes.get(range.clone()).unwrap_or_default(),
            None => &[],
        }
    }

    /// The datagram's size in bytes.
    pub fn len(&self) -> usize {
        self.head.len() + self.tail().len()
    }

    /// True for an empty datagram (never queued).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Drops the reference to the payload (once sent), so its buffer can be reused while
    /// the head waits to be recycled.
    pub fn release_tail(&mut self) {
        self.tail = None;
    }

    /// The whole datagram in one buffer (for tests and simulated networks).
    pub fn to_vec(&self) -> Vec<u8> {
        let mut all = Vec::with_capacity(self.len());
        all.extend_from_slice(&self.head);
        all.extend_from_slice(self.tail());
        all
    }
}

/// The queue of datagrams to send and the spare head buffers.
#[derive(Debug, Default)]
pub(crate) struct Transmits {
    queue: VecDeque<Transmit>,
    free: Vec<Vec<u8>>,
    /// Datagrams and bytes queued so far.
    pub(crate) datagrams: u64,
    pub(crate) bytes: u64,
    /// Seals every datagram (a domain with a key): the payload is then copied after the
    /// head and sealed with it, never shared.
    pub(crate) sealer: Option<Sealer>,
    /// Datagrams not sent because they could not be sealed (a session's counter used up).
    pub(crate) unsealable: u64,
    /// Sealers by destination, with the pair's data key (a domain with permissions).
    pub(crate) pair_sealers: HashMap<SocketAddrV4, Sealer>,
    /// Send only to destinations with a data key (a domain with permissions).
    pub(crate) pairwise: bool,
    /// Datagrams not sent because their destination has no data key.
    pub(crate) unkeyed: u64,
}

impl Transmits {
    /// Queues `head ++ tail` for `to` (the head, and a tail of at most [`COPIED_TAIL`]
    /// bytes, are copied into a spare buffer; a longer tail is shared).
    pub(crate) fn push(
        &mut self,
        to: SocketAddrV4,
        head: &[u8],
        tail: Option<(&Arc<Vec<u8>>, Range<usize>)>,
    ) {
        // The most recently freed spare large enough (a small one would have to grow). A new
        // one is rounded up to a power of two, so heads that grow a little at a time (a batch
        // a few samples longer than any before) do not each need a new buffer.
        if self.pairwise && !self.pair_sealers.contains_key(&to) {
            // Its daemon never gave this pair a key: the document does not allow it.
            self.unkeyed += 1;
            return;
        }
        let sealed = self.sealer.is_some();
        let copied = tail
            .as_ref()
            .filter(|(_, range)| sealed || range.len() <= COPIED_TAIL)
            .map_or(0, |(_, range)| range.len());
        let needed = head.len() + copied + if sealed { OVERHEAD } else { 0 };
        let mut buffer = match self.free.iter().rposition(|b| b.capacity() >= needed) {
            Some(index) => self.free.swap_remove(index),
            None => {
                if self.free.is_empty() && self.datagrams == 0 {
                    // The first datagram: a few spares at once, so that heads a driver
                    // still holds (sent by another thread, not yet recycled) are not
                    // what makes a later push allocate.
                    self.free
                        .extend((0..RESERVED_HEADS).map(|_| Vec::with_capacity(MIN_HEAD)));
                }
                Vec::with_capacity(needed.max(MIN_HEAD).next_power_of_two())
            }
        };
        let sealer = match self.pair_sealers.get_mut(&to) {
            Some(sealer) => Some(sealer),
            None => self.sealer.as_mut(),
        };
        let tail = match sealer {
            // Sealed: head and payload written once, with room for the seal head.
            Some(sealer) => {
                let payload = tail
                    .as_ref()
                    .and_then(|(bytes, range)| bytes.get(range.clone()))
                    .unwrap_or_default();
                if sealer.seal_into(&mut buffer, &[head, payload]).is_err() {
                    self.unsealable += 1;
                    self.free.push(buffer);
                    return;
                }
                None
            }
            None => {
                buffer.clear();
                buffer.extend_from_slice(head);
                match tail {
                    Some((bytes, range)) if range.len() <= COPIED_TAIL => {
                        buffer.extend_from_slice(bytes.get(range).unwrap_or_default());
                        None
                    }
                    tail => tail.map(|(bytes, range)| (Arc::clone(bytes), range)),
                }
            }
        };
        let transmit = Transmit {
            to,
            head: buffer,
            tail,
        };
        self.datagrams += 1;
        self.bytes += transmit.len() as u64;
        self.queue.push_back(transmit);
    }

    pub(crate) fn pop(&mut self) -> Option<Transmit> {
        self.queue.pop_front()
    }

    pub(crate) fn len(&self) -> usize {
        self.queue.len()
    }

    /// Takes a sent datagram's head buffer back (its payload reference is dropped).
    pub(crate) fn recycle(&mut self, transmit: Transmit) {
        if self.free.len() >= FREE_HEADS {
            return;
        }
        if transmit.head.capacity() > KEPT_HEAD
            && self
                .free
                .iter()
                .filter(|b| b.capacity() > KEPT_HEAD)
                .count()
                >= LARGE_HEADS
        {
            return;
        }
        self.free.push(transmit.head);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn to() -> SocketAddrV4 {
        SocketAddrV4::new(std::net::Ipv4Addr::LOCALHOST, 7400)
    }

    #[test]
    fn a_small_payload_is_copied_after_the_head_and_a_large_one_shared() {
        let mut transmits = Transmits::default();
        let small = Arc::new(vec![7u8; COPIED_TAIL]);
        let large = Arc::new(vec![9u8; COPIED_TAIL + 1]);
        transmits.push(to(), b"head", Some((&small, 0..small.len())));
        transmits.push(to(), b"head", Some((&large, 0..large.len())));

        let first = transmits.pop().expect("the small one is queued");
        assert!(first.tail().is_empty());
        assert_eq!(first.head().len(), 4 + COPIED_TAIL);
        assert_eq!(
            Arc::strong_count(&small),
            1,
            "the small payload is not held"
        );

        let second = transmits.pop().expect("the large one is queued");
        assert_eq!(second.head(), b"head");
        assert_eq!(second.tail().len(), COPIED_TAIL + 1);
        assert_eq!(Arc::strong_count(&large), 2, "the large payload is shared");

        let mut expected = b"head".to_vec();
        expected.extend_from_slice(&small);
        assert_eq!(first.to_vec(), expected);
        assert_eq!(first.len(), expected.len());
        assert_eq!(second.len(), 5 + COPIED_TAIL);
    }
}

//! Hostile datagrams: arbitrary bytes never make the decoder panic, and never make it allocate
//! more than the datagram's length justifies. A counting global allocator measures every byte
//! this thread allocates while decoding one input.
//!
//! Also hostile type layouts: deep, self- or forward-referring, or huge claims, which the
//! decoder must survive and `TypeLayout::validate` must reject. The `Data` and `Feedback`
//! parsers get the same treatment in `wire_data/hostile.rs`.

#[path = "support/messages.rs"]
mod messages;
#[path = "support/submessages.rs"]
mod submessages;
#[path = "wire_data/hostile.rs"]
mod wire_data;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::net::SocketAddr;
use std::time::Instant;

use ndds_core::discovery::{DiscoveryConfig, Engine, Event, Via};
use ndds_core::types::layout::MAX_FORMATS;
use ndds_core::types::{
    Container, ContainerShape, Field, Format, LayoutError, TypeDescription, TypeLayout,
};
use ndds_core::wire::{
    self, Announce, DropReason, EndpointInfo, EndpointQos, Guid, HEADER_LEN, Header, Locator,
    MAX_DATAGRAM, Message, MessageKind, NodeInfo, ProducerQosWire,
};
use proptest::collection::vec;
use proptest::prelude::*;

// ----- counting allocator ------------------------------------------------------------------

/// Wraps the system allocator and counts, per thread, the bytes currently allocated, their
/// high-water mark and the sum of every allocation.
struct CountingAllocator;

thread_local! {
    // `const` initialisers without destructors: no lazy initialisation and no registration,
    // so touching them from inside the allocator cannot allocate or recurse.
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
    static TOTAL: Cell<usize> = const { Cell::new(0) };
}

fn note_alloc(size: usize) {
    let _ = LIVE.try_with(|live| {
        live.set(live.get() + size as isize);
        let _ = PEAK.try_with(|peak| peak.set(peak.get().max(live.get())));
    });
    let _ = TOTAL.try_with(|total| total.set(total.get() + size));
}

fn note_dealloc(size: usize) {
    let _ = LIVE.try_with(|live| live.set(live.get() - size as isize));
}

/// A reallocation is counted as a new block while the old one is still live (the worst case,
/// when the block moves), then the old block is released.
fn note_realloc(old: usize, new: usize) {
    note_alloc(new);
    note_dealloc(old);
}

// SAFETY: every method forwards to `System` with the caller's arguments unchanged; the
// bookkeeping only touches `Cell`s of this thread and never allocates.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded contract.
        let ptr = unsafe { System.alloc(layout) };
        if !ptr.is_null() {
            note_alloc(layout.size());
        }
        ptr
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded contract.
        let ptr = unsafe { System.alloc_zeroed(layout) };
        if !ptr.is_null() {
            note_alloc(layout.size());
        }
        ptr
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded contract.
        unsafe { System.dealloc(ptr, layout) };
        note_dealloc(layout.size());
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: forwarded contract.
        let new = unsafe { System.realloc(ptr, layout, new_size) };
        if !new.is_null() {
            note_realloc(layout.size(), new_size);
        }
        new
    }
}

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Bytes allocated by this thread while running one closure.
#[derive(Clone, Copy, Debug)]
struct Usage {
    /// Highest amount live at once, above what was live before (includes the result).
    peak: usize,
    /// Sum of all allocations.
    total: usize,
}

fn measure<R>(f: impl FnOnce() -> R) -> (R, Usage) {
    let base = LIVE.with(Cell::get);
    PEAK.with(|peak| peak.set(base));
    let total_before = TOTAL.with(Cell::get);
    let result = f();
    let usage = Usage {
        peak: (PEAK.with(Cell::get) - base).max(0) as usize,
        total: TOTAL.with(Cell::get) - total_before,
    };
    (result, usage)
}

/// What decoding `len` bytes may allocate, at peak and in total.
///
/// Measured by `densest_inputs_stay_within_the_budget`. The most memory per input byte comes
/// from a layout's container list made of empty-named unit structs: 2 input bytes each, 56
/// bytes each as a `Container`. The bounded vector doubles its capacity as elements arrive, so
/// up to 2 × 56 bytes are reserved per 2 input bytes (56 per byte); a reallocation briefly
/// holds the old block too (counted as such above), so the peak reaches 3/2 × 56 = 84 bytes per
/// input byte, and the sum of all the blocks of the growth (4 + 8 + … + 2n elements, about 4n)
/// reaches 2 × 56 = 112. One-byte `Format::Unit` nodes (24 bytes each) come next at 72 and 96.
/// The constant covers tiny datagrams, where each vector starts with room for a few elements.
fn budget(len: usize) -> usize {
    128 * len + 4096
}

fn decode_within_budget(bytes: &[u8]) -> Result<MessageKind, DropReason> {
    let (result, usage) = measure(|| wire::decode(bytes));
    assert!(
        usage.peak <= budget(bytes.len()) && usage.total <= budget(bytes.len()),
        "decoding {} bytes allocated {usage:?} (budget {})",
        bytes.len(),
        budget(bytes.len())
    );
    result.map(|(header, message)| {
        assert_eq!(header.kind, message.kind());
        header.kind
    })
}

// ----- arbitrary bytes ---------------------------------------------------------------------

fn header_bytes(kind: u8, domain: u16, sender: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN);
    out.extend_from_slice(&wire::MAGIC);
    out.push(wire::PROTOCOL_VERSION);
    out.push(kind);
    out.extend_from_slice(&domain.to_le_bytes());
    out.extend_from_slice(&sender.to_le_bytes());
    out
}

/// One of the kinds this version knows, followed by random body bytes.
fn valid_header_then_noise() -> impl Strategy<Value = Vec<u8>> {
    (
        messages::kind(),
        any::<u16>(),
        any::<u64>(),
        vec(any::<u8>(), 0..1024),
    )
        .prop_map(|(kind, domain, sender, body)| {
            let mut bytes = header_bytes(kind as u8, domain, sender);
            bytes.extend_from_slice(&body);
            bytes
        })
}

/// A valid datagram with a few bytes overwritten, inserted or removed.
fn mutated_datagram() -> impl Strategy<Value = Vec<u8>> {
    (
        messages::datagram(),
        vec((any::<usize>(), any::<u8>(), 0..3u8), 1..6),
    )
        .prop_map(|(d, edits)| {
            let mut bytes = d.encode();
            for (at, value, op) in edits {
                // Keep the header so the body decoder is reached.
                let at = HEADER_LEN + at % (bytes.len() - HEADER_LEN + 1);
                match op {
                    0 if at < bytes.len() => bytes[at] = value,
                    1 => bytes.insert(at, value),
                    _ if at < bytes.len() => {
                        bytes.remove(at);
                    }
                    _ => bytes.push(value),
                }
            }
            bytes
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2048))]

    #[test]
    fn arbitrary_bytes_never_panic_nor_overallocate(bytes in vec(any::<u8>(), 0..2048)) {
        let _ = decode_within_budget(&bytes);
        let _ = wire::decode_for_domain(&bytes, 0);
    }

    /// Discovery kinds decode as themselves or not at all; `Data` and `Feedback` bodies (and
    /// `Signed` envelopes, which the engine opens first) are never decoded by `wire::decode`.
    #[test]
    fn valid_header_then_noise_never_panics_nor_overallocates(bytes in valid_header_then_noise()) {
        let expected = MessageKind::from_u8(bytes[5]).unwrap();
        match decode_within_budget(&bytes) {
            Ok(kind) => prop_assert_eq!(kind, expected),
            Err(DropReason::Unexpected) => {
                prop_assert!(matches!(
                    expected,
                    MessageKind::Data | MessageKind::Feedback | MessageKind::Signed
                ));
            }
            Err(reason) => prop_assert_eq!(reason, DropReason::Malformed),
        }
        if matches!(expected, MessageKind::Data | MessageKind::Feedback | MessageKind::Signed) {
            prop_assert_eq!(decode_within_budget(&bytes), Err(DropReason::Unexpected));
        }
    }

    /// A `Signed` envelope of noise never panics, and verifies only with a true signature.
    #[test]
    fn signed_noise_never_verifies(body in vec(any::<u8>(), 0..1024), sender in any::<u64>()) {
        let mut bytes = header_bytes(MessageKind::Signed as u8, 0, sender);
        bytes.extend_from_slice(&body);
        if let Ok(view) = wire::signed::parse(&bytes) {
            prop_assert!(view.verify().is_err());
        }
    }

    #[test]
    fn mutated_datagrams_never_panic_nor_overallocate(bytes in mutated_datagram()) {
        let _ = decode_within_budget(&bytes);
    }

    #[test]
    fn valid_datagrams_stay_within_the_budget(d in messages::datagram()) {
        let bytes = d.encode();
        prop_assert!(decode_within_budget(&bytes).is_ok());
    }

    /// The engine counts every datagram exactly once, as accepted or dropped.
    #[test]
    fn the_engine_survives_noise(inputs in vec(valid_header_then_noise(), 1..16)) {
        let now = Instant::now();
        let mut engine = Engine::new(DiscoveryConfig::new(0, locator(1)), now).unwrap();
        for bytes in &inputs {
            let mut bytes = bytes.clone();
            bytes[6..8].copy_from_slice(&0u16.to_le_bytes());
            engine.handle_datagram(now, from(), Via::Unicast, &bytes);
        }
        let stats = engine.stats();
        prop_assert_eq!(stats.received, inputs.len() as u64);
        prop_assert_eq!(stats.accepted + stats.dropped.iter().sum::<u64>(), stats.received);
    }
}

// ----- hand-written hostile datagrams --------------------------------------------------------

/// Varint of `u32::MAX`.
const CLAIM_U32_MAX: [u8; 5] = [0xFF, 0xFF, 0xFF, 0xFF, 0x0F];
/// Varint of 2^64 - 1 (the largest length a 64-bit postcard decoder reads).
const CLAIM_U64_MAX: [u8; 10] = [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x01];

fn datagram(kind: MessageKind, body: &[&[u8]]) -> Vec<u8> {
    let mut bytes = header_bytes(kind as u8, 0, 1);
    for part in body {
        bytes.extend_from_slice(part);
    }
    bytes
}

#[test]
fn tiny_datagrams_claiming_huge_vectors_are_malformed_and_cheap() {
    let cases = [
        // Withdraw: u32::MAX guids, then one guid.
        datagram(MessageKind::Withdraw, &[&CLAIM_U32_MAX, &[1, 1]]),
        datagram(MessageKind::Withdraw, &[&CLAIM_U64_MAX, &[1, 1]]),
        // Announce: empty NodeInfo fields, then u32::MAX endpoints.
        datagram(MessageKind::Announce, &[&[0; 10], &CLAIM_U32_MAX]),
    ];
    for bytes in &cases {
        assert_eq!(decode_within_budget(bytes), Err(DropReason::Malformed));
        // At most the first few elements that actually follow the claim.
        let (_, usage) = measure(|| wire::decode(bytes));
        assert!(usage.peak <= 256, "{} bytes: {usage:?}", bytes.len());
    }
}

#[test]
fn strings_and_payloads_claiming_gigabytes_are_malformed_and_cheap() {
    let cases = [
        // Solicit whose host name claims 4 GiB.
        datagram(MessageKind::Solicit, &[&CLAIM_U32_MAX, b"host"]),
        datagram(MessageKind::Solicit, &[&CLAIM_U64_MAX, b"host"]),
    ];
    for bytes in &cases {
        assert_eq!(decode_within_budget(bytes), Err(DropReason::Malformed));
        let (_, usage) = measure(|| wire::decode(bytes));
        assert_eq!(usage.peak, 0, "{} bytes: {usage:?}", bytes.len());
    }
}

#[test]
fn densest_inputs_stay_within_the_budget() {
    // Element counts just past a power of two, where vector growth has reserved the most.
    let units = layout(vec![Format::Unit; (1 << 14) + 1], 0, vec![]);
    let unit_struct = Container {
        name: String::new(),
        shape: ContainerShape::UnitStruct,
    };
    let unit_structs = layout(vec![Format::Unit], 0, vec![unit_struct; (1 << 12) + 1]);
    let empty_tuples = layout(vec![Format::Tuple(vec![]); (1 << 13) + 1], 0, vec![]);
    let many_guids = Message::Withdraw(wire::Withdraw {
        endpoints: vec![
            Guid {
                participant: 0,
                entity: 0
            };
            (1 << 14) + 1
        ],
    });
    let mut worst: f64 = 0.0;
    for message in [
        announce_one(units),
        announce_one(unit_structs),
        announce_one(empty_tuples),
        many_guids,
    ] {
        let bytes = encode(&message);
        assert!(bytes.len() < MAX_DATAGRAM);
        let (result, usage) = measure(|| wire::decode(&bytes));
        assert!(result.is_ok());
        assert!(
            usage.peak <= budget(bytes.len()) && usage.total <= budget(bytes.len()),
            "{} bytes: {usage:?}",
            bytes.len()
        );
        worst = worst.max(usage.total as f64 / bytes.len() as f64);
    }
    // The budget is not loose either: the densest input comes close to it.
    assert!(worst > 100.0, "worst case {worst:.1} bytes per input byte");
}

// ----- hostile layouts -----------------------------------------------------------------------

fn layout(formats: Vec<Format>, root: u32, containers: Vec<Container>) -> TypeLayout {
    TypeLayout {
        formats,
        root,
        containers,
    }
}

fn endpoint_with(layout: TypeLayout) -> EndpointInfo {
    let type_desc = TypeDescription {
        name: "hostile".to_owned(),
        layout: Some(layout),
    };
    EndpointInfo {
        guid: Guid {
            participant: 7,
            entity: 1,
        },
        topic: "hostile".to_owned(),
        // Not `type_desc.fingerprint()`: computing it is what some of these layouts attack.
        fingerprint: 0,
        type_desc,
        qos: EndpointQos::Producer(ProducerQosWire::default()),
        locator: locator(9),
        pid: 1,
        process: "p".to_owned(),
    }
}

fn announce_one(layout: TypeLayout) -> Message {
    Message::Announce(Announce {
        node: NodeInfo {
            hostname: "evil".to_owned(),
            pid: 1,
            unicast: locator(9),
            lease_ms: 5000,
            announce_period_ms: 1000,
            version: String::new(),
        },
        endpoints: vec![endpoint_with(layout)],
        withdrawn: vec![],
    })
}

fn encode(message: &Message) -> Vec<u8> {
    let mut out = Vec::new();
    wire::encode(0, 0xE1, message, &mut out).unwrap();
    out
}

/// Decodes an announcement of one endpoint and returns that endpoint's layout.
fn decoded_layout(bytes: &[u8]) -> TypeLayout {
    match wire::decode(bytes) {
        Ok((_, Message::Announce(mut announce))) => {
            announce.endpoints.remove(0).type_desc.layout.unwrap()
        }
        other => panic!("not an announcement: {other:?}"),
    }
}

fn locator(host: u8) -> Locator {
    Locator {
        addr: [10, 0, 0, host],
        port: 7400,
    }
}

fn from() -> SocketAddr {
    "10.0.0.9:7400".parse().unwrap()
}

/// Feeds `bytes` to a fresh engine and checks that the endpoint was refused.
fn assert_engine_refuses(bytes: &[u8]) {
    let now = Instant::now();
    let mut engine = Engine::new(DiscoveryConfig::new(0, locator(1)), now).unwrap();
    engine.handle_datagram(now, from(), Via::Unicast, bytes);
    assert_eq!(engine.stats().accepted, 1);
    assert_eq!(engine.stats().invalid_endpoints, 1);
    assert_eq!(engine.endpoints().count(), 0);
    let events: Vec<Event> = std::iter::from_fn(|| engine.poll_event()).collect();
    assert!(
        events
            .iter()
            .all(|e| matches!(e, Event::NodeDiscovered { .. })),
        "{events:?}"
    );
}

/// `U8, Option(0), Option(1), …`: `depth` options around a `u8`.
fn option_chain(depth: usize) -> TypeLayout {
    let mut formats = vec![Format::U8];
    formats.extend((0..depth as u32).map(Format::Option));
    layout(formats, depth as u32, vec![])
}

#[test]
fn deep_option_chains_decode_without_recursion_and_are_rejected() {
    for (depth, expected) in [
        (3000, LayoutError::TooDeep),
        (MAX_FORMATS, LayoutError::TooManyFormats(MAX_FORMATS + 1)),
    ] {
        let bytes = encode(&announce_one(option_chain(depth)));
        assert!(bytes.len() <= MAX_DATAGRAM);
        let _ = decode_within_budget(&bytes);
        let decoded = decoded_layout(&bytes);
        assert_eq!(decoded.formats.len(), depth + 1);
        assert_eq!(decoded.validate(), Err(expected));
        assert_engine_refuses(&bytes);
    }
    // The limit itself: 31 options around a u8 is 32 levels, accepted.
    option_chain(31).validate().unwrap();
    assert_eq!(option_chain(32).validate(), Err(LayoutError::TooDeep));
}

#[test]
fn self_forward_and_dangling_references_are_rejected() {
    let named = |name: &str, shape| Container {
        name: name.to_owned(),
        shape,
    };
    let cases: Vec<(TypeLayout, LayoutError)> = vec![
        (
            layout(vec![Format::Option(0)], 0, vec![]),
            LayoutError::BadChild { node: 0, child: 0 },
        ),
        (
            layout(vec![Format::Seq(1), Format::U8], 0, vec![]),
            LayoutError::BadChild { node: 0, child: 1 },
        ),
        (
            layout(
                vec![Format::U8, Format::Map { key: 0, value: 1 }],
                1,
                vec![],
            ),
            LayoutError::BadChild { node: 1, child: 1 },
        ),
        (
            layout(
                vec![Format::U8, Format::Tuple(vec![0, u32::MAX])],
                1,
                vec![],
            ),
            LayoutError::BadChild {
                node: 1,
                child: u32::MAX,
            },
        ),
        (
            layout(vec![Format::Array { item: 5, len: 2 }], 0, vec![]),
            LayoutError::BadChild { node: 0, child: 5 },
        ),
        (
            layout(
                vec![Format::Array {
                    item: 0,
                    len: u32::MAX,
                }],
                0,
                vec![],
            ),
            LayoutError::ArrayTooLong(u32::MAX),
        ),
        (
            layout(vec![Format::Named(0)], 0, vec![]),
            LayoutError::BadContainer(0),
        ),
        (layout(vec![Format::U8], 1, vec![]), LayoutError::BadRoot(1)),
        (layout(vec![], 0, vec![]), LayoutError::BadRoot(0)),
        (
            layout(
                vec![Format::U8],
                0,
                vec![named(
                    "S",
                    ContainerShape::Struct(vec![Field {
                        name: "f".to_owned(),
                        format: 1,
                    }]),
                )],
            ),
            LayoutError::BadChild { node: 1, child: 1 },
        ),
        (
            layout(
                vec![Format::U8],
                0,
                vec![
                    named("B", ContainerShape::UnitStruct),
                    named("A", ContainerShape::UnitStruct),
                ],
            ),
            LayoutError::UnsortedContainers("A".to_owned()),
        ),
        (
            layout(
                vec![Format::U8],
                0,
                vec![
                    named("A", ContainerShape::UnitStruct),
                    named("A", ContainerShape::UnitStruct),
                ],
            ),
            LayoutError::UnsortedContainers("A".to_owned()),
        ),
    ];
    for (bad, expected) in cases {
        let bytes = encode(&announce_one(bad.clone()));
        let decoded = decoded_layout(&bytes);
        assert_eq!(decoded, bad);
        assert_eq!(decoded.validate(), Err(expected), "{bad:?}");
        assert_engine_refuses(&bytes);
    }
}

/// `U8, Tuple(0, 0), Tuple(1, 1), …`: every level refers twice to the level below, so the
/// canonical text doubles with each of the `depth` levels while the layout grows by 4 bytes.
fn doubling_tuples(depth: u32) -> TypeLayout {
    let mut formats = vec![Format::U8];
    formats.extend((0..depth).map(|i| Format::Tuple(vec![i, i])));
    layout(formats, depth, vec![])
}

#[test]
fn validate_rejects_layouts_whose_canonical_text_explodes() {
    // 30 levels of doubling: 31 formats, depth 31 (under MAX_FORMAT_DEPTH), ~130 bytes on the
    // wire, 2^30 `u8` leaves in the canonical text. Only validate() is called here, so this
    // test fails fast instead of exhausting memory.
    let hostile = doubling_tuples(30);
    assert!(postcard::to_allocvec(&hostile).unwrap().len() < 200);
    assert!(
        hostile.validate().is_err(),
        "a layout whose canonical text has 2^30 leaves passed validate()"
    );
}

#[test]
fn the_engine_handles_an_exploding_layout_in_bounded_memory() {
    // 20 levels keep this test fast (a ~10 MB string); 30 levels would need ~10 GB.
    let bytes = encode(&announce_one(doubling_tuples(20)));
    let now = Instant::now();
    let mut engine = Engine::new(DiscoveryConfig::new(0, locator(1)), now).unwrap();
    let ((), usage) = measure(|| engine.handle_datagram(now, from(), Via::Unicast, &bytes));
    assert!(
        usage.peak <= budget(bytes.len()),
        "a {}-byte datagram made the engine allocate {usage:?}",
        bytes.len()
    );
}

#[test]
fn canonical_text_of_doubling_tuples_grows_exponentially() {
    // Documents the amplification the two tests above guard against, at a harmless size.
    let small = TypeDescription {
        name: String::new(),
        layout: Some(doubling_tuples(4)),
    };
    small.layout.as_ref().unwrap().validate().unwrap();
    let text = small.canonical_text();
    assert_eq!(text.matches("u8").count(), 16);
    assert!(text.starts_with("root=tuple<tuple<tuple<tuple<u8,u8>,"));
}

// ----- arbitrary decoded layouts -------------------------------------------------------------

/// A raw format node: a tag and numbers that become child indices, lengths or containers.
fn raw_format() -> impl Strategy<Value = (u8, u32, u32, Vec<u32>)> {
    (0u8..23, any::<u32>(), any::<u32>(), vec(any::<u32>(), 0..3))
}

/// Builds format node `node` from raw numbers. With `wrap`, child indices are reduced below
/// `node` (leaves where that is impossible) and containers below `containers`, so the layout
/// is valid by construction; without it they stay arbitrary.
fn make_format(
    node: usize,
    containers: usize,
    (tag, a, b, items): (u8, u32, u32, Vec<u32>),
    wrap: bool,
) -> Format {
    let child = |x: u32| if wrap { x % node as u32 } else { x };
    let leaves = [
        Format::Unit,
        Format::Bool,
        Format::I8,
        Format::I16,
        Format::I32,
        Format::I64,
        Format::I128,
        Format::U8,
        Format::U16,
        Format::U32,
        Format::U64,
        Format::U128,
        Format::F32,
        Format::F64,
        Format::Char,
        Format::Str,
        Format::Bytes,
    ];
    if let Some(leaf) = leaves.get(tag as usize) {
        return leaf.clone();
    }
    if wrap && node == 0 && tag != 22 {
        return Format::Str;
    }
    match tag {
        17 => Format::Option(child(a)),
        18 => Format::Seq(child(a)),
        19 => Format::Map {
            key: child(a),
            value: child(b),
        },
        20 => Format::Tuple(items.into_iter().map(child).collect()),
        21 => Format::Array {
            item: child(a),
            len: if wrap { b % 1000 } else { b },
        },
        _ if wrap && containers == 0 => Format::Unit,
        _ => Format::Named(if wrap {
            a % containers.max(1) as u32
        } else {
            a
        }),
    }
}

fn make_layout(
    raw: Vec<(u8, u32, u32, Vec<u32>)>,
    names: Vec<String>,
    root: u32,
    wrap: bool,
) -> TypeLayout {
    let mut names = names;
    names.sort();
    names.dedup();
    let count = raw.len() as u32;
    let containers: Vec<Container> = names
        .into_iter()
        .zip(&raw)
        .map(|(name, (_, a, b, items))| Container {
            name,
            shape: match a % 3 {
                0 => ContainerShape::UnitStruct,
                1 => ContainerShape::NewType(if wrap { b % count } else { *b }),
                _ => ContainerShape::Struct(
                    items
                        .iter()
                        .map(|x| Field {
                            name: format!("f{x}"),
                            format: if wrap { x % count } else { *x },
                        })
                        .collect(),
                ),
            },
        })
        .collect();
    let formats = raw
        .into_iter()
        .enumerate()
        .map(|(node, r)| make_format(node, containers.len(), r, wrap))
        .collect();
    TypeLayout {
        formats,
        root: if wrap { root % count } else { root },
        containers,
    }
}

/// Checks what a validated layout promises: canonical text and fingerprint are computed
/// without panicking, have the documented shape, and survive a trip over the wire.
fn check_validated(layout: &TypeLayout) -> Result<(), TestCaseError> {
    let desc = TypeDescription {
        name: "t".to_owned(),
        layout: Some(layout.clone()),
    };
    let text = desc.canonical_text();
    prop_assert!(text.starts_with("root="));
    prop_assert!(text.ends_with(';'));
    prop_assert_eq!(text.matches(";\"").count(), layout.containers.len());
    let bytes = postcard::to_allocvec(&desc).unwrap();
    let back: TypeDescription = postcard::from_bytes(&bytes).unwrap();
    prop_assert_eq!(back.fingerprint(), desc.fingerprint());
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1024))]

    /// Layouts built valid (children precede parents, at most 10 nodes so that the canonical
    /// text stays small) pass `validate` and can be fingerprinted.
    #[test]
    fn valid_layouts_validate_and_fingerprint(
        raw in vec(raw_format(), 1..10),
        names in vec("[A-Za-z\"\\\\é]{1,6}", 0..4),
        root in any::<u32>(),
    ) {
        let layout = make_layout(raw, names, root, true);
        prop_assert_eq!(layout.validate(), Ok(()));
        check_validated(&layout)?;
    }

    /// Layouts with arbitrary indices either fail `validate` or can be fingerprinted.
    #[test]
    fn arbitrary_layouts_are_rejected_or_fingerprinted(
        raw in vec(raw_format(), 1..10),
        names in vec("[A-Z]{1,3}", 0..4),
        root in 0u32..12,
    ) {
        let layout = make_layout(raw, names, root, false);
        if layout.validate().is_ok() {
            check_validated(&layout)?;
        }
    }

    /// Layouts decoded from arbitrary bytes, likewise.
    #[test]
    fn layouts_decoded_from_noise_are_rejected_or_fingerprinted(
        bytes in vec(any::<u8>(), 0..256),
    ) {
        let (decoded, usage) = measure(|| postcard::from_bytes::<TypeLayout>(&bytes));
        prop_assert!(usage.peak <= budget(bytes.len()), "{:?}", usage);
        if let Ok(layout) = decoded
            && layout.validate().is_ok()
        {
            check_validated(&layout)?;
        }
    }
}

#[test]
fn a_header_alone_is_parsed_without_a_body() {
    // Sanity check of the helper used above: our hand-built header is the real one.
    let bytes = header_bytes(MessageKind::Bye as u8, 5, 6);
    let (header, body) = Header::parse(&bytes).unwrap();
    assert_eq!(
        (header.kind, header.domain, header.sender),
        (MessageKind::Bye, 5, 6)
    );
    assert!(body.is_empty());
}

#[test]
fn a_node_cannot_flood_the_engine_with_endpoints() {
    use ndds_core::discovery::engine::MAX_ENDPOINTS_PER_NODE;
    let now = Instant::now();
    let mut engine = Engine::new(DiscoveryConfig::new(0, locator(1)), now).unwrap();
    let mut template = endpoint_with(layout(vec![Format::U8], 0, vec![]));
    template.fingerprint = template.type_desc.fingerprint();
    let flood = MAX_ENDPOINTS_PER_NODE + 100;
    for chunk in (0..flood).collect::<Vec<_>>().chunks(500) {
        let endpoints = chunk
            .iter()
            .map(|i| {
                let mut info = template.clone();
                info.guid.participant = 1000 + *i as u64;
                info
            })
            .collect();
        let Message::Announce(mut announce) = announce_one(layout(vec![Format::U8], 0, vec![]))
        else {
            unreachable!()
        };
        announce.endpoints = endpoints;
        engine.handle_datagram(
            now,
            from(),
            Via::Unicast,
            &encode(&Message::Announce(announce)),
        );
    }
    assert_eq!(engine.endpoints().count(), MAX_ENDPOINTS_PER_NODE);
    assert_eq!(engine.stats().invalid_endpoints, 100);
}

#[test]
fn nodes_with_unusable_unicast_locators_or_timers_are_invalid() {
    let now = Instant::now();
    let mut engine = Engine::new(DiscoveryConfig::new(0, locator(1)), now).unwrap();
    let Message::Announce(valid) = announce_one(layout(vec![Format::U8], 0, vec![])) else {
        unreachable!()
    };
    let mut broken = Vec::new();
    for edit in [
        |n: &mut NodeInfo| n.unicast.addr = [0; 4],
        |n: &mut NodeInfo| n.unicast.port = 0,
        |n: &mut NodeInfo| n.announce_period_ms = 0,
        |n: &mut NodeInfo| n.lease_ms = n.announce_period_ms,
        |n: &mut NodeInfo| {
            n.announce_period_ms = 3_000_000;
            n.lease_ms = 4_000_000;
        },
    ] {
        let mut announce = valid.clone();
        edit(&mut announce.node);
        broken.push(encode(&Message::Announce(announce)));
    }
    for bytes in &broken {
        engine.handle_datagram(now, from(), Via::Unicast, bytes);
    }
    assert_eq!(
        engine.stats().dropped(DropReason::Invalid),
        broken.len() as u64
    );
    assert_eq!(engine.nodes().count(), 0);
    assert_eq!(engine.endpoints().count(), 0);
}

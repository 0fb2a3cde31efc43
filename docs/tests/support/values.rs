//! Every value section 13 of `docs/protocol.md` documents, as the code has it today.
//!
//! Public constants are read directly. Limits that are private to `ndds-core` are observed
//! through its public behaviour (configuration validation, the datagrams the discovery engine
//! produces), so the document cannot drift from them either.

use std::net::Ipv4Addr;
use std::time::{Duration, Instant};

use ndds_core::discovery::engine::{
    MAX_ENDPOINTS_PER_NODE, MAX_LEASE, MAX_NODES, MAX_PENDING_REPLIES, MAX_REMOTE_BYTES,
    MAX_REMOTE_ENDPOINTS, NODE_OVERHEAD, PROBE_INTERVAL,
};
use ndds_core::discovery::fanout::unicast_window;
use ndds_core::discovery::{DiscoveryConfig, Engine, MAX_PEERS, MAX_TOPIC_LEN};
use ndds_core::types::TypeDescription;
use ndds_core::types::layout::{
    MAX_ARRAY_LEN, MAX_EXPANDED_FORMATS, MAX_FORMAT_DEPTH, MAX_FORMATS,
};
use ndds_core::wire::data::{FLAG_RELIABLE, FRAGMENT_OVERHEAD, MAX_READERS, SAMPLE_OVERHEAD};
use ndds_core::wire::feedback::MAX_BITMAP_BYTES;
use ndds_core::wire::{
    self, EndpointInfo, EndpointQos, Guid, HEADER_LEN, Locator, MAGIC, MAX_DATAGRAM, Message,
    PROTOCOL_VERSION, ProducerQosWire,
};
use ndds_core::{domain, dynamic, ipc};

/// `(name as written in the table's first column, value as written in its second)`.
pub fn expected() -> Vec<(&'static str, String)> {
    let config = DiscoveryConfig::new(0, locator(40000));
    let daemon = ndds_daemon::ConfigFile::default()
        .resolve()
        .expect("the daemon's defaults resolve");
    let engine = engine_limits();
    vec![
        ("MAGIC", String::from_utf8_lossy(&MAGIC).into_owned()),
        ("PROTOCOL_VERSION", PROTOCOL_VERSION.to_string()),
        ("HEADER_LEN", HEADER_LEN.to_string()),
        ("MAX_DATAGRAM", MAX_DATAGRAM.to_string()),
        ("MAX_READERS", MAX_READERS.to_string()),
        ("FLAG_RELIABLE", FLAG_RELIABLE.to_string()),
        ("SAMPLE_OVERHEAD", SAMPLE_OVERHEAD.to_string()),
        ("FRAGMENT_OVERHEAD", FRAGMENT_OVERHEAD.to_string()),
        ("MAX_BITMAP_BYTES", MAX_BITMAP_BYTES.to_string()),
        ("MAX_DOMAIN", domain::MAX_DOMAIN.to_string()),
        ("BASE_PORT", domain::BASE_PORT.to_string()),
        ("UNICAST_BASE_PORT", domain::UNICAST_BASE_PORT.to_string()),
        ("announce_period", duration(config.announce_period)),
        ("lease", duration(config.lease)),
        ("solicit_delays", durations(&config.solicit_delays)),
        ("reply_jitter", duration(config.reply_jitter)),
        ("period_jitter", config.period_jitter.to_string()),
        ("withdraw_repeats", config.withdraw_repeats.to_string()),
        ("announce_chunk", config.announce_chunk.to_string()),
        ("unicast_window", duration(unicast_window(&config))),
        ("MAX_TOPIC_LEN", MAX_TOPIC_LEN.to_string()),
        ("MAX_NODES", MAX_NODES.to_string()),
        ("MAX_ENDPOINTS_PER_NODE", MAX_ENDPOINTS_PER_NODE.to_string()),
        ("MAX_REMOTE_ENDPOINTS", MAX_REMOTE_ENDPOINTS.to_string()),
        ("MAX_REMOTE_BYTES", MAX_REMOTE_BYTES.to_string()),
        ("NODE_OVERHEAD", NODE_OVERHEAD.to_string()),
        ("MAX_PENDING_REPLIES", MAX_PENDING_REPLIES.to_string()),
        ("MAX_LEASE", duration(MAX_LEASE)),
        ("PROBE_INTERVAL", duration(PROBE_INTERVAL)),
        ("MAX_PEERS", MAX_PEERS.to_string()),
        (
            "WITHDRAWN_PER_DATAGRAM",
            engine.withdrawn_per_announce.to_string(),
        ),
        ("guids per Withdraw", engine.guids_per_withdraw.to_string()),
        ("MIN_CHUNK", chunk_bounds().0.to_string()),
        ("MAX_CHUNK", chunk_bounds().1.to_string()),
        ("MAX_DELAY", duration(max_delay())),
        ("period_jitter bound", jitter_bound()),
        ("MAX_FORMAT_DEPTH", MAX_FORMAT_DEPTH.to_string()),
        ("MAX_FORMATS", MAX_FORMATS.to_string()),
        ("MAX_ARRAY_LEN", MAX_ARRAY_LEN.to_string()),
        ("MAX_EXPANDED_FORMATS", MAX_EXPANDED_FORMATS.to_string()),
        ("MAX_DEPTH", dynamic::MAX_DEPTH.to_string()),
        ("BASE_VALUES", dynamic::BASE_VALUES.to_string()),
        ("VALUES_PER_BYTE", dynamic::VALUES_PER_BYTE.to_string()),
        ("IPC_VERSION", ipc::IPC_VERSION.to_string()),
        ("FRAME_PREFIX", ipc::FRAME_PREFIX.to_string()),
        ("MAX_FRAME", ipc::MAX_FRAME.to_string()),
        ("OUTBOX", ndds_daemon::connection::OUTBOX.to_string()),
        (
            "MAX_CLIENT_FRAME",
            ndds_daemon::connection::MAX_CLIENT_FRAME.to_string(),
        ),
        ("GRAPH_PAGE", ndds_daemon::driver::GRAPH_PAGE.to_string()),
        (
            "GRAPH_PAGE_BYTES",
            ndds_daemon::driver::GRAPH_PAGE_BYTES.to_string(),
        ),
        (
            "MAX_BACKLOG_ANSWERS",
            ndds_daemon::driver::MAX_BACKLOG_ANSWERS.to_string(),
        ),
        ("SLOW_CLIENT", duration(ndds_daemon::driver::SLOW_CLIENT)),
        ("interface", daemon.interface.to_string()),
        ("unicast_port", unicast_port_default(&daemon)),
        ("multicast", daemon.multicast.to_string()),
        ("peers", peers_default(&daemon)),
        ("multicast_ttl", daemon.ttl.to_string()),
    ]
}

/// The default unicast port as the document writes it: `UNICAST_BASE_PORT + domain`.
fn unicast_port_default(daemon: &ndds_daemon::DaemonConfig) -> String {
    assert_eq!(
        daemon.unicast_port, None,
        "the default unicast port follows the domain"
    );
    let resolved = |d: u32| {
        let config = ndds_daemon::ConfigFile {
            domain: Some(d),
            ..Default::default()
        }
        .resolve()
        .expect("the daemon's defaults resolve");
        (config.unicast_port, domain::unicast_port(config.domain))
    };
    assert_eq!(resolved(9), (None, domain::UNICAST_BASE_PORT + 9));
    "UNICAST_BASE_PORT + domain".to_owned()
}

/// The default peer list as the document writes it.
fn peers_default(daemon: &ndds_daemon::DaemonConfig) -> String {
    assert!(daemon.peers.is_empty(), "no peers by default");
    "none".to_owned()
}

/// A duration the way the document writes it: `0`, `5 s`, `200 ms` or `250 µs`.
pub fn duration(d: Duration) -> String {
    if d.is_zero() {
        "0".to_owned()
    } else if d.subsec_nanos() == 0 {
        format!("{} s", d.as_secs())
    } else if Duration::from_millis(d.as_millis() as u64) == d {
        format!("{} ms", d.as_millis())
    } else {
        format!("{} µs", d.as_micros())
    }
}

fn durations(list: &[Duration]) -> String {
    list.iter()
        .map(|d| duration(*d))
        .collect::<Vec<_>>()
        .join(", ")
}

fn locator(port: u16) -> Locator {
    Locator {
        addr: Ipv4Addr::LOCALHOST.octets(),
        port,
    }
}

fn accepts(change: impl FnOnce(&mut DiscoveryConfig)) -> bool {
    let mut config = DiscoveryConfig::new(0, locator(40000));
    change(&mut config);
    config.validate().is_ok()
}

/// Smallest and largest `announce_chunk` the configuration accepts.
fn chunk_bounds() -> (usize, usize) {
    let accepted = |chunk: usize| accepts(|c| c.announce_chunk = chunk);
    let default = DiscoveryConfig::new(0, locator(40000)).announce_chunk;
    // Below the default: the first accepted size; above it: the last one.
    let min = partition(0, default, |chunk| !accepted(chunk));
    let max = partition(default, MAX_DATAGRAM + 1, accepted) - 1;
    (min, max)
}

/// Longest reply jitter the configuration accepts.
fn max_delay() -> Duration {
    let accepted = |ms: usize| accepts(|c| c.reply_jitter = Duration::from_millis(ms as u64));
    let last_ms = partition(0, 24 * 3600 * 1000, accepted) - 1;
    let last = Duration::from_millis(last_ms as u64);
    // Sub-millisecond precision is not a documented value; confirm it is a whole ms.
    assert!(
        !accepts(|c| c.reply_jitter = last + Duration::from_micros(1)),
        "the reply jitter limit is not a whole number of milliseconds"
    );
    last
}

/// The exclusive upper bound of `period_jitter`, to six decimals.
fn jitter_bound() -> String {
    let (mut ok, mut bad) = (0.0_f64, 1.0_f64);
    assert!(accepts(|c| c.period_jitter = ok) && !accepts(|c| c.period_jitter = bad));
    for _ in 0..60 {
        let mid = (ok + bad) / 2.0;
        if accepts(|c| c.period_jitter = mid) {
            ok = mid;
        } else {
            bad = mid;
        }
    }
    let rounded = format!("{bad:.6}");
    rounded
        .trim_end_matches('0')
        .trim_end_matches('.')
        .to_owned()
}

/// First value in `lo..hi` for which `pred` is false, where `pred` holds on a prefix.
fn partition(mut lo: usize, mut hi: usize, pred: impl Fn(usize) -> bool) -> usize {
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if pred(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// What the engine's datagrams reveal about its private chunk sizes.
struct EngineLimits {
    guids_per_withdraw: usize,
    withdrawn_per_announce: usize,
}

/// More endpoints than either limit, so both show as a full datagram plus a remainder.
const PROBE_ENDPOINTS: u32 = 5000;

fn engine_limits() -> EngineLimits {
    let now = Instant::now();
    let mut engine =
        Engine::new(DiscoveryConfig::new(0, locator(40000)), now).expect("default config");
    let type_desc = TypeDescription::try_of::<f64>().expect("f64 is traceable");
    let guids: Vec<Guid> = (1..=PROBE_ENDPOINTS)
        .map(|entity| Guid {
            participant: 7,
            entity,
        })
        .collect();
    for guid in &guids {
        let info = EndpointInfo {
            guid: *guid,
            // One topic each: endpoints of one topic are paired with each other on insertion.
            topic: format!("probe/{}", guid.entity),
            fingerprint: type_desc.fingerprint(),
            type_desc: type_desc.clone(),
            qos: EndpointQos::Producer(ProducerQosWire::default()),
            locator: locator(40001),
            pid: 1,
            process: "probe".to_owned(),
        };
        engine
            .add_local(now, info)
            .expect("probe endpoint accepted");
    }
    drain(&mut engine);
    engine.remove_locals(&guids);
    let withdraws = drain(&mut engine);
    engine.handle_timeout(now);
    let announces = drain(&mut engine);
    let withdraw_sizes: Vec<usize> = withdraws
        .iter()
        .filter_map(|m| match m {
            Message::Withdraw(w) => Some(w.endpoints.len()),
            _ => None,
        })
        .collect();
    let withdrawn_sizes: Vec<usize> = announces
        .iter()
        .filter_map(|m| match m {
            Message::Announce(a) if !a.withdrawn.is_empty() => Some(a.withdrawn.len()),
            _ => None,
        })
        .collect();
    for (what, sizes) in [
        ("Withdraw", &withdraw_sizes),
        ("Announce", &withdrawn_sizes),
    ] {
        assert!(
            sizes.len() > 1 && sizes.iter().sum::<usize>() == guids.len(),
            "{PROBE_ENDPOINTS} withdrawn guids did not split over several {what} datagrams \
             ({sizes:?}); raise PROBE_ENDPOINTS in docs/tests/support/values.rs"
        );
    }
    EngineLimits {
        guids_per_withdraw: withdraw_sizes.into_iter().max().unwrap_or(0),
        withdrawn_per_announce: withdrawn_sizes.into_iter().max().unwrap_or(0),
    }
}

/// Decodes every datagram the engine wants to send.
fn drain(engine: &mut Engine) -> Vec<Message> {
    let mut out = Vec::new();
    while let Some(transmit) = engine.poll_transmit() {
        let (_, message) =
            wire::decode(&transmit.payload).expect("the engine sends valid datagrams");
        out.push(message);
    }
    out
}

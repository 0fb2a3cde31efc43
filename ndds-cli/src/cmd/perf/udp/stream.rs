//! Raw-UDP pub and sub: one datagram per sample (or per 64 KiB piece of a larger one), sent
//! with no batching; received on a thread of its own while the main thread cuts the steady
//! window out of the counts, as with ndds.

use std::cell::Cell;
use std::io::ErrorKind;
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::{Collect, HEADER, Header, await_listener, bind, send_sample, timed_out};
use crate::cmd::perf::sample::{Gaps, pattern, wall_ns};
use crate::cmd::perf::throughput::{self, Counts, Measured, Published, Rate, Window};

/// How often the receiving thread looks whether it should stop.
const STOP_POLL: Duration = Duration::from_millis(100);

/// Sends samples of `size` bytes to `peer` for `duration` at `rate`, once the subscriber
/// there answered (within `wait`).
pub fn publish(
    peer: SocketAddrV4,
    size: usize,
    rate: Rate,
    duration: Duration,
    wait: Duration,
) -> anyhow::Result<Published> {
    let socket = bind(SocketAddrV4::new(Ipv4Addr::LOCALHOST, 0))?;
    socket.connect(peer)?;
    await_listener(&socket, wait)?;
    let payload = pattern(size);
    // The kernel answers a send to a closed port with "connection refused": the subscriber
    // has gone.
    // Sends from then on are not counted.
    let (gone, wasted) = (Cell::new(false), Cell::new(0u64));
    let mut sent_ns = 0;
    let mut out = throughput::publish_for(
        duration,
        rate,
        |seq| {
            if gone.get() {
                wasted.set(wasted.get() + 1);
                return Ok(());
            }
            if throughput::stamp_due(seq, rate) {
                sent_ns = wall_ns();
            }
            let sent = send_sample(&socket, seq, sent_ns, &payload);
            if sent
                .as_ref()
                .is_err_and(|err| err.kind() == ErrorKind::ConnectionRefused)
            {
                gone.set(true);
                wasted.set(wasted.get() + 1);
                return Ok(());
            }
            sent
        },
        || !gone.get(),
    );
    out.written -= wasted.get();
    Ok(out)
}

/// Receives samples at `addr` and measures the steady window.
pub fn subscribe(addr: SocketAddrV4, window: &Window) -> anyhow::Result<Measured> {
    let socket = bind(addr)?;
    socket.set_read_timeout(Some(STOP_POLL))?;
    let counts = Arc::new(Mutex::new(Counts::default()));
    let stop = Arc::new(AtomicBool::new(false));
    let receiver = {
        let (counts, stop) = (Arc::clone(&counts), Arc::clone(&stop));
        std::thread::Builder::new()
            .name("perf-udp-sub".into())
            .spawn(move || receive(&socket, &counts, &stop))?
    };
    let measured =
        throughput::measure(window, || *counts.lock().unwrap_or_else(|p| p.into_inner()));
    stop.store(true, Ordering::Release);
    let received = receiver
        .join()
        .map_err(|_| anyhow::anyhow!("the receiving thread panicked"))?;
    received?;
    measured
}

/// Counts whole samples and sequence gaps until `stop`.
fn receive(socket: &UdpSocket, counts: &Mutex<Counts>, stop: &AtomicBool) -> std::io::Result<()> {
    let mut buf = vec![0u8; 65_536];
    let mut collect = Collect::default();
    let mut gaps = Gaps::default();
    while !stop.load(Ordering::Acquire) {
        let (len, from) = match socket.recv_from(&mut buf) {
            Ok(received) => received,
            Err(err) if timed_out(&err) => continue,
            Err(err) => return Err(err),
        };
        let Some(header) = Header::decode(&buf[..len]) else {
            continue;
        };
        if header.is_probe() {
            let _ = socket.send_to(&buf[..len], from);
            continue;
        }
        if let Some(bytes) = collect.take(&header, len - HEADER) {
            let before = gaps;
            gaps.see(header.seq);
            let mut counts = counts.lock().unwrap_or_else(|p| p.into_inner());
            counts.samples += 1;
            counts.bytes += bytes as u64;
            counts.lost += gaps.lost - before.lost;
            counts.late += gaps.late - before.late;
        }
    }
    Ok(())
}

//! Raw-UDP ping and pong, each on one thread: the ping sends a sample and receives its echo
//! in a loop (or, with `--rate`, sends on a timer and receives in between); the pong receives
//! a datagram and sends it back.

use std::io;
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::time::{Duration, Instant};

use super::{Collect, HEADER, Header, bind, send_end, send_sample, timed_out};
use crate::cmd::perf::latency::Progress;
use crate::cmd::perf::ping::{FIRST_RETRY, PingRun, STALL};
use crate::cmd::perf::pong::Echoed;
use crate::cmd::perf::sample::{mono_ns, pattern};
use crate::seconds;

/// Receive buffer: one byte more than the largest UDP payload.
const BUFFER: usize = 65_536;
/// How often a waiting pong looks at its deadline.
const PONG_POLL: Duration = Duration::from_millis(250);

/// Runs a raw-UDP ping against the pong at `peer`.
pub fn ping(peer: SocketAddrV4, run: &PingRun) -> anyhow::Result<Progress> {
    let socket = bind(SocketAddrV4::new(Ipv4Addr::LOCALHOST, 0))?;
    socket.connect(peer)?;
    let mut pinger = Pinger {
        socket,
        payload: pattern(run.size),
        buf: vec![0; BUFFER],
        seq: 0,
        progress: Progress::new(run.warmup, run.limit()),
    };
    pinger.first_reply(run.wait)?;
    let result = match run.rate {
        None => pinger.closed_loop(run.timeout),
        Some(period) => pinger.open_loop(run.timeout, period),
    };
    send_end(&pinger.socket);
    result.map(|()| pinger.progress)
}

struct Pinger {
    socket: UdpSocket,
    payload: Vec<u8>,
    buf: Vec<u8>,
    seq: u64,
    progress: Progress,
}

impl Pinger {
    fn send(&mut self) -> io::Result<()> {
        self.seq += 1;
        send_sample(&self.socket, self.seq, mono_ns(), &self.payload)
    }

    /// Pings until the pong answers once (not measured).
    fn first_reply(&mut self, wait: Duration) -> anyhow::Result<()> {
        let deadline = seconds::deadline(wait);
        loop {
            self.send()?;
            if self.reply(self.seq, FIRST_RETRY)?.is_some() {
                return Ok(());
            }
            if seconds::passed(deadline) {
                anyhow::bail!("the pong never answered within {} s", wait.as_secs_f64());
            }
        }
    }

    /// One ping at a time, each sent when the previous one's reply is in.
    fn closed_loop(&mut self, timeout: Duration) -> anyhow::Result<()> {
        let mut silent = 0;
        while !self.progress.done(Instant::now()) {
            self.send()?;
            match self.reply(self.seq, timeout)? {
                Some(sent_ns) => {
                    let rtt = mono_ns().saturating_sub(sent_ns);
                    self.progress.record(rtt, Instant::now());
                    silent = 0;
                }
                None => {
                    self.progress.trips.lost += 1;
                    silent += 1;
                    if silent >= STALL {
                        anyhow::bail!("the pong stopped answering ({STALL} pings lost in a row)");
                    }
                }
            }
        }
        Ok(())
    }

    /// Waits up to `timeout` for the whole echo of ping `seq`; returns its send time.
    fn reply(&mut self, seq: u64, timeout: Duration) -> io::Result<Option<u64>> {
        let deadline = Instant::now() + timeout;
        self.socket.set_read_timeout(Some(timeout))?;
        let mut collect = Collect::default();
        loop {
            match self.socket.recv(&mut self.buf) {
                Ok(len) => {
                    if let Some(header) = Header::decode(&self.buf[..len])
                        && header.seq == seq
                        && collect.take(&header, len - HEADER).is_some()
                    {
                        return Ok(Some(header.sent_ns));
                    }
                }
                // Nobody listens there (yet): the kernel said so at once.
                Err(err) if err.kind() == io::ErrorKind::ConnectionRefused => {
                    std::thread::sleep(Duration::from_millis(5));
                }
                Err(err) if timed_out(&err) => {}
                Err(err) => return Err(err),
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    /// Pings at a fixed rate, receiving the echoes in between.
    fn open_loop(&mut self, timeout: Duration, period: Duration) -> anyhow::Result<()> {
        let start = Instant::now();
        let (mut due, mut sent) = (start, 0u64);
        let mut last_reply = start;
        let mut collect = Collect::default();
        loop {
            let now = Instant::now();
            let sending = self.progress.wants_more(sent, now);
            if sending && now >= due {
                self.send()?;
                (sent, due) = (sent + 1, due + period);
                continue;
            }
            let quiet = now.duration_since(last_reply);
            if !sending && (self.progress.trips.replies >= sent || quiet >= timeout) {
                break;
            }
            if quiet >= timeout * STALL {
                anyhow::bail!("the pong stopped answering");
            }
            let wait = if sending { due - now } else { timeout - quiet };
            self.socket
                .set_read_timeout(Some(wait.max(Duration::from_micros(1))))?;
            match self.socket.recv(&mut self.buf) {
                Ok(len) => {
                    let Some(header) = Header::decode(&self.buf[..len]) else {
                        continue;
                    };
                    if collect.take(&header, len - HEADER).is_some() {
                        let rtt = mono_ns().saturating_sub(header.sent_ns);
                        last_reply = Instant::now();
                        self.progress.record(rtt, last_reply);
                    }
                }
                Err(err) if timed_out(&err) => {}
                Err(err) => return Err(err.into()),
            }
        }
        self.progress.trips.lost = sent.saturating_sub(self.progress.trips.replies);
        Ok(())
    }
}

/// Echoes every datagram arriving at `addr` to its sender until a ping's end marker or
/// `duration`.
pub fn pong(addr: SocketAddrV4, duration: Duration) -> anyhow::Result<Echoed> {
    let socket = bind(addr)?;
    socket.set_read_timeout(Some(PONG_POLL))?;
    let end = seconds::deadline(duration);
    let mut buf = vec![0u8; BUFFER];
    let mut echoed = Echoed::default();
    while !seconds::passed(end) {
        let (len, from) = match socket.recv_from(&mut buf) {
            Ok(received) => received,
            Err(err) if timed_out(&err) => continue,
            Err(err) => return Err(err.into()),
        };
        let Some(header) = Header::decode(&buf[..len]) else {
            continue;
        };
        if header.is_end() {
            break;
        }
        match socket.send_to(&buf[..len], from) {
            Ok(_) if header.index + 1 == header.count => echoed.echoed += 1,
            Ok(_) => {}
            Err(err) => {
                echoed.errors += 1;
                echoed.first_error.get_or_insert_with(|| err.to_string());
            }
        }
    }
    Ok(echoed)
}

//! `ndds perf port`: round trips through a port — `send` / `receive` / `reply`, or `query`
//! answered by a response handler — between two processes (start `--serve` first).

use std::time::{Duration, Instant};

use hdrhistogram::Histogram;
use ndds_client::ports::{
    PortError, PortOwner, PortUser, ProcessClass, Responder, Restrictions, Usage,
};
use serde_json::json;

use super::connect;
use crate::connect::DaemonArgs;
use crate::outln;

/// Options of `ndds perf port`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Serve: own the port and answer (reply to sends, or a response handler with --query).
    #[arg(long)]
    serve: bool,
    /// Query / response instead of send / receive / reply.
    #[arg(long)]
    query: bool,
    /// The port's name.
    #[arg(long, default_value = "ndds.perf")]
    port: String,
    /// Round trips measured (after 100 warm-up ones).
    #[arg(long, default_value_t = 2000)]
    count: u64,
    /// Serve this many seconds at most.
    #[arg(long, default_value_t = 60.0)]
    seconds: f64,
    /// Serve a tightly-coupled port: the owner's `receive`, and its users' `send` and
    /// `query`, busy-wait this many microseconds before they park (the client learns it
    /// from the owner's declaration). Each waiting side keeps a core busy meanwhile.
    #[arg(long, value_name = "SPIN_US")]
    tight: Option<u32>,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

const WAIT: Duration = Duration::from_secs(5);

/// Runs `ndds perf port`.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let participant = connect(daemon)?;
    anyhow::ensure!(
        args.seconds > 0.0 && args.seconds <= 3600.0,
        "--seconds in (0, 3600]"
    );
    if args.serve {
        let until = Instant::now() + Duration::from_secs_f64(args.seconds);
        let restrictions = Restrictions {
            class: args
                .tight
                .map_or(ProcessClass::Loose, |spin_us| ProcessClass::Tight {
                    spin_us,
                }),
            ..Restrictions::default()
        };
        if args.query {
            let mut responder = Responder::new(&participant, "perf-server")?;
            responder.handle_with(&args.port, restrictions, |n: u64| n)?;
            std::thread::sleep(until.saturating_duration_since(Instant::now()));
            return Ok(());
        }
        let owner = PortOwner::<u64, u64>::declare_with(
            &participant,
            &args.port,
            "perf-server",
            restrictions,
        )?;
        while Instant::now() < until {
            match owner.receive(Duration::from_millis(100)) {
                Ok((n, reply)) => reply.reply(&n)?,
                Err(PortError::Timeout { .. }) => {}
                Err(err) => return Err(err.into()),
            }
        }
        return Ok(());
    }
    let usage = if args.query {
        Usage::Query
    } else {
        Usage::Send
    };
    let user =
        PortUser::<u64, u64>::declare_with(&participant, &args.port, "perf-client", &[usage])?;
    let call = |n: u64| -> anyhow::Result<u64> {
        Ok(if args.query {
            user.query(&n, WAIT)?
        } else {
            user.send(&n, WAIT)?
        })
    };
    for n in 0..100 {
        anyhow::ensure!(call(n)? == n, "wrong echo");
    }
    let mut rtt = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3)?;
    let start = Instant::now();
    for n in 0..args.count {
        let t = Instant::now();
        anyhow::ensure!(call(n)? == n, "wrong echo");
        rtt.saturating_record(t.elapsed().as_nanos().max(1) as u64);
    }
    let us = |q: f64| rtt.value_at_quantile(q) as f64 / 1000.0;
    let mode = if args.query {
        "query"
    } else {
        "send/receive/reply"
    };
    if args.json {
        outln!(
            "{}",
            json!({
                "mode": mode, "count": args.count, "seconds": start.elapsed().as_secs_f64(),
                "p50_us": us(0.5), "p90_us": us(0.9), "p99_us": us(0.99),
                "max_us": rtt.max() as f64 / 1000.0,
            })
        )?;
    } else {
        outln!(
            "port {mode}: {} round trips, p50 {:.1} us, p90 {:.1} us, p99 {:.1} us, max {:.1} us",
            args.count,
            us(0.5),
            us(0.9),
            us(0.99),
            rtt.max() as f64 / 1000.0
        )?;
    }
    Ok(())
}

//! `ndds studio`: the network, the running systems, their state machines and live plots in a
//! browser (docs/studio.md). Serves on loopback unless told otherwise; prints the URL, with
//! the token that lets a page change anything.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::Context as _;
use ndds_studio::{Studio, StudioOptions};

use crate::connect::{DaemonArgs, connect};
use crate::outln;

/// Arguments of `ndds studio`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The port to serve on (0: any free one).
    #[arg(long, default_value_t = 8470)]
    port: u16,
    /// Serve on this address instead of 127.0.0.1 (other hosts can then reach it: a page
    /// needs the printed token to see or change anything).
    #[arg(long, value_name = "ADDR")]
    bind: Option<IpAddr>,
    /// Open the page in a browser (`xdg-open`).
    #[arg(long)]
    open: bool,
    /// The directory whose description files the editor may open and save (it never reads
    /// or writes outside it).
    #[arg(long, value_name = "DIR", default_value = ".")]
    files: std::path::PathBuf,
    /// Do not measure each topic's rate (the studio then declares no consumer of user topics
    /// until a plot asks for one).
    #[arg(long)]
    no_rates: bool,
}

/// Runs `ndds studio` until Ctrl-C.
pub fn run(daemon: &DaemonArgs, args: &Args) -> anyhow::Result<()> {
    let participant = connect(daemon)?;
    let ip = args.bind.unwrap_or(IpAddr::V4(Ipv4Addr::LOCALHOST));
    let studio = Studio::bind(
        participant,
        StudioOptions {
            addr: SocketAddr::new(ip, args.port),
            token: None,
            rates: !args.no_rates,
            files: Some(args.files.clone()),
        },
    )
    .context("use --port to choose another port (`--port 0` takes any free one)")?;
    let url = studio.url();
    outln!("ndds studio: {url}")?;
    outln!("ndds studio: Foxglove at {}", studio.foxglove_url())?;
    if !ip.is_loopback() {
        eprintln!(
            "ndds studio: serving on {ip}, reachable from other hosts; only pages opened with the \
             URL above (its token) can see or change anything"
        );
    }
    if args.open
        && let Err(err) = std::process::Command::new("xdg-open").arg(&url).spawn()
    {
        eprintln!("ndds studio: cannot open a browser ({err}); open the URL above");
    }
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop)).context("cannot catch signals")?;
    }
    studio.run(stop)?;
    Ok(())
}

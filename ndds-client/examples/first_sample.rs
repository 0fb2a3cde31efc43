//! Measures the time from creating a consumer to receiving its first sample, across two
//! daemons on loopback (each embedded in this process, standing for two hosts), while a
//! producer on the other daemon writes every 100 µs.
//!
//! ```text
//! cargo run --release -p ndds-client --example first_sample [-- ROUNDS]
//! ```

use std::net::Ipv4Addr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use ndds_client::{ConsumerQos, DaemonConfig, EmbeddedPolicy, Participant, ProducerQos};

fn config(dir: &std::path::Path, name: &str, port: u16, group: Ipv4Addr) -> DaemonConfig {
    let mut config = DaemonConfig::new(42, Ipv4Addr::LOCALHOST);
    config.socket = dir.join(format!("{name}.sock"));
    config.port = port;
    config.group = group;
    config
}

fn participant(config: DaemonConfig) -> Result<Participant, Box<dyn std::error::Error>> {
    Ok(Participant::builder()
        .embedded(EmbeddedPolicy::Always)
        .embedded_config(config)
        .connect()?)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let rounds: usize = std::env::args()
        .nth(1)
        .map_or(Ok(50), |arg| arg.parse())
        .map_err(|_| "ROUNDS must be a number")?;
    let dir = tempfile::tempdir()?;
    let port = fastrand::u16(20_000..60_000);
    let group = Ipv4Addr::new(239, 255, fastrand::u8(100..=254), fastrand::u8(1..=254));
    let host_a = participant(config(dir.path(), "a", port, group))?;
    let host_b = participant(config(dir.path(), "b", port, group))?;

    let producer = host_a.producer::<u64>("first/sample", ProducerQos::default())?;
    let running = Arc::new(AtomicBool::new(true));
    let writer = {
        let running = running.clone();
        std::thread::spawn(move || {
            let mut i = 0u64;
            while running.load(Ordering::Relaxed) {
                i += 1;
                let _ = producer.write(&i);
                std::thread::sleep(Duration::from_micros(100));
            }
        })
    };

    let mut times = Vec::with_capacity(rounds);
    for _ in 0..rounds {
        let created = Instant::now();
        let consumer = host_b.consumer::<u64>("first/sample", ConsumerQos::default())?;
        consumer.recv_timeout(Duration::from_secs(5))?;
        times.push(created.elapsed());
        drop(consumer);
        std::thread::sleep(Duration::from_millis(20));
    }
    running.store(false, Ordering::Relaxed);
    let _ = writer.join();

    times.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "consumer creation to first sample over {rounds} rounds, two daemons on loopback: \
         min {:.3} ms, median {:.3} ms, p90 {:.3} ms, max {:.3} ms",
        ms(times[0]),
        ms(times[rounds / 2]),
        ms(times[rounds * 9 / 10]),
        ms(times[rounds - 1])
    );
    Ok(())
}

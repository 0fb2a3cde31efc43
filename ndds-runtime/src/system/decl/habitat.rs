//! `[[habitat]]`: a periodic task running one dependency-sorted execution list.

use std::time::Duration;

use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use super::values::number;
use super::{Description, Named};
use crate::system::source::Diagnostics;
use crate::{Clock, HabitatOptions, MAX_RATE_HZ, MIN_RATE_HZ};

pub(super) const SECTION: Section = Section::list(
    "habitat",
    &[
        Key::new("name", TEXT),
        Key::new("rate", "the sample rate in Hz"),
        Key::new("clock", CLOCKS),
        Key::new("topic", "the topic whose u64 ticks clock it"),
        Key::new("priority", "a SCHED_FIFO priority from 1 to 99"),
        Key::new("cpu", "the CPU to pin the habitat's thread to"),
        Key::new("stats_interval", "seconds between statistics reports"),
    ],
    |d, r, _, p| read(d, r, p),
);

/// The clocks a habitat may have.
const CLOCKS: &str = "\"timer\", \"manual\" or \"topic\"";

pub(crate) struct HabitatDecl {
    pub name: Named,
    pub options: HabitatOptions,
}

fn read(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    let rate = rate(r, p);
    let clock = clock(r, p);
    let priority = r.integer("priority", (1, 99), p);
    let cpu = r.integer("cpu", (0, 4095), p);
    let interval = stats_interval(r, p);
    if let Some(name) = &name
        && (rate.is_none() || clock.is_none())
    {
        d.broken_habitats.push(name.name.clone());
    }
    let (Some(name), Some(rate), Some(clock)) = (name, rate, clock) else {
        return;
    };
    let mut options = HabitatOptions::rate(rate).clock(clock);
    options.realtime_priority = priority.map(|x| x as i32);
    options.cpu = cpu.map(|x| x as usize);
    if let Some(i) = interval {
        options.stats_interval = i;
    }
    d.habitats.push(HabitatDecl { name, options });
}

fn rate(r: &Reader<'_>, p: &mut Diagnostics) -> Option<f64> {
    let Some(raw) = r.raw("rate") else {
        r.missing("rate", p);
        return None;
    };
    let hz = number(raw, "rate", p)?;
    if (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&hz) {
        return Some(hz);
    }
    p.expected(
        &raw.at,
        format!("`rate` is {hz} Hz"),
        format!("a rate from {MIN_RATE_HZ:.6} to {MAX_RATE_HZ} Hz"),
    );
    None
}

fn clock(r: &Reader<'_>, p: &mut Diagnostics) -> Option<Clock> {
    let Some(clock) = r.text("clock", p) else {
        return Some(Clock::Timer);
    };
    match clock.name.as_str() {
        "timer" => Some(Clock::Timer),
        "manual" => Some(Clock::Manual),
        "topic" => {
            let topic = r.text("topic", p);
            if topic.is_none() {
                r.missing("topic", p);
            }
            topic.map(|topic| Clock::Topic(topic.name))
        }
        other => {
            p.expected(&clock.at, format!("unknown clock `{other}`"), CLOCKS);
            None
        }
    }
}

/// `stats_interval`, reported (but kept) when out of range.
fn stats_interval(r: &Reader<'_>, p: &mut Diagnostics) -> Option<Duration> {
    let interval = r.seconds("stats_interval", p);
    if let Some(raw) = r.raw("stats_interval")
        && interval.is_some_and(|i| !(0.01..=3600.0).contains(&i.as_secs_f64()))
    {
        let range = "0.01 to 3600 seconds";
        p.expected(&raw.at, "`stats_interval` out of range", range);
    }
    interval
}

//! Modules that move CSMats between habitats and over the network, and what a subscription
//! tells the status about its input ([`InputStatus`]).
//!
//! A [`Subscriber`] records each sample it takes into a [`Reception`] of atomics that the
//! status reads without any lock the habitat holds. Times are the habitat's own sample time
//! (the sum of its periods, [`SampleContext::time`]), so a simulated system or a habitat that
//! falls behind judges an input by the samples it actually ran.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::csmat::CsMat;
use super::mat::Mat;
use super::module::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule, Shape};
use super::runtime::lock;
use ndds_client::{Producer, RawConsumer};

/// Copies `src` into `dst`, reallocating only when the shape changes.
pub(crate) fn copy_into(dst: &mut CsMat, src: &CsMat) {
    if dst.shape() == src.shape() {
        let _ = dst.copy_from(src);
    } else {
        let name = dst.name().to_owned();
        *dst = src.clone();
        dst.set_name(name);
    }
}

/// Writes its input on a topic each sample (installed by `Runtime::publish`).
pub(crate) struct Publisher {
    input: Mat,
    producer: Producer<CsMat>,
}

impl Publisher {
    pub(crate) fn new(b: &mut Binder<'_>, mat: &str, producer: Producer<CsMat>) -> Self {
        Self {
            input: b.input(mat, Shape::Any),
            producer,
        }
    }
}

impl SampleModule for Publisher {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let value = self.input.read();
        self.producer
            .write(&value)
            .map_err(|err| ModuleError::Failed(format!("publishing `{}`: {err}", value.name())))
    }
}

/// How long an input may go without a sample before it is stale: three periods of its
/// habitat or half a second, whichever is longer (a fast habitat is not alarmed by the
/// network's ordinary delays; a slow one gets a few samples' grace).
pub fn stale_after(period: Duration) -> Duration {
    period.saturating_mul(3).max(Duration::from_millis(500))
}

/// Whether a subscribed input is being fed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Freshness {
    /// No sample taken since its habitat began sampling.
    Never,
    /// The last sample is at most [`stale_after`] old.
    Fresh,
    /// The last sample is older than [`stale_after`]: the CSMat holds an old value.
    Stale,
}

impl Freshness {
    /// The rule: `age` is the habitat time since the last sample taken (`None`: never).
    pub fn of(age: Option<Duration>, period: Duration) -> Self {
        match age {
            None => Self::Never,
            Some(age) if age > stale_after(period) => Self::Stale,
            Some(_) => Self::Fresh,
        }
    }
}

/// What the status knows about one subscribed CSMat (one `[[subscribe]]`, one
/// [`Runtime::subscribe`](super::Runtime::subscribe)).
#[derive(Clone, Debug, PartialEq)]
pub struct InputStatus {
    /// The topic subscribed.
    pub topic: String,
    /// The CSMat it writes.
    pub mat: String,
    /// The habitat whose samples take it in.
    pub habitat: String,
    /// Samples taken into the CSMat since the habitat began sampling.
    pub received: u64,
    /// Samples refused since then (undecodable, or of another shape than the CSMat's).
    pub refused: u64,
    /// Habitat time since the last sample taken (`None`: never taken).
    pub age: Option<Duration>,
    /// Habitat time sampled so far (how long it has waited, when nothing came).
    pub sampled: Duration,
    /// The verdict of [`Freshness::of`].
    pub freshness: Freshness,
    /// The sample period of its habitat.
    pub period: Duration,
}

impl InputStatus {
    /// Stale, or never received although its habitat has sampled for longer than
    /// [`stale_after`] (the same grace a fed input gets, so a publisher that starts a moment
    /// after the system is not reported): the habitat computes with a value nobody sent
    /// recently.
    pub fn is_problem(&self) -> bool {
        match self.freshness {
            Freshness::Fresh => false,
            Freshness::Stale => true,
            Freshness::Never => self.sampled > stale_after(self.period),
        }
    }
}

/// Written by the habitat thread (relaxed stores, no lock), read by the status.
#[derive(Debug)]
pub(crate) struct Reception {
    pub(crate) topic: String,
    pub(crate) mat: String,
    received: AtomicU64,
    refused: AtomicU64,
    /// Habitat time (ns) of the last sample taken; [`NEVER`] before the first.
    last_ns: AtomicU64,
    /// Habitat time (ns) of the latest sample the subscriber ran in.
    ran_ns: AtomicU64,
    period_ns: AtomicU64,
}

const NEVER: u64 = u64::MAX;

fn as_ns(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX - 1)
}

impl Reception {
    fn new(topic: &str, mat: &str) -> Self {
        Self {
            topic: topic.to_owned(),
            mat: mat.to_owned(),
            received: AtomicU64::new(0),
            refused: AtomicU64::new(0),
            last_ns: AtomicU64::new(NEVER),
            ran_ns: AtomicU64::new(0),
            period_ns: AtomicU64::new(0),
        }
    }

    /// Sampling begins: nothing taken yet.
    fn restart(&self, ctx: &SampleContext) {
        self.received.store(0, Ordering::Relaxed);
        self.refused.store(0, Ordering::Relaxed);
        self.last_ns.store(NEVER, Ordering::Relaxed);
        self.ran_ns.store(0, Ordering::Relaxed);
        self.period_ns.store(as_ns(ctx.period), Ordering::Relaxed);
    }

    fn ran(&self, ctx: &SampleContext) {
        self.ran_ns.store(as_ns(ctx.time), Ordering::Relaxed);
        self.period_ns.store(as_ns(ctx.period), Ordering::Relaxed);
    }

    fn took(&self, ctx: &SampleContext) {
        self.last_ns.store(as_ns(ctx.time), Ordering::Relaxed);
        self.received.fetch_add(1, Ordering::Relaxed);
    }

    fn refused(&self) {
        self.refused.fetch_add(1, Ordering::Relaxed);
    }

    /// Its status now, in `habitat`.
    pub(crate) fn status(&self, habitat: &str) -> InputStatus {
        let ran = self.ran_ns.load(Ordering::Relaxed);
        let last = self.last_ns.load(Ordering::Relaxed);
        let period = Duration::from_nanos(self.period_ns.load(Ordering::Relaxed));
        let age = (last != NEVER).then(|| Duration::from_nanos(ran.saturating_sub(last)));
        InputStatus {
            topic: self.topic.clone(),
            mat: self.mat.clone(),
            habitat: habitat.to_owned(),
            received: self.received.load(Ordering::Relaxed),
            refused: self.refused.load(Ordering::Relaxed),
            age,
            sampled: Duration::from_nanos(ran),
            freshness: Freshness::of(age, period),
            period,
        }
    }
}

/// Writes the newest sample of a topic into its output (installed by `Runtime::subscribe`).
pub(crate) struct Subscriber {
    output: Mat,
    shape: Shape,
    consumer: RawConsumer,
    staging: CsMat,
    reception: Arc<Reception>,
}

impl Subscriber {
    pub(crate) fn new(b: &mut Binder<'_>, mat: &str, shape: Shape, consumer: RawConsumer) -> Self {
        let reception = Arc::new(Reception::new(consumer.topic(), mat));
        Self {
            output: b.output(mat, shape),
            shape,
            consumer,
            staging: CsMat::zeros(mat, 0, 0),
            reception,
        }
    }

    /// What it records for the status (the runtime keeps a clone when installing it).
    pub(crate) fn reception(&self) -> Arc<Reception> {
        Arc::clone(&self.reception)
    }

    fn take(&mut self, sample: &ndds_client::sample::RawSample) -> RoutineResult {
        // Decoded into a staging matrix that keeps the sender's name and fields, so the
        // steady state allocates nothing; then copied under the local name.
        self.staging.decode_into(&sample.payload)?;
        let (rows, cols) = self.staging.shape();
        if let Shape::Exact(r, c) = self.shape
            && (r, c) != (rows, cols)
        {
            return Err(ModuleError::Failed(format!(
                "a sample from {} is {rows}x{cols}; CSMat `{}` is declared {r}x{c}: ignored",
                sample.info.writer,
                self.output.name()
            )));
        }
        let mut out = self.output.write();
        if out.shape() != (rows, cols) {
            out.resize(rows, cols);
            out.set_fields_from(&self.staging);
        } else if out.row_fields().is_empty()
            && out.col_fields().is_empty()
            && !(self.staging.row_fields().is_empty() && self.staging.col_fields().is_empty())
        {
            // Created with its declared shape only: take the sender's field names and
            // units (once; they are kept from then on).
            out.set_fields_from(&self.staging);
        }
        out.copy_from(&self.staging)?;
        Ok(())
    }
}

impl SampleModule for Subscriber {
    fn startup(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.reception.restart(ctx);
        Ok(())
    }

    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        self.reception.ran(ctx);
        let mut newest = None;
        while let Ok(sample) = self.consumer.try_recv_raw() {
            newest = Some(sample);
        }
        let Some(sample) = newest else {
            return Ok(());
        };
        let taken = self.take(&sample);
        match &taken {
            Ok(()) => self.reception.took(ctx),
            Err(_) => self.reception.refused(),
        }
        taken
    }
}

/// The source side of a rate transition.
pub(crate) struct RateIn {
    input: Mat,
    staging: CsMat,
    buffer: Arc<Mutex<Option<CsMat>>>,
}

impl RateIn {
    pub(crate) fn new(b: &mut Binder<'_>, mat: &str, buffer: Arc<Mutex<Option<CsMat>>>) -> Self {
        Self {
            input: b.input(mat, Shape::Any),
            staging: CsMat::zeros(mat, 0, 0),
            buffer,
        }
    }
}

impl SampleModule for RateIn {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        // One lock at a time (the CSMat, then the buffer): no lock order to get wrong.
        copy_into(&mut self.staging, &self.input.read());
        let mut buffer = lock(&self.buffer);
        match buffer.as_mut() {
            Some(held) => copy_into(held, &self.staging),
            None => *buffer = Some(self.staging.clone()),
        }
        Ok(())
    }
}

/// The destination side of a rate transition.
pub(crate) struct RateOut {
    output: Mat,
    staging: Option<CsMat>,
    buffer: Arc<Mutex<Option<CsMat>>>,
}

impl RateOut {
    /// Writes `mat`, created with the shape (and fields) of `source` once that exists.
    pub(crate) fn new(
        b: &mut Binder<'_>,
        mat: &str,
        source: &Mat,
        buffer: Arc<Mutex<Option<CsMat>>>,
    ) -> Self {
        let output = if source.is_bound() {
            let mut template = source.snapshot();
            template.fill(0.0);
            b.output_like(mat, template)
        } else {
            b.output_same_as(mat, source)
        };
        Self {
            output,
            staging: None,
            buffer,
        }
    }
}

impl SampleModule for RateOut {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        {
            let buffer = lock(&self.buffer);
            match (buffer.as_ref(), self.staging.as_mut()) {
                (Some(value), Some(staging)) => copy_into(staging, value),
                (Some(value), None) => self.staging = Some(value.clone()),
                (None, _) => return Ok(()),
            }
        }
        if let Some(staging) = &self.staging {
            copy_into(&mut self.output.write(), staging);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn stale_after_three_periods_or_half_a_second() {
        assert_eq!(stale_after(MS), Duration::from_millis(500));
        assert_eq!(stale_after(Duration::from_secs(1)), Duration::from_secs(3));
        assert_eq!(stale_after(MS * 200), Duration::from_millis(600));
    }

    #[test]
    fn freshness_follows_the_rule() {
        assert_eq!(Freshness::of(None, MS), Freshness::Never);
        assert_eq!(Freshness::of(Some(MS * 500), MS), Freshness::Fresh);
        assert_eq!(Freshness::of(Some(MS * 501), MS), Freshness::Stale);
        let slow = Duration::from_secs(1);
        assert_eq!(Freshness::of(Some(slow * 3), slow), Freshness::Fresh);
        assert_eq!(Freshness::of(Some(slow * 4), slow), Freshness::Stale);
    }

    #[test]
    fn a_reception_counts_in_habitat_time() {
        let reception = Reception::new("arm/angles", "angles");
        let at = |sample: u64| SampleContext {
            period: MS * 10,
            sample,
            time: MS * 10 * u32::try_from(sample).unwrap(),
        };
        reception.restart(&at(0));
        reception.ran(&at(0));
        let status = reception.status("control");
        assert_eq!((status.freshness, status.age), (Freshness::Never, None));
        assert!(
            !status.is_problem(),
            "not yet: a publisher may start a moment later"
        );
        reception.ran(&at(50));
        assert!(!reception.status("control").is_problem(), "0.5 s of grace");
        reception.ran(&at(51));
        assert!(
            reception.status("control").is_problem(),
            "never, past the grace"
        );
        reception.restart(&at(0));
        reception.ran(&at(3));
        reception.took(&at(3));
        reception.ran(&at(53));
        let status = reception.status("control");
        assert_eq!(status.age, Some(MS * 500));
        assert_eq!((status.received, status.freshness), (1, Freshness::Fresh));
        reception.ran(&at(54));
        let status = reception.status("control");
        assert_eq!(status.freshness, Freshness::Stale);
        assert_eq!(status.sampled, MS * 540);
        reception.restart(&at(0));
        assert_eq!(reception.status("control").freshness, Freshness::Never);
    }
}

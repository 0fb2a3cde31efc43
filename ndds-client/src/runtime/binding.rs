//! Modules that move CSMats between habitats and over the network.

use std::sync::{Arc, Mutex};

use super::csmat::CsMat;
use super::mat::Mat;
use super::module::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule, Shape};
use super::runtime::lock;
use crate::{Producer, RawConsumer};

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

/// Writes the newest sample of a topic into its output (installed by `Runtime::subscribe`).
pub(crate) struct Subscriber {
    output: Mat,
    shape: Shape,
    consumer: RawConsumer,
    staging: CsMat,
}

impl Subscriber {
    pub(crate) fn new(b: &mut Binder<'_>, mat: &str, shape: Shape, consumer: RawConsumer) -> Self {
        Self {
            output: b.output(mat, shape),
            shape,
            consumer,
            staging: CsMat::zeros(mat, 0, 0),
        }
    }
}

impl SampleModule for Subscriber {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let mut newest = None;
        while let Ok(sample) = self.consumer.try_recv_raw() {
            newest = Some(sample);
        }
        if let Some(sample) = newest {
            // Decoded into a staging matrix that keeps the sender's name and fields, so the
            // steady state allocates nothing; then copied under the local name.
            self.staging.decode_into(&sample.payload)?;
            let (rows, cols) = self.staging.shape();
            if let Shape::Exact(r, c) = self.shape
                && (r, c) != (rows, cols)
            {
                return Err(ModuleError::Failed(format!(
                    "sample of `{}` from {} is {rows}x{cols}, the CSMat is declared {r}x{c}: ignored",
                    self.staging.name(),
                    sample.info.writer
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
        }
        Ok(())
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

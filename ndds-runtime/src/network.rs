//! Network bindings of CSMats (publish, subscribe), rate transitions between habitats, and the
//! runtime's services on the network: statistics topics, the configure command topic and the
//! command port (`command.rs`).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::binding::{Publisher, RateIn, RateOut, Subscriber};
use super::csmat::CsMat;
use super::error::RuntimeError;
use super::module::ModuleError;
use super::runtime::{Inner, Runtime, Services, lock};
use super::stats::HabitatStats;
use ndds_client::{ConsumerQos, Participant, Producer, ProducerQos, Reliability, TypeDescription};
use ndds_core::types::builtin;

impl Runtime {
    pub(crate) fn start_services(&self, participant: &Participant) -> Result<(), RuntimeError> {
        let stop = Arc::new(AtomicBool::new(false));
        // First: a runtime whose name is taken in the domain goes no further.
        let commands = super::command::serve(&self.inner, participant, &stop)?;
        let stop_on_error = |err: RuntimeError| {
            stop.store(true, Ordering::Release);
            err
        };
        let topic = format!("cs/{}/configure", self.inner.name);
        let qos = ConsumerQos {
            reliability: Reliability::Reliable { depth: 64 },
            depth: 64,
            ..ConsumerQos::default()
        };
        let consumer = participant
            .consumer::<String>(&topic, qos)
            .map_err(|source| {
                stop_on_error(RuntimeError::Declare {
                    topic: topic.clone(),
                    source,
                })
            })?;
        let weak = Arc::downgrade(&self.inner);
        let configure = consumer
            .on_sample(move |sample| {
                if let Some(inner) = weak.upgrade() {
                    let rt = Runtime { inner };
                    match rt.switch_explained(sample.value.trim()) {
                        Ok(done) => tracing::info!(runtime = %rt.name(), "{done} (from the network)"),
                        Err(refused) => tracing::warn!(runtime = %rt.name(), "configuration command refused: {refused}"),
                    }
                }
            })
            .map_err(|err| {
                stop_on_error(RuntimeError::Build {
                    module: topic,
                    source: ModuleError::Failed(err.to_string()),
                })
            })?;
        let weak = Arc::downgrade(&self.inner);
        let stop_flag = Arc::clone(&stop);
        let stats = std::thread::Builder::new()
            .name(format!("cs-{}-stats", self.inner.name))
            .spawn(move || publish_stats(&weak, &stop_flag))
            .ok();
        *lock(&self.inner.services) = Some(Services {
            stop,
            stats,
            commands: Some(commands),
            _configure: configure,
        });
        Ok(())
    }

    fn participant_or_err(&self) -> Result<&Participant, RuntimeError> {
        self.inner
            .participant
            .as_ref()
            .ok_or_else(|| RuntimeError::NoParticipant(self.inner.name.clone()))
    }

    /// Publishes CSMat `mat` on `topic` every sample: a module `publish:<topic>` in
    /// `habitat`, ordered after the CSMat's writer. A reliable producer here never blocks the
    /// habitat: its `when_full` is made [`WhenFull::DropOldest`](ndds_client::WhenFull), so a slow
    /// consumer loses old samples (and is told so) instead of stalling the loop.
    pub fn publish(
        &self,
        habitat: &str,
        mat: &str,
        topic: &str,
        qos: ProducerQos,
    ) -> Result<(), RuntimeError> {
        let producer: Producer<CsMat> = self
            .participant_or_err()?
            .producer_with_type(topic, TypeDescription::named::<CsMat>(builtin::CSMAT), qos)
            .map_err(|source| RuntimeError::Declare {
                topic: topic.to_owned(),
                source,
            })?;
        self.install(habitat, &format!("publish:{topic}"), |b| {
            Ok(Publisher::new(b, mat, producer))
        })
    }

    /// Writes the newest sample received on `topic` into CSMat `mat` (created with `shape`
    /// if it does not exist) at the start of each sample: a module `subscribe:<topic>` in
    /// `habitat`, which is the CSMat's writer.
    pub fn subscribe(
        &self,
        habitat: &str,
        mat: &str,
        shape: impl Into<super::module::Shape>,
        topic: &str,
        qos: ConsumerQos,
    ) -> Result<(), RuntimeError> {
        let shape = shape.into();
        let consumer = self
            .participant_or_err()?
            .raw_consumer(topic, TypeDescription::named::<CsMat>(builtin::CSMAT), qos)
            .map_err(|source| RuntimeError::Declare {
                topic: topic.to_owned(),
                source,
            })?;
        self.install(habitat, &format!("subscribe:{topic}"), |b| {
            Ok(Subscriber::new(b, mat, shape, consumer))
        })
    }

    /// Passes CSMat `from.1` (written in habitat `from.0`) to CSMat `to.1` read in habitat
    /// `to.0`, whatever their rates: module `<name>.in` copies it into a buffer each sample of
    /// the source habitat, module `<name>.out` copies the newest complete value out at the
    /// start of each sample of the destination. Neither ever sees a half-written matrix.
    pub fn rate_transition(
        &self,
        name: &str,
        from: (&str, &str),
        to: (&str, &str),
    ) -> Result<(), RuntimeError> {
        let source = self.db().mat(from.1);
        let buffer = Arc::new(Mutex::new(None));
        let shared = Arc::clone(&buffer);
        self.install(from.0, &format!("{name}.in"), |b| {
            Ok(RateIn::new(b, from.1, shared))
        })?;
        let result = self.install(to.0, &format!("{name}.out"), |b| {
            Ok(RateOut::new(b, to.1, &source, buffer))
        });
        if result.is_err() {
            let _ = self.remove(&format!("{name}.in"));
        }
        result
    }
}

/// The statistics service: every habitat's stats on `cs/<runtime>/<habitat>/stats`.
fn publish_stats(weak: &std::sync::Weak<Inner>, stop: &AtomicBool) {
    let mut producers: BTreeMap<String, Producer<HabitatStats>> = BTreeMap::new();
    let tick = Duration::from_millis(100);
    let mut next: BTreeMap<String, std::time::Instant> = BTreeMap::new();
    let mut description = Description::default();
    while !stop.load(Ordering::Acquire) {
        std::thread::sleep(tick);
        let Some(inner) = weak.upgrade() else { return };
        let rt = Runtime { inner };
        let Some(participant) = rt.inner.participant.clone() else {
            return;
        };
        description.refresh(&rt, &participant);
        for habitat in rt.habitats() {
            if !habitat.is_created() {
                continue;
            }
            let now = std::time::Instant::now();
            let interval = habitat.stats_interval();
            let due = next.entry(habitat.name().to_owned()).or_insert(now);
            if now < *due {
                continue;
            }
            *due = now
                .checked_add(interval)
                .unwrap_or(now + Duration::from_secs(3600));
            let name = habitat.name().to_owned();
            if !producers.contains_key(&name) {
                let topic = format!("cs/{}/{}/stats", rt.inner.name, name);
                match participant.producer_with_type::<HabitatStats>(
                    &topic,
                    TypeDescription::named::<HabitatStats>(builtin::HABITAT_STATS),
                    ProducerQos::default(),
                ) {
                    Ok(p) => {
                        producers.insert(name.clone(), p);
                    }
                    Err(err) => {
                        tracing::warn!(topic, error = %err, "cannot publish habitat statistics");
                        continue;
                    }
                }
            }
            let stats = rt.habitat_stats(&habitat);
            if let Some(producer) = producers.get(&name)
                && let Err(err) = producer.write(&stats)
            {
                tracing::debug!(habitat = %name, error = %err, "habitat statistics not sent");
            }
        }
    }
}

/// The runtime's description on `cs/<runtime>/description` (`describe.rs`): looked at every
/// second, written when it changed and at least every [`DESCRIPTION_AGAIN`], kept for
/// reliable consumers that join later. Written again because a best-effort consumer (`ndds
/// echo`) gets no kept sample, and a reliable one did not always get it in the studio's
/// browser test (3 runs of 8).
#[derive(Default)]
struct Description {
    producer: Option<Producer<crate::describe::SystemDescription>>,
    last: Option<(crate::describe::SystemDescription, std::time::Instant)>,
    due: Option<std::time::Instant>,
}

/// How often an unchanged description is written again.
const DESCRIPTION_AGAIN: Duration = Duration::from_secs(5);

impl Description {
    fn refresh(&mut self, rt: &Runtime, participant: &Participant) {
        let now = std::time::Instant::now();
        if self.due.is_some_and(|due| now < due) {
            return;
        }
        self.due = Some(now + Duration::from_secs(1));
        if self.producer.is_none() {
            let topic = crate::describe::description_topic(rt.name());
            let qos = ProducerQos {
                reliability: Reliability::Reliable { depth: 4 },
                late_joiners: 1,
                ..ProducerQos::default()
            };
            match participant.producer_with_type(&topic, crate::describe::description_type(), qos) {
                Ok(producer) => self.producer = Some(producer),
                Err(err) => {
                    tracing::warn!(topic, error = %err, "cannot publish the system's description");
                    // Not again for a minute.
                    self.due = Some(now + Duration::from_secs(60));
                    return;
                }
            }
        }
        let current = rt.describe();
        if let Some((last, written)) = &self.last
            && *last == current
            && now.duration_since(*written) < DESCRIPTION_AGAIN
        {
            return;
        }
        if let Some(producer) = &self.producer {
            match producer.write(&current) {
                Ok(()) => self.last = Some((current, now)),
                Err(err) => tracing::debug!(error = %err, "the system's description not sent"),
            }
        }
    }
}

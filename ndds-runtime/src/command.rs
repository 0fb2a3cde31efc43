//! The runtime's command port: requests a tool makes of a running system (`ndds pub` to its
//! configure topic, `ndds pub` of a CSMat it subscribes), answered with what happened or why
//! not, so a command the system refuses is never reported as done.
//!
//! Port `cs.<runtime>` (see [`command_port`]) takes a [`RuntimeCommand`] and answers a
//! [`CommandReply`](ndds_client::ports::CommandReply): `Ok(what happened)` or `Err(the reason)`.
//! Owning it is also how a runtime says its name is taken: a second runtime of the same name
//! in the domain is refused when it is created.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::thread::JoinHandle;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::csmat::CsMat;
use super::error::RuntimeError;
use super::module::Shape;
use super::runtime::{Inner, Runtime};
use ndds_client::Participant;
use ndds_client::ports::{CommandReply, PortOwner};

/// A request to a running runtime.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum RuntimeCommand {
    /// Switch to this configuration (what a sample on `cs/<runtime>/configure` does).
    Configure(String),
    /// Would the subscription of `topic` take `sample`? Answers without applying it: `Err`
    /// only when this runtime subscribes the topic and would refuse the sample.
    CheckSample {
        /// The subscribed topic.
        topic: String,
        /// The sample a tool is about to publish.
        sample: CsMat,
    },
    /// Set a CSMat that no module writes (a parameter or a reference input) to `values`,
    /// row-major, as `ndds pub` to a subscribed parameter would: its habitats take the new
    /// value at their next sample boundary.
    SetMat {
        /// The CSMat.
        name: String,
        /// Its new values, row-major; as many as it has elements.
        values: Vec<f64>,
    },
    /// The values of these CSMats now, answered as JSON text: an object from each name to
    /// `{"rows", "cols", "data"}` (row-major) or `{"error"}`.
    ReadMats(Vec<String>),
    /// Sample habitat `habitat` at `hz` from its next sample boundary (`ndds habitat NAME
    /// rate HZ`; [`RuntimeCommand::habitat`] makes the four habitat commands).
    HabitatRate {
        /// The habitat.
        habitat: String,
        /// Samples per second.
        hz: f64,
    },
    /// Reset this habitat's modules at its next sample boundary.
    HabitatReset(String),
    /// Start this habitat.
    HabitatStart(String),
    /// Stop this habitat.
    HabitatStop(String),
    /// Every habitat's statistics now, answered as JSON text (a list of
    /// [`HabitatStats`](crate::HabitatStats)).
    Stats,
    /// The system's description now, answered as JSON text (a
    /// [`SystemDescription`](crate::describe::SystemDescription)).
    Describe,
}

impl RuntimeCommand {
    /// The command that does `action` to `habitat`.
    pub fn habitat(habitat: &str, action: HabitatAction) -> Self {
        let habitat = habitat.to_owned();
        match action {
            HabitatAction::Rate(hz) => RuntimeCommand::HabitatRate { habitat, hz },
            HabitatAction::Reset => RuntimeCommand::HabitatReset(habitat),
            HabitatAction::Start => RuntimeCommand::HabitatStart(habitat),
            HabitatAction::Stop => RuntimeCommand::HabitatStop(habitat),
        }
    }
}

/// What can be done to a habitat from outside: [`Runtime::habitat_explained`],
/// [`RuntimeCommand::habitat`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HabitatAction {
    /// Sample at this rate (Hz) from the next sample boundary (`timing_changed` runs).
    Rate(f64),
    /// Call every module's `reset` at the next sample boundary.
    Reset,
    /// Begin sampling (verifies the system first).
    Start,
    /// Stop sampling (disable and shutdown routines run).
    Stop,
}

impl std::fmt::Display for HabitatAction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            HabitatAction::Rate(hz) => write!(f, "rate {hz}"),
            HabitatAction::Reset => f.write_str("reset"),
            HabitatAction::Start => f.write_str("start"),
            HabitatAction::Stop => f.write_str("stop"),
        }
    }
}

/// The name of runtime `runtime`'s command port.
pub fn command_port(runtime: &str) -> String {
    format!("cs.{runtime}")
}

/// How long the server waits for a request before checking for a stop.
const POLL: Duration = Duration::from_millis(100);

impl Runtime {
    /// The configurations declared, by name.
    pub fn configurations(&self) -> Vec<String> {
        self.db().configurations.keys().cloned().collect()
    }

    /// Switches like [`switch`](Self::switch), with a refusal in words for a person: an unknown
    /// configuration names the close one and every declared one.
    pub fn switch_explained(&self, name: &str) -> CommandReply {
        let known = self.configurations();
        if !known.iter().any(|k| k == name) {
            let listed = if known.is_empty() {
                "it declares none".to_owned()
            } else {
                format!("it has: {}", known.join(", "))
            };
            return Err(format!(
                "system `{}` has no configuration `{name}`{}; {listed}",
                self.name(),
                crate::system::decl::suggest(name, &known)
            ));
        }
        if self.current_configuration().as_deref() == Some(name) {
            return Ok(format!(
                "system `{}` is in configuration `{name}` already; nothing changed",
                self.name()
            ));
        }
        self.switch(name)
            .map(|()| {
                format!(
                    "system `{}` switched to configuration `{name}`",
                    self.name()
                )
            })
            .map_err(|err| format!("system `{}` refused `{name}`: {err}", self.name()))
    }

    /// Whether the subscription of `topic` would take `sample` (its shape), in words.
    pub fn check_sample(&self, topic: &str, sample: &CsMat) -> CommandReply {
        let module = format!("subscribe:{topic}");
        let db = self.db();
        let Some(entry) = db.modules.get(&module) else {
            // No objection: another consumer of the process may take it.
            return Ok(format!(
                "system `{}` does not subscribe `{topic}`",
                self.name()
            ));
        };
        let Some(port) = entry.interface.outputs.first() else {
            return Ok(format!(
                "system `{}` takes any sample on `{topic}`",
                self.name()
            ));
        };
        let (rows, cols) = sample.shape();
        match port.shape {
            Shape::Exact(r, c) if (r, c) != (rows, cols) => Err(format!(
                "system `{}` subscribes `{topic}` into CSMat `{}`, which is {r}x{c}; this sample \
                 is {rows}x{cols} and would be refused",
                self.name(),
                port.mat.name()
            )),
            _ => Ok(format!(
                "system `{}` takes it into CSMat `{}`",
                self.name(),
                port.mat.name()
            )),
        }
    }

    /// Sets CSMat `name` to `values` (row-major) if no module writes it, in words (see
    /// [`RuntimeCommand::SetMat`]).
    pub fn set_mat(&self, name: &str, values: &[f64]) -> CommandReply {
        let system = self.name();
        let mat = {
            let db = self.db();
            let Some(entry) = db.mats.get(name).filter(|e| e.mat.is_bound()) else {
                let known: Vec<String> = db.mats.keys().cloned().collect();
                return Err(format!(
                    "system `{system}` has no CSMat `{name}`{}",
                    crate::system::decl::suggest(name, &known)
                ));
            };
            let writer = db
                .modules
                .iter()
                .find(|(_, m)| m.interface.output_names().any(|o| o == name));
            if let Some((writer, _)) = writer {
                return Err(format!(
                    "CSMat `{name}` of system `{system}` is written by module `{writer}` every \
                     sample; only parameters and reference inputs (CSMats no module writes) \
                     can be set"
                ));
            }
            entry.mat.clone()
        };
        let (rows, cols) = mat.shape();
        if values.len() != rows * cols {
            return Err(format!(
                "CSMat `{name}` of system `{system}` is {rows}x{cols} ({} values); {} given",
                rows * cols,
                values.len()
            ));
        }
        if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
            return Err(format!("CSMat `{name}`: {bad} is not a finite number"));
        }
        mat.write()
            .copy_from_slice(values)
            .map(|()| format!("system `{system}`: CSMat `{name}` set to {values:?}"))
            .map_err(|err| format!("CSMat `{name}` of system `{system}`: {err}"))
    }

    /// The values of `names` now, as JSON text (see [`RuntimeCommand::ReadMats`]).
    pub fn read_mats(&self, names: &[String]) -> CommandReply {
        let mut out = serde_json::Map::new();
        for name in names.iter().take(256) {
            let mat = self.db().mats.get(name).map(|e| e.mat.clone());
            let value = match mat.filter(super::mat::Mat::is_bound) {
                Some(mat) => {
                    let value = mat.snapshot();
                    let (rows, cols) = value.shape();
                    let data: Vec<f64> = (0..rows)
                        .flat_map(|r| (0..cols).map(move |c| (r, c)))
                        .map(|(r, c)| value.get(r, c).unwrap_or(f64::NAN))
                        .collect();
                    serde_json::json!({"rows": rows, "cols": cols, "data": data})
                }
                None => serde_json::json!({"error": format!("no CSMat `{name}`")}),
            };
            out.insert(name.clone(), value);
        }
        Ok(serde_json::Value::Object(out).to_string())
    }

    /// Carries out `action` on habitat `name`, in words (see [`RuntimeCommand::habitat`]): an
    /// unknown habitat names the close one and every habitat.
    pub fn habitat_explained(&self, name: &str, action: HabitatAction) -> CommandReply {
        let system = self.name();
        let Some(habitat) = self.find_habitat(name) else {
            let known: Vec<String> = self
                .habitats()
                .iter()
                .filter(|h| h.is_created())
                .map(|h| h.name().to_owned())
                .collect();
            return Err(format!(
                "system `{system}` has no habitat `{name}`{}; habitats: {}",
                crate::system::decl::suggest(name, &known),
                if known.is_empty() {
                    "none".to_owned()
                } else {
                    known.join(", ")
                }
            ));
        };
        let refused = |err: super::HabitatError| format!("system `{system}`: {err}");
        match action {
            HabitatAction::Rate(hz) => {
                let before = habitat.rate_hz();
                habitat.set_rate(hz).map_err(refused)?;
                Ok(format!(
                    "habitat `{name}` of system `{system}`: rate {before} Hz -> {hz} Hz from its \
                     next sample"
                ))
            }
            HabitatAction::Reset => {
                habitat.reset();
                Ok(format!(
                    "habitat `{name}` of system `{system}`: reset at its next sample"
                ))
            }
            HabitatAction::Start if habitat.is_running() => Ok(format!(
                "habitat `{name}` of system `{system}` samples already; nothing changed"
            )),
            HabitatAction::Start => {
                habitat.start().map_err(refused)?;
                Ok(format!("habitat `{name}` of system `{system}` started"))
            }
            HabitatAction::Stop if !habitat.is_running() => Ok(format!(
                "habitat `{name}` of system `{system}` is stopped already; nothing changed"
            )),
            HabitatAction::Stop => {
                habitat.stop();
                Ok(format!("habitat `{name}` of system `{system}` stopped"))
            }
        }
    }

    fn answer(&self, command: RuntimeCommand) -> CommandReply {
        match command {
            RuntimeCommand::Configure(name) => self.switch_explained(name.trim()),
            RuntimeCommand::CheckSample { topic, sample } => self.check_sample(&topic, &sample),
            RuntimeCommand::SetMat { name, values } => self.set_mat(name.trim(), &values),
            RuntimeCommand::ReadMats(names) => self.read_mats(&names),
            RuntimeCommand::HabitatRate { habitat, hz } => {
                self.habitat_explained(habitat.trim(), HabitatAction::Rate(hz))
            }
            RuntimeCommand::HabitatReset(habitat) => {
                self.habitat_explained(habitat.trim(), HabitatAction::Reset)
            }
            RuntimeCommand::HabitatStart(habitat) => {
                self.habitat_explained(habitat.trim(), HabitatAction::Start)
            }
            RuntimeCommand::HabitatStop(habitat) => {
                self.habitat_explained(habitat.trim(), HabitatAction::Stop)
            }
            RuntimeCommand::Stats => {
                let stats: Vec<_> = self
                    .habitats()
                    .iter()
                    .map(|h| self.habitat_stats(h))
                    .collect();
                serde_json::to_string(&stats).map_err(|e| e.to_string())
            }
            RuntimeCommand::Describe => {
                serde_json::to_string(&self.describe()).map_err(|e| e.to_string())
            }
        }
    }
}

/// Refuses a runtime whose name another one in the domain holds, then owns the command port
/// and answers it on a thread of its own until the runtime's services stop.
pub(crate) fn serve(
    inner: &Arc<Inner>,
    participant: &Participant,
    stop: &Arc<std::sync::atomic::AtomicBool>,
) -> Result<JoinHandle<()>, RuntimeError> {
    let port = command_port(&inner.name);
    let port_error = |reason: String| RuntimeError::CommandPort {
        runtime: inner.name.clone(),
        reason,
    };
    let others = ndds_client::ports::owners_elsewhere(participant, &port)
        .map_err(|e| port_error(e.to_string()))?;
    if let Some(owner) = others.into_iter().next() {
        return Err(RuntimeError::AlreadyRunning {
            name: inner.name.clone(),
            owner,
        });
    }
    let owner: PortOwner<RuntimeCommand, CommandReply> =
        PortOwner::declare(participant, &port, &inner.name)
            .map_err(|e| port_error(e.to_string()))?;
    let weak = Arc::downgrade(inner);
    let stop = Arc::clone(stop);
    std::thread::Builder::new()
        .name(format!("cs-{}-commands", inner.name))
        .spawn(move || {
            let mut failing = None;
            while !stop.load(Ordering::Acquire) {
                let Some((command, reply)) = owner.serve_next(POLL, &mut failing) else {
                    continue;
                };
                let Some(inner) = weak.upgrade() else { return };
                let answer = Runtime { inner }.answer(command);
                match &answer {
                    Ok(done) => tracing::info!(port = %port, "{done}"),
                    // The one who asked is told; here it is news, not a warning.
                    Err(refused) => tracing::info!(port = %port, "command refused: {refused}"),
                }
                if let Err(err) = reply.reply(&answer) {
                    tracing::debug!(port = %port, error = %err, "command outcome not sent");
                }
            }
        })
        .map_err(|e| port_error(e.to_string()))
}

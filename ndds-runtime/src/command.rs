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

    fn answer(&self, command: RuntimeCommand) -> CommandReply {
        match command {
            RuntimeCommand::Configure(name) => self.switch_explained(name.trim()),
            RuntimeCommand::CheckSample { topic, sample } => self.check_sample(&topic, &sample),
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

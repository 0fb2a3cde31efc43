//! The running systems of a domain, as tools reach them: their names (from the owners of their
//! command ports, `cs.NAME`) and requests to them (`RuntimeCommand`s answered in words).
//! `ndds habitat` and `ndds shell` share this.

use std::time::Duration;

use anyhow::Context as _;
use ndds_client::Participant;
use ndds_client::ports::{CommandReply, PortError, PortUser};
use ndds_core::suggest;
use ndds_runtime::describe::SystemDescription;
use ndds_runtime::{RuntimeCommand, command_port};

/// The names after `prefix` of the ports some process owns, sorted, from the daemon's view
/// (`cs.` gives the running systems, `fsm.` the state machines).
pub fn owned_ports(participant: &Participant, prefix: &str) -> anyhow::Result<Vec<String>> {
    let graph = participant.graph()?;
    let mut names: Vec<String> = graph
        .endpoints
        .iter()
        .filter(|e| e.info.qos.kind() == ndds_core::wire::EndpointKind::Producer)
        .filter_map(|e| e.info.topic.strip_prefix("port/")?.strip_prefix(prefix))
        .filter_map(|rest| rest.strip_suffix("/owner"))
        .map(str::to_owned)
        .collect();
    names.sort();
    names.dedup();
    Ok(names)
}

/// The systems running in the domain, by name: the owners of command ports `cs.NAME`.
pub fn running(participant: &Participant) -> anyhow::Result<Vec<String>> {
    owned_ports(participant, "cs.")
}

/// The ports the process of system `name` owns, by name: its command port `cs.NAME`, its
/// state machines' `fsm.MACHINE`, those its description files declare (and any other the
/// process owns). Empty when the command port has no owner in the daemon's view.
pub fn ports_of(participant: &Participant, name: &str) -> anyhow::Result<Vec<String>> {
    let graph = participant.graph()?;
    let owners: Vec<(&str, (u64, u32))> = graph
        .endpoints
        .iter()
        .filter(|e| e.info.qos.kind() == ndds_core::wire::EndpointKind::Producer)
        .filter_map(|e| {
            let port = e.info.topic.strip_prefix("port/")?.strip_suffix("/owner")?;
            Some((port, (e.node, e.info.pid)))
        })
        .collect();
    let command = command_port(name);
    let Some(process) = owners
        .iter()
        .find(|(p, _)| *p == command)
        .map(|(_, at)| *at)
    else {
        return Ok(Vec::new());
    };
    let mut ports: Vec<String> = owners
        .iter()
        .filter(|(_, at)| *at == process)
        .map(|(port, _)| (*port).to_owned())
        .collect();
    ports.sort();
    ports.dedup();
    Ok(ports)
}

/// A connection to one system's command port.
pub struct SystemLink {
    name: String,
    user: PortUser<RuntimeCommand, CommandReply>,
    wait: Duration,
}

impl SystemLink {
    /// Opens the command port of system `name` (answers must come within `wait`).
    pub fn open(participant: &Participant, name: &str, wait: Duration) -> anyhow::Result<Self> {
        let user = PortUser::declare(participant, &command_port(name), "ndds")?;
        Ok(Self {
            name: name.to_owned(),
            user,
            wait,
        })
    }

    /// The system's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Sends `command`; the system's answer (done, in words, or refused with the reason).
    pub fn ask(&self, command: &RuntimeCommand) -> anyhow::Result<CommandReply> {
        self.ask_within(command, self.wait)
    }

    /// As [`ask`](Self::ask), waiting at most `wait` for the answer.
    pub fn ask_within(
        &self,
        command: &RuntimeCommand,
        wait: Duration,
    ) -> anyhow::Result<CommandReply> {
        match self.user.send(command, wait) {
            Ok(reply) => Ok(reply),
            Err(PortError::Timeout { owner: None, .. }) => anyhow::bail!(
                "system `{}` is not running (its command port has no owner); `ndds run FILE` \
                 starts it",
                self.name
            ),
            Err(PortError::Timeout { .. }) => {
                anyhow::bail!("system `{}` did not answer within {wait:?}", self.name)
            }
            Err(err) => Err(err.into()),
        }
    }

    /// The system's description now.
    pub fn describe(&self) -> anyhow::Result<SystemDescription> {
        self.describe_within(self.wait)
    }

    /// As [`describe`](Self::describe), waiting at most `wait` for the answer.
    pub fn describe_within(&self, wait: Duration) -> anyhow::Result<SystemDescription> {
        let text = self
            .ask_within(&RuntimeCommand::Describe, wait)?
            .map_err(|refused| anyhow::anyhow!("system `{}`: {refused}", self.name))?;
        serde_json::from_str(&text).with_context(|| format!("system `{}`'s description", self.name))
    }
}

/// The system to talk to: `asked` if given (it must run), else the one system running, else
/// the one of those running that has habitat `habitat` (when given).
pub fn choose(
    participant: &Participant,
    asked: Option<&str>,
    habitat: Option<&str>,
    wait: Duration,
) -> anyhow::Result<SystemLink> {
    let known = running(participant)?;
    if let Some(name) = asked {
        if !known.iter().any(|k| k == name) {
            let hint = suggest::did_you_mean(&suggest::suggest(name, &known))
                .map(|s| format!(" ({s})"))
                .unwrap_or_default();
            anyhow::bail!(
                "no system `{name}` runs in this domain{hint}; {}",
                listed(&known)
            );
        }
        return SystemLink::open(participant, name, wait);
    }
    match known.as_slice() {
        [] => anyhow::bail!(
            "no system runs in this domain; start one with `ndds run FILE` (or name the daemon \
             with --domain or --socket)"
        ),
        [only] => SystemLink::open(participant, only, wait),
        several => {
            let Some(habitat) = habitat else {
                anyhow::bail!(
                    "several systems run: name one with --system; {}",
                    listed(several)
                );
            };
            let mut having = Vec::new();
            // A system that does not answer is left out (and said), not a reason to give up.
            let mut silent = Vec::new();
            for name in several {
                let link = SystemLink::open(participant, name, wait)?;
                match link.describe() {
                    Ok(d) if d.habitats.iter().any(|h| h.name == habitat) => having.push(link),
                    Ok(_) => {}
                    Err(_) => silent.push(name.clone()),
                }
            }
            match having.len() {
                1 => Ok(having.remove(0)),
                0 => anyhow::bail!(
                    "none of the running systems has a habitat `{habitat}`; {}{}",
                    listed(several),
                    if silent.is_empty() {
                        String::new()
                    } else {
                        format!(
                            " ({} did not answer; name it with --system)",
                            silent.join(", ")
                        )
                    }
                ),
                _ => anyhow::bail!(
                    "several systems have a habitat `{habitat}` ({}): name one with --system",
                    having
                        .iter()
                        .map(|l| l.name.clone())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
        }
    }
}

fn listed(known: &[String]) -> String {
    if known.is_empty() {
        "none runs".to_owned()
    } else {
        format!("running: {}", known.join(", "))
    }
}

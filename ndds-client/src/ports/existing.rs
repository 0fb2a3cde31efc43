//! Finding a port's owner in the domain before declaring one: a command port names a running
//! system or state machine, and a second one of the same name is refused at start instead of
//! fighting the first for the port.

use super::{check_name, topic};
use crate::Participant;
use crate::error::QueryError;

/// An owner of a port, as the local daemon's view of the domain shows it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OwnerLocation {
    /// The owner's host (its daemon's host name).
    pub host: String,
    /// The owner's process id.
    pub pid: u32,
    /// The owner's process name.
    pub process: String,
}

impl std::fmt::Display for OwnerLocation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "`{}` (pid {}) on host {}",
            self.process, self.pid, self.host
        )
    }
}

/// The owners of `port` in the domain other than `participant` itself (the producers of the
/// port's owner topic), as far as the local daemon knows them now (a daemon this process
/// started less than 300 ms ago is given that long to hear the other hosts first). A port
/// name that cannot be a port has no owner. Owners that start at the same moment can both
/// miss each other here; the port then reports its second owner.
pub fn owners_elsewhere(
    participant: &Participant,
    port: &str,
) -> Result<Vec<OwnerLocation>, QueryError> {
    if check_name(port).is_err() {
        return Ok(Vec::new());
    }
    let owner_topic = topic(port, "owner");
    // A daemon this process has just started has not heard the other hosts yet.
    crate::embedded::wait_first_hearing(participant.daemon_socket());
    let graph = participant.graph()?;
    let mut owners: Vec<OwnerLocation> = graph
        .endpoints
        .iter()
        .filter(|e| e.info.topic == owner_topic)
        .filter(|e| e.info.qos.kind() == ndds_core::wire::EndpointKind::Producer)
        .filter(|e| e.info.guid.participant != participant.id())
        .map(|e| OwnerLocation {
            host: e.hostname.clone(),
            pid: e.info.pid,
            process: e.info.process.clone(),
        })
        .collect();
    owners.sort_by(|a, b| (&a.host, a.pid).cmp(&(&b.host, b.pid)));
    owners.dedup();
    Ok(owners)
}

//! The participant's local endpoints by entity number: what was declared (to declare it again
//! after a daemon restart) and the state the daemon's match events update.

use std::collections::HashMap;
use std::net::SocketAddrV4;
use std::sync::{Arc, RwLock};

use ndds_core::arbitration::Notification;
use ndds_core::discovery::Incompatibility;
use ndds_core::ipc::{DaemonMessage, EndpointDecl};
use ndds_core::wire::EndpointKind;

use crate::consumer::ConsumerState;
use crate::matches::{Matched, Peers};
use crate::producer::ProducerState;
use crate::sync::{read, write};

/// Endpoints whose matched set changed since it was last applied, by entity.
pub(crate) type Changed = HashMap<u32, Endpoint>;

/// A local endpoint's state.
#[derive(Debug, Clone)]
pub(crate) enum Endpoint {
    Producer(Arc<ProducerState>),
    Consumer(Arc<ConsumerState>),
}

impl Endpoint {
    pub(crate) fn peers(&self) -> &Peers {
        match self {
            Endpoint::Producer(state) => &state.peers,
            Endpoint::Consumer(state) => &state.peers,
        }
    }

    /// Applies a change of the matched set: producers re-target their samples, consumers
    /// believe the new set's producers only.
    fn on_change(&self, all: Matched<'_>) {
        match self {
            Endpoint::Producer(state) => state.set_matched(all),
            Endpoint::Consumer(state) => {
                let producers = all
                    .filter(|info| info.kind() == EndpointKind::Producer)
                    .map(|info| (info.guid, SocketAddrV4::from(info.locator)));
                state.plane.set_consumer_matched(state.entity, producers);
            }
        }
    }

    /// Tells a consumer that a matched producer went away.
    fn lost(&self, writer: ndds_core::wire::Guid) {
        if let Endpoint::Consumer(state) = self {
            state.plane.producer_lost(state.entity, writer);
        }
    }
}

/// Local endpoints by entity number.
#[derive(Debug, Default)]
pub(crate) struct LocalEndpoints {
    endpoints: RwLock<HashMap<u32, (Endpoint, EndpointDecl)>>,
}

impl LocalEndpoints {
    pub(crate) fn insert(&self, endpoint: Endpoint, decl: EndpointDecl) {
        write(&self.endpoints).insert(decl.entity, (endpoint, decl));
    }

    pub(crate) fn remove(&self, entity: u32) -> Option<Endpoint> {
        write(&self.endpoints)
            .remove(&entity)
            .map(|(endpoint, _)| endpoint)
    }

    /// Every declaration, to repeat after reconnecting to a daemon.
    pub(crate) fn declarations(&self) -> Vec<EndpointDecl> {
        read(&self.endpoints)
            .values()
            .map(|(_, decl)| decl.clone())
            .collect()
    }

    /// Marks every current match as unconfirmed (the daemon was replaced).
    pub(crate) fn mark_stale(&self) {
        for (endpoint, _) in read(&self.endpoints).values() {
            endpoint.peers().mark_stale();
        }
    }

    /// Drops the matches the new daemon did not confirm; returns how many.
    pub(crate) fn sweep_stale(&self) -> usize {
        let endpoints: Vec<Endpoint> = read(&self.endpoints)
            .values()
            .map(|(endpoint, _)| endpoint.clone())
            .collect();
        let mut swept = 0;
        for endpoint in endpoints {
            for writer in endpoint.peers().sweep_stale(|all| endpoint.on_change(all)) {
                endpoint.lost(writer);
                swept += 1;
            }
        }
        swept
    }

    /// Applies the matched sets of the endpoints in `changed` (emptied).
    pub(crate) fn publish(&self, changed: &mut Changed) {
        for (_, endpoint) in changed.drain() {
            for writer in endpoint.peers().publish(|all| endpoint.on_change(all)) {
                endpoint.lost(writer);
            }
        }
    }

    /// Records one match event of the daemon; the endpoint's data plane learns the new
    /// matched set when [`LocalEndpoints::publish`] applies `changed` (once per burst of
    /// events, not once per event: a burst of `n` matches then costs `n`, not `n²`).
    pub(crate) fn route(&self, message: DaemonMessage, changed: &mut Changed) {
        let entity = match &message {
            DaemonMessage::Matched { local, .. }
            | DaemonMessage::Incompatible { local, .. }
            | DaemonMessage::NotPermitted { local, .. }
            | DaemonMessage::PairKeys { local, .. }
            | DaemonMessage::Unmatched { local, .. } => *local,
            other => {
                tracing::debug!(?other, "unexpected frame from the daemon");
                return;
            }
        };
        let Some(endpoint) = read(&self.endpoints)
            .get(&entity)
            .map(|(endpoint, _)| endpoint.clone())
        else {
            return;
        };
        let peers = endpoint.peers();
        match message {
            DaemonMessage::Matched { remote, .. } => {
                peers.record_matched(remote);
                changed.entry(entity).or_insert_with(|| endpoint.clone());
            }
            DaemonMessage::Unmatched { remote, .. } => {
                peers.record_unmatched(remote);
                changed.entry(entity).or_insert_with(|| endpoint.clone());
            }
            DaemonMessage::Incompatible { remote, .. } => {
                if let Endpoint::Consumer(state) = &endpoint {
                    // Same type, so the daemon found the reliability wanting.
                    let reason = if remote.fingerprint == peers.fingerprint {
                        Incompatibility::Reliability
                    } else {
                        Incompatibility::Type
                    };
                    state.plane.notify(
                        state.entity,
                        Notification::Incompatible {
                            reason,
                            writer: remote.guid,
                            type_name: remote.type_desc.name.clone(),
                            fingerprint: remote.fingerprint,
                            local_type: peers.type_desc.name.clone(),
                            local_fingerprint: peers.fingerprint,
                        },
                    );
                }
                peers.incompatible(remote);
                changed.entry(entity).or_insert_with(|| endpoint.clone());
            }
            DaemonMessage::PairKeys {
                participant,
                locator,
                keys,
                ..
            } => {
                let plane = match &endpoint {
                    Endpoint::Producer(state) => &state.plane,
                    Endpoint::Consumer(state) => &state.plane,
                };
                if !plane.set_pair_keys(participant, SocketAddrV4::from(locator), &keys) {
                    tracing::warn!(
                        peer = format_args!("{participant:016x}"),
                        "data keys not installed (no domain key here, or too many peers)"
                    );
                }
            }
            DaemonMessage::NotPermitted { remote, reason, .. } => {
                if let Endpoint::Consumer(state) = &endpoint {
                    state.plane.notify(
                        state.entity,
                        Notification::NotPermitted {
                            writer: remote.guid,
                            reason: reason.clone(),
                        },
                    );
                }
                tracing::warn!(topic = %remote.topic, remote = %remote.guid, %reason, "not matched: not permitted");
                peers.incompatible(remote);
                changed.entry(entity).or_insert_with(|| endpoint.clone());
            }
            _ => {}
        }
    }
}

//! The owner's side of port liveness. An owner writes its declaration ([`OwnerInfo`]) once
//! and again only when what it says changes; users write theirs ([`UserInfo`]) once. Both
//! producers keep their last sample for endpoints that match later, so a late user (or
//! `ndds ports`) still gets them. Who is there is what discovery says: a user or another
//! owner is present while its declaration's producer is matched, and gone with the
//! `ProducerLost` its consumer gets — no declaration is repeated to stay alive.
//!
//! One thread per owner (`port-<P>`) sleeps on the users' and owners' topics and on the
//! owner's [`Notify`], and:
//! - admits users in the order first heard, under the user list, usage and maximum active
//!   users restrictions, and forgets a lost user with its reply stream;
//! - notes other owners of the port (a conflict) until their declaration is lost;
//! - rewrites the declaration when the admitted users change at once, and when the queue
//!   length changes at most every [`QUEUE_REPORT`].

use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use crate::Notification;

use super::owner::OwnerShared;
use super::wait::{self, Either};
use super::wire::{OwnerInfo, UserInfo};
use crate::{Consumer, Event, Guid, Producer};

/// How often, at most, an owner rewrites its declaration for a changed queue length only.
pub const QUEUE_REPORT: Duration = Duration::from_millis(250);

/// Users an owner tracks at most.
const ACTIVE_LIMIT: usize = 1024;

/// What the owner knows of the others on its port.
#[derive(Default)]
pub(crate) struct Presence {
    /// Users whose declaration's producer is matched, in the order first heard.
    pub(crate) active: Vec<(UserInfo, Guid)>,
    /// Other owners of the port (their declaration's producer -> who, in words, and their
    /// takeover claim).
    pub(crate) others: HashMap<Guid, (String, u64)>,
    /// Refusals so far, in words.
    pub(crate) refused: Vec<String>,
    /// Users that went away while admitted, most recent last (at most [`DEPARTED_KEPT`]),
    /// with when: their last replies may still be on their way (the loss of a user's
    /// declaration can overtake a reply it wrote on another topic just before it left).
    pub(crate) departed: std::collections::VecDeque<(String, Instant)>,
}

/// Users that went away remembered at most (see [`Presence::departed`]).
const DEPARTED_KEPT: usize = 256;

/// How long a reply from a user that went away while admitted is still taken.
pub(crate) const DEPARTED_GRACE: Duration = Duration::from_secs(30);

impl Presence {
    /// Whether user handle `user` went away while admitted within [`DEPARTED_GRACE`].
    pub(crate) fn departed_recently(&self, user: &str) -> bool {
        self.departed
            .iter()
            .any(|(u, at)| u == user && at.elapsed() <= DEPARTED_GRACE)
    }
}

/// The declaration thread's endpoints.
pub(crate) struct Declaration {
    pub(crate) users: Consumer<UserInfo>,
    pub(crate) owners: Consumer<OwnerInfo>,
    pub(crate) announce: Producer<OwnerInfo>,
    pub(crate) info: OwnerInfo,
}

impl Declaration {
    /// Runs until the owner stops (see the module docs).
    pub(crate) fn run(mut self, shared: &OwnerShared) {
        let _ = self.announce.write(&self.info);
        let mut written = Instant::now();
        while !shared.stop.load(Ordering::Acquire) {
            let seen = shared.changed.generation();
            while let Ok(event) = self.users.try_recv_event() {
                on_user(shared, event);
            }
            while let Ok(event) = self.owners.try_recv_event() {
                on_owner(shared, &self.info, event);
            }
            let admitted = shared.admitted_users();
            let queue = u32::try_from(shared.queue_len()).unwrap_or(u32::MAX);
            let mut report_at = None;
            if admitted != self.info.admitted {
                self.info.admitted = admitted;
                self.info.queue = queue;
            } else if queue != self.info.queue && written.elapsed() >= QUEUE_REPORT {
                self.info.queue = queue;
            } else {
                if queue != self.info.queue {
                    report_at = Some(written + QUEUE_REPORT);
                }
                self.wait(shared, seen, report_at);
                continue;
            }
            if let Err(err) = self.announce.write(&self.info) {
                tracing::warn!(port = %shared.port, error = %err, "port declaration not written");
            }
            written = Instant::now();
        }
    }

    /// Sleeps until a user or owner event, a change the owner notifies, or `until`.
    fn wait(&self, shared: &OwnerShared, seen: u64, until: Option<Instant>) {
        wait::block_on(async {
            let (Ok(mut users), Ok(mut owners)) = (self.users.events(), self.owners.events())
            else {
                return wait::timeout_at(until, shared.changed.changed(seen)).await;
            };
            let topics = wait::race(wait::next(&mut users), wait::next(&mut owners));
            let woke = wait::timeout_at(until, wait::race(topics, shared.changed.changed(seen)));
            match woke.await {
                Some(Either::Left(Either::Left(Some(event)))) => on_user(shared, event),
                Some(Either::Left(Either::Right(Some(event)))) => {
                    on_owner(shared, &self.info, event);
                }
                Some(Either::Left(_)) => {
                    // A topic closed: only a change or the deadline can help now.
                    wait::timeout_at(until, shared.changed.changed(seen)).await;
                }
                Some(Either::Right(())) | None => {}
            }
            Some(())
        });
    }
}

fn on_user(shared: &OwnerShared, event: Event<UserInfo>) {
    on_user_event(shared, event);
    shared.users_changed.notify();
}

fn on_user_event(shared: &OwnerShared, event: Event<UserInfo>) {
    let mut presence = shared.presence();
    match event {
        Event::Sample(sample) => {
            let (info, writer) = (sample.value, sample.info.writer);
            if let Some(known) = presence
                .active
                .iter_mut()
                .find(|(u, _)| u.user == info.user)
            {
                known.1 = writer;
                return;
            }
            if presence.active.len() >= ACTIVE_LIMIT {
                return;
            }
            if let Some(why) = shared.refusal(&info) {
                shared.note_refusal(&mut presence, &info, &why);
            }
            presence.active.push((info, writer));
        }
        Event::Notification(Notification::ProducerLost { writer, .. }) => {
            let gone: Vec<String> = presence
                .active
                .iter()
                .filter(|(_, w)| *w == writer)
                .map(|(u, _)| u.user.clone())
                .collect();
            drop(presence);
            let admitted = shared.admitted_users();
            let mut presence = shared.presence();
            for user in gone.iter().filter(|u| admitted.contains(u)) {
                if presence.departed.len() >= DEPARTED_KEPT {
                    presence.departed.pop_front();
                }
                presence.departed.push_back((user.clone(), Instant::now()));
            }
            presence.active.retain(|(_, w)| *w != writer);
            drop(presence);
            for user in gone {
                shared.forget_replies(&user);
            }
        }
        Event::Notification(_) => {}
    }
}

fn on_owner(shared: &OwnerShared, mine: &OwnerInfo, event: Event<OwnerInfo>) {
    let mut presence = shared.presence();
    let before = presence.others.clone();
    match event {
        Event::Sample(sample) if sample.value.incarnation != mine.incarnation => {
            let (other, claim) = (
                format!("{} (pid {})", sample.value.task, sample.value.pid),
                sample.value.claim,
            );
            // Said once per other owner (its declaration is rewritten whenever its users or
            // queue change), and again only if its claim changes.
            let known = presence.others.get(&sample.info.writer).map(|(_, c)| *c);
            if known == Some(claim) {
                // Nothing new about it.
            } else if claim > mine.claim {
                tracing::warn!(port = %shared.port, owner = %shared.task, by = %other,
                    "this owner was replaced (the port was taken over)");
            } else if claim == mine.claim && presence.others.is_empty() {
                tracing::warn!(port = %shared.port, owner = %shared.task, other = %other,
                    "a second owner declared this port");
            }
            presence.others.insert(sample.info.writer, (other, claim));
        }
        Event::Notification(Notification::ProducerLost { writer, .. }) => {
            presence.others.remove(&writer);
        }
        _ => {}
    }
    let changed = presence.others != before;
    drop(presence);
    if changed {
        shared.release_requests_if_replaced();
        shared.changed.notify();
    }
}

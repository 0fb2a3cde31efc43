//! `waitfor`: an n-way rendezvous among named tasks. Each task arrives with a message, blocks
//! until every named task has arrived, then runs a combining function over all the messages
//! and continues with its result. Calls are numbered in rounds, so consecutive rendezvous never
//! mix.
//!
//! On the network (reliable topic `waitfor/<name>`), each task writes its arrival — message
//! and the tasks whose arrival it has — whenever what it has changes, until it has every
//! message and every other task has its message; the topic keeps each task's last arrival for
//! tasks that match later, so a task that joined late still gets everything, and nobody
//! leaves while another still needs its message. Between writes a task sleeps on the topic.

use std::collections::{BTreeMap, BTreeSet};
use std::marker::PhantomData;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::error::PortError;
use super::wait::{self, Notify};
use super::{check_name, declaring_producer, reliable_consumer};
use crate::{Consumer, Participant, Producer};

/// How soon an arrival whose write failed (a full window on a loaded machine) is written
/// again.
pub const REPEAT: Duration = Duration::from_millis(20);

/// How long a task leaving the rendezvous (its handle dropped) waits for its last arrival to
/// be acknowledged by the others: they may still need it to learn that it has their
/// messages, and once its producer is gone nobody could repair it.
pub const LINGER: Duration = Duration::from_secs(1);

/// One task's arrival at a rendezvous round.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Arrival {
    /// The round.
    pub round: u64,
    /// The task.
    pub task: String,
    /// Its message, postcard-encoded.
    #[serde(with = "serde_bytes")]
    pub payload: Vec<u8>,
    /// Tasks whose arrival this task has for this round.
    pub seen: Vec<String>,
}

/// One task's place in a named rendezvous.
pub struct Rendezvous<T> {
    name: String,
    task: String,
    tasks: BTreeSet<String>,
    producer: Producer<Arrival>,
    consumer: Consumer<Arrival>,
    /// The rounds' state, taken by the one `wait` in progress (`None` meanwhile).
    state: Mutex<Option<State>>,
    /// Told when a `wait` gives the state back.
    returned: Notify,
    _message: PhantomData<fn(T)>,
}

#[derive(Default)]
struct State {
    round: u64,
    /// Arrivals of rounds not reached yet (round -> task -> arrival).
    early: BTreeMap<u64, BTreeMap<String, Arrival>>,
}

impl<T: Serialize + DeserializeOwned> Rendezvous<T> {
    /// Joins rendezvous `name` as `task`; `tasks` names every participant (including `task`).
    pub fn join(
        participant: &Participant,
        name: &str,
        task: &str,
        tasks: &[&str],
    ) -> Result<Self, PortError> {
        check_name(name)?;
        let tasks: BTreeSet<String> = tasks.iter().map(|t| (*t).to_owned()).collect();
        if !tasks.contains(task) {
            return Err(PortError::UnknownTask {
                name: name.to_owned(),
                task: task.to_owned(),
                tasks: tasks.into_iter().collect(),
            });
        }
        let topic = format!("waitfor/{name}");
        Ok(Self {
            producer: declaring_producer(participant, name, &topic)?,
            consumer: reliable_consumer(participant, name, &topic)?,
            name: name.to_owned(),
            task: task.to_owned(),
            tasks,
            state: Mutex::new(Some(State::default())),
            returned: Notify::default(),
            _message: PhantomData,
        })
    }

    /// The rendezvous' name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Arrives with `message`, waits (at most `timeout`) for every named task, and returns
    /// `combine` over all their messages (by task name).
    pub fn wait<O>(
        &self,
        message: &T,
        timeout: Duration,
        combine: impl FnOnce(&BTreeMap<String, T>) -> O,
    ) -> Result<O, PortError> {
        wait::block_on(self.wait_future(message, timeout, combine))
    }

    /// The state, once no other `wait` of this handle holds it.
    async fn turn(&self) -> Turn<'_, T> {
        loop {
            let seen = self.returned.generation();
            if let Some(state) = self.state.lock().unwrap_or_else(|p| p.into_inner()).take() {
                return Turn {
                    rendezvous: self,
                    state: Some(state),
                };
            }
            self.returned.changed(seen).await;
        }
    }

    pub(crate) async fn wait_future<O>(
        &self,
        message: &T,
        timeout: Duration,
        combine: impl FnOnce(&BTreeMap<String, T>) -> O,
    ) -> Result<O, PortError> {
        let start = Instant::now();
        let deadline = wait::deadline(start, timeout);
        let mut turn = self.turn().await;
        let state = turn.state();
        let round = state.round;
        let payload = postcard::to_stdvec(message).map_err(|e| PortError::Codec {
            port: self.name.clone(),
            what: "encoding a waitfor message",
            reason: e.to_string(),
        })?;
        let mut arrivals: BTreeMap<String, Arrival> =
            state.early.remove(&round).unwrap_or_default();
        arrivals.insert(
            self.task.clone(),
            Arrival {
                round,
                task: self.task.clone(),
                payload: payload.clone(),
                seen: Vec::new(),
            },
        );
        let mut changed = true;
        let mut retry_at: Option<Instant> = None;
        // Whether the last arrival that went out (written without error) had every message:
        // the others wait for it, so this task leaves the round only after it went out.
        let mut sent_complete = false;
        loop {
            while let Ok(sample) = self.consumer.try_recv() {
                changed |= self.take(state, &mut arrivals, round, sample.value);
            }
            let have: Vec<String> = arrivals.keys().cloned().collect();
            let complete = have.len() == self.tasks.len();
            if changed || retry_at.is_some_and(|at| Instant::now() >= at) {
                let written = self.producer.write(&Arrival {
                    round,
                    task: self.task.clone(),
                    payload: payload.clone(),
                    seen: have.clone(),
                });
                changed = false;
                retry_at = written.is_err().then(|| Instant::now() + REPEAT);
                if written.is_ok() {
                    sent_complete = complete;
                }
            }
            let acknowledged = arrivals
                .values()
                .filter(|a| a.task != self.task)
                .all(|a| a.seen.contains(&self.task));
            if complete && acknowledged && sent_complete {
                break;
            }
            if deadline.is_some_and(|at| Instant::now() >= at) {
                // Keep what came: a retry of this round still has the other tasks' messages.
                let others: BTreeMap<String, Arrival> = arrivals
                    .iter()
                    .filter(|(t, _)| **t != self.task)
                    .map(|(t, a)| (t.clone(), a.clone()))
                    .collect();
                state.early.insert(round, others);
                let missing: Vec<String> = self
                    .tasks
                    .iter()
                    .filter(|t| !arrivals.contains_key(*t))
                    .cloned()
                    .collect();
                return Err(PortError::WaitFor {
                    name: self.name.clone(),
                    task: self.task.clone(),
                    missing,
                    waited: start.elapsed(),
                });
            }
            // Sleep until an arrival, the retry of a failed write, or the deadline.
            let until = deadline.into_iter().chain(retry_at).min();
            match wait::timeout_at(until, wait::next_sample(&self.consumer)).await {
                Some(Some(sample)) => {
                    changed |= self.take(state, &mut arrivals, round, sample.value);
                }
                Some(None) => wait::sleep_until(until).await,
                None => {}
            }
        }
        state.round += 1;
        drop(turn);
        let mut messages = BTreeMap::new();
        for (task, arrival) in arrivals {
            let value = postcard::from_bytes(&arrival.payload).map_err(|e| PortError::Codec {
                port: self.name.clone(),
                what: "decoding a waitfor message",
                reason: format!("from `{task}`: {e}"),
            })?;
            messages.insert(task, value);
        }
        Ok(combine(&messages))
    }

    /// Takes one arrival into this round's (or, early, the next round's); whether what this
    /// task has changed.
    fn take(
        &self,
        state: &mut State,
        arrivals: &mut BTreeMap<String, Arrival>,
        round: u64,
        arrival: Arrival,
    ) -> bool {
        if !self.tasks.contains(&arrival.task) || arrival.task == self.task {
            return false;
        }
        if arrival.round == round {
            let changed = arrivals
                .get(&arrival.task)
                .is_none_or(|known| known.seen.len() != arrival.seen.len());
            arrivals.insert(arrival.task.clone(), arrival);
            return changed;
        }
        if arrival.round == round + 1 {
            state
                .early
                .entry(arrival.round)
                .or_default()
                .insert(arrival.task.clone(), arrival);
        }
        false
    }
}

/// The rounds' state while one `wait` holds it; given back when dropped (also when an async
/// `wait` is dropped half-way).
struct Turn<'a, T> {
    rendezvous: &'a Rendezvous<T>,
    state: Option<State>,
}

impl<T> Turn<'_, T> {
    fn state(&mut self) -> &mut State {
        self.state.get_or_insert_with(State::default)
    }
}

impl<T> Drop for Turn<'_, T> {
    fn drop(&mut self) {
        let state = self.state.take().unwrap_or_default();
        *self
            .rendezvous
            .state
            .lock()
            .unwrap_or_else(|p| p.into_inner()) = Some(state);
        self.rendezvous.returned.notify();
    }
}

impl<T> Drop for Rendezvous<T> {
    fn drop(&mut self) {
        // The other tasks finish the last round only once they have this task's complete
        // arrival: if that datagram was lost, only this producer can repair it.
        if !self.producer.wait_for_acknowledgments(LINGER) {
            tracing::debug!(rendezvous = %self.name, task = %self.task,
                "left before every other task acknowledged the last arrival");
        }
    }
}

//! The Foxglove WebSocket protocol (`foxglove.websocket.v1`, published by Foxglove as
//! `ws-protocol`), served at `/foxglove` beside the page, so that Foxglove or Lichtblick can
//! open the same live data: every topic whose type carries a layout is a channel in JSON
//! encoding, its schema the JSON Schema that `ndds record --json` writes into recordings
//! (`ndds_core::dynamic::json_schema`), each sample decoded from its layout
//! (`ndds_core::dynamic::decode_json`). Read-only: the server offers no capability (no client
//! publishing, parameters or services), so a Foxglove client can look but never change the
//! system.
//!
//! [`Bridge`] holds the channels (made from the daemon's graph once a second; a channel keeps
//! its id while its topic keeps its type) and one consumer per subscribed channel, shared by
//! every connection that subscribed to it and dropped with the last; the connection itself
//! ([`serve`]) speaks the protocol. A client that falls behind misses messages rather than
//! slowing the studio down.

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime};

use axum::extract::ws::{Message as WsMessage, WebSocket};
use ndds_client::{DirectConsumer, Graph, Participant, TypeDescription};
use serde_json::json;
use tokio::sync::broadcast;
use tokio::sync::broadcast::error::RecvError;

/// The subprotocol a client asks for.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// Messages a subscribed channel may have waiting for slow connections.
const BACKLOG: usize = 4096;

/// One channel: a topic with one type.
#[derive(Clone, Debug)]
pub struct Channel {
    /// Its id (kept while the topic keeps its type).
    pub id: u32,
    /// The topic.
    pub topic: String,
    /// The type's name (the schema's name).
    pub schema_name: String,
    /// The JSON Schema of its messages, as text.
    pub schema: String,
    desc: TypeDescription,
}

impl Channel {
    fn advertised(&self) -> serde_json::Value {
        json!({
            "id": self.id,
            "topic": self.topic,
            "encoding": "json",
            "schemaName": self.schema_name,
            "schema": self.schema,
            "schemaEncoding": "jsonschema",
        })
    }
}

/// One sample of a channel, encoded: (channel, receive time in ns since the epoch, JSON).
pub type Data = Arc<(u32, u64, Vec<u8>)>;

struct Subscribed {
    _consumer: DirectConsumer,
    subscribers: usize,
}

/// The channels, and the consumers of the subscribed ones (see the module's documentation).
pub struct Bridge {
    participant: Participant,
    channels: Mutex<Channels>,
    subscribed: Mutex<HashMap<u32, Subscribed>>,
    tx: broadcast::Sender<Data>,
}

#[derive(Default)]
struct Channels {
    /// By (topic, type fingerprint).
    by_key: BTreeMap<(String, u64), Channel>,
    next: u32,
}

impl Bridge {
    /// A bridge taking samples through `participant`.
    pub fn new(participant: Participant) -> Self {
        let (tx, _) = broadcast::channel(BACKLOG);
        Self {
            participant,
            channels: Mutex::new(Channels {
                next: 1,
                ..Channels::default()
            }),
            subscribed: Mutex::new(HashMap::new()),
            tx,
        }
    }

    /// Makes the channels from `graph`: one per topic with a producer whose type has a
    /// layout (ports' internal topics left out); channels of topics gone are dropped.
    pub fn follow(&self, graph: &Graph) {
        let mut present: BTreeMap<(String, u64), &TypeDescription> = BTreeMap::new();
        for e in &graph.endpoints {
            if e.info.kind() != ndds_core::wire::EndpointKind::Producer
                || e.info.topic.starts_with("port/")
                || e.info.type_desc.layout.is_none()
            {
                continue;
            }
            present
                .entry((e.info.topic.clone(), e.info.type_desc.fingerprint()))
                .or_insert(&e.info.type_desc);
        }
        let mut channels = lock(&self.channels);
        channels.by_key.retain(|key, _| present.contains_key(key));
        for (key, desc) in present {
            if channels.by_key.contains_key(&key) {
                continue;
            }
            let Some(layout) = &desc.layout else { continue };
            let schema = match ndds_core::dynamic::json_schema(layout, &desc.name) {
                Ok(schema) => schema.to_string(),
                Err(err) => {
                    tracing::debug!(topic = key.0, %err, "no JSON schema: not a Foxglove channel");
                    continue;
                }
            };
            let id = channels.next;
            channels.next = channels.next.wrapping_add(1).max(1);
            channels.by_key.insert(
                key.clone(),
                Channel {
                    id,
                    topic: key.0,
                    schema_name: desc.name.clone(),
                    schema,
                    desc: desc.clone(),
                },
            );
        }
    }

    /// The channels now.
    pub fn channels(&self) -> Vec<Channel> {
        lock(&self.channels).by_key.values().cloned().collect()
    }

    /// Samples of the subscribed channels from now on.
    pub fn data(&self) -> broadcast::Receiver<Data> {
        self.tx.subscribe()
    }

    /// One more subscriber of `channel` (its consumer made for the first).
    pub fn subscribe(&self, channel: u32) -> Result<(), String> {
        if let Some(s) = lock(&self.subscribed).get_mut(&channel) {
            s.subscribers += 1;
            return Ok(());
        }
        let found = lock(&self.channels)
            .by_key
            .values()
            .find(|c| c.id == channel)
            .cloned();
        let Some(found) = found else {
            return Err(format!("no channel {channel}"));
        };
        let Some(layout) = found.desc.layout.clone() else {
            return Err(format!("channel {channel} has no layout"));
        };
        let tx = self.tx.clone();
        let consumer = self
            .participant
            .raw_consumer(&found.topic, found.desc.clone(), crate::hub::watching_qos())
            .map_err(|e| e.to_string())?
            .on_raw_sample_direct(move |sample| {
                let Ok(value) = ndds_core::dynamic::decode_json(&layout, &sample.payload) else {
                    return;
                };
                let ns = SystemTime::now()
                    .duration_since(SystemTime::UNIX_EPOCH)
                    .map_or(0, |d| d.as_nanos() as u64);
                // Nobody listening is not an error.
                let _ = tx.send(Arc::new((channel, ns, value.to_string().into_bytes())));
            })
            .map_err(|e| e.to_string())?;
        let mut subscribed = lock(&self.subscribed);
        // Another connection subscribed meanwhile: its consumer serves both.
        subscribed
            .entry(channel)
            .or_insert(Subscribed {
                _consumer: consumer,
                subscribers: 0,
            })
            .subscribers += 1;
        Ok(())
    }

    /// One subscriber of `channel` fewer (its consumer dropped with the last).
    pub fn unsubscribe(&self, channel: u32) {
        let mut subscribed = lock(&self.subscribed);
        if let Some(s) = subscribed.get_mut(&channel) {
            s.subscribers = s.subscribers.saturating_sub(1);
            if s.subscribers == 0 {
                subscribed.remove(&channel);
            }
        }
    }
}

/// A Message Data frame: opcode 1, the subscription id and the time (little-endian), the
/// message.
fn frame(subscription: u32, ns: u64, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(13 + payload.len());
    out.push(1);
    out.extend_from_slice(&subscription.to_le_bytes());
    out.extend_from_slice(&ns.to_le_bytes());
    out.extend_from_slice(payload);
    out
}

fn status(level: u8, message: &str) -> String {
    json!({"op": "status", "level": level, "message": message}).to_string()
}

async fn send_text(socket: &mut WebSocket, text: String) -> bool {
    socket.send(WsMessage::Text(text.into())).await.is_ok()
}

/// Speaks the protocol on one connection until the client leaves.
pub async fn serve(mut socket: WebSocket, bridge: Arc<Bridge>, session: String) {
    let info = json!({
        "op": "serverInfo",
        "name": format!("ndds studio {}", env!("CARGO_PKG_VERSION")),
        "capabilities": [],
        "sessionId": session,
    });
    if !send_text(&mut socket, info.to_string()).await {
        return;
    }
    let mut data = bridge.data();
    // Advertised channels by id; subscriptions: client's id -> channel.
    let mut advertised: BTreeMap<u32, Channel> = BTreeMap::new();
    let mut subscriptions: BTreeMap<u32, u32> = BTreeMap::new();
    let mut refresh = tokio::time::interval(Duration::from_secs(1));
    loop {
        tokio::select! {
            _ = refresh.tick() => {
                let now: BTreeMap<u32, Channel> =
                    bridge.channels().into_iter().map(|c| (c.id, c)).collect();
                let gone: Vec<u32> = advertised.keys().filter(|id| !now.contains_key(id)).copied().collect();
                let new: Vec<serde_json::Value> = now
                    .values()
                    .filter(|c| !advertised.contains_key(&c.id))
                    .map(Channel::advertised)
                    .collect();
                if !gone.is_empty() {
                    // Their subscriptions end with them.
                    subscriptions.retain(|_, channel| {
                        let keep = !gone.contains(channel);
                        if !keep {
                            bridge.unsubscribe(*channel);
                        }
                        keep
                    });
                    let text = json!({"op": "unadvertise", "channelIds": gone}).to_string();
                    if !send_text(&mut socket, text).await {
                        break;
                    }
                }
                if !new.is_empty() {
                    let text = json!({"op": "advertise", "channels": new}).to_string();
                    if !send_text(&mut socket, text).await {
                        break;
                    }
                }
                advertised = now;
            }
            message = data.recv() => match message {
                Ok(message) => {
                    let (channel, ns, payload) = &*message;
                    for (&id, _) in subscriptions.iter().filter(|(_, c)| *c == channel) {
                        let bytes = frame(id, *ns, payload);
                        if socket.send(WsMessage::Binary(bytes.into())).await.is_err() {
                            return unsubscribe_all(&bridge, &subscriptions);
                        }
                    }
                }
                Err(RecvError::Lagged(_)) => continue,
                Err(RecvError::Closed) => break,
            },
            incoming = socket.recv() => {
                let Some(Ok(incoming)) = incoming else { break };
                let answer = match incoming {
                    WsMessage::Text(text) => request(&bridge, &advertised, &mut subscriptions, &text).await,
                    WsMessage::Binary(_) => Some(status(1, "this server takes no client messages (it offers no clientPublish)")),
                    _ => None,
                };
                if let Some(answer) = answer
                    && !send_text(&mut socket, answer).await
                {
                    break;
                }
            }
        }
    }
    unsubscribe_all(&bridge, &subscriptions);
}

fn unsubscribe_all(bridge: &Bridge, subscriptions: &BTreeMap<u32, u32>) {
    for channel in subscriptions.values() {
        bridge.unsubscribe(*channel);
    }
}

/// A client's JSON message; a status message to answer with, if any.
async fn request(
    bridge: &Arc<Bridge>,
    advertised: &BTreeMap<u32, Channel>,
    subscriptions: &mut BTreeMap<u32, u32>,
    text: &str,
) -> Option<String> {
    let value: serde_json::Value = match serde_json::from_str(text) {
        Ok(v) => v,
        Err(e) => return Some(status(2, &format!("not JSON: {e}"))),
    };
    match value.get("op").and_then(|o| o.as_str()) {
        Some("subscribe") => {
            let mut problems = Vec::new();
            let wanted = value
                .get("subscriptions")
                .and_then(|s| s.as_array())
                .cloned()
                .unwrap_or_default();
            for s in wanted {
                let (Some(id), Some(channel)) = (
                    s.get("id").and_then(serde_json::Value::as_u64),
                    s.get("channelId").and_then(serde_json::Value::as_u64),
                ) else {
                    problems.push("a subscription needs a numeric `id` and `channelId`".to_owned());
                    continue;
                };
                let (Ok(id), Ok(channel)) = (u32::try_from(id), u32::try_from(channel)) else {
                    problems.push(format!("subscription {id}: ids are 32-bit"));
                    continue;
                };
                if subscriptions.contains_key(&id) {
                    problems.push(format!("subscription id {id} is in use"));
                    continue;
                }
                if !advertised.contains_key(&channel) {
                    problems.push(format!("no channel {channel}"));
                    continue;
                }
                let b = Arc::clone(bridge);
                match tokio::task::spawn_blocking(move || b.subscribe(channel)).await {
                    Ok(Ok(())) => {
                        subscriptions.insert(id, channel);
                    }
                    Ok(Err(e)) => problems.push(format!("channel {channel}: {e}")),
                    Err(e) => problems.push(e.to_string()),
                }
            }
            (!problems.is_empty()).then(|| status(2, &problems.join("; ")))
        }
        Some("unsubscribe") => {
            let ids = value
                .get("subscriptionIds")
                .and_then(|s| s.as_array())
                .cloned()
                .unwrap_or_default();
            for id in ids.iter().filter_map(serde_json::Value::as_u64) {
                if let Ok(id) = u32::try_from(id)
                    && let Some(channel) = subscriptions.remove(&id)
                {
                    bridge.unsubscribe(channel);
                }
            }
            None
        }
        Some(other) => Some(status(
            1,
            &format!(
                "`{other}` is not supported: this server only streams topics (subscribe, unsubscribe)"
            ),
        )),
        None => Some(status(2, "a message needs an `op`")),
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_message_data_frame_is_opcode_subscription_time_and_payload() {
        let f = frame(7, 0x0102_0304_0506_0708, b"{}");
        assert_eq!(
            f,
            [1, 7, 0, 0, 0, 8, 7, 6, 5, 4, 3, 2, 1, b'{', b'}'].to_vec()
        );
    }
}

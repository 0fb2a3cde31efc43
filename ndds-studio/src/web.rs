//! The web server: the page and its assets (embedded in the binary), and one WebSocket per
//! page through which the hub's messages go out and the page's requests come in.
//!
//! Page to server (JSON): `{"type": "auth", "token"}`, `{"type": "watch", "topic"}`,
//! `{"type": "unwatch", "topic"}`, `{"type": "command", "id", "command": ...}` (see
//! [`Command`]), `{"type": "edit", "id", "op": ...}` (see [`EditOp`]). Server to page: `hello`
//! (whether this page may change anything), then `network`, `system`, `stats`, `machine`,
//! `points`, `reply`, `editor` and `error` messages (docs/studio.md).

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::sync::Arc;

use axum::extract::State;
use axum::extract::ws::{Message as WsMessage, WebSocket, WebSocketUpgrade};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde_json::json;
use tokio::sync::broadcast::error::RecvError;

use crate::editor::{EditOp, Editor, palette};
use crate::hub::{Command, Hub};

/// The page and its assets: (path, content type, bytes).
const ASSETS: &[(&str, &str, &[u8])] = &[
    (
        "/",
        "text/html; charset=utf-8",
        include_bytes!("../assets/index.html"),
    ),
    (
        "/app.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../assets/app.js"),
    ),
    (
        "/editor.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../assets/editor.js"),
    ),
    (
        "/style.css",
        "text/css; charset=utf-8",
        include_bytes!("../assets/style.css"),
    ),
    (
        "/vendor/cytoscape.min.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../assets/vendor/cytoscape.min.js"),
    ),
    (
        "/vendor/uPlot.iife.min.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../assets/vendor/uPlot.iife.min.js"),
    ),
    (
        "/vendor/uPlot.min.css",
        "text/css; charset=utf-8",
        include_bytes!("../assets/vendor/uPlot.min.css"),
    ),
];

/// Who may do what.
#[derive(Clone)]
pub struct Access {
    /// The token a page presents to change anything (and, off loopback, to see anything).
    pub token: String,
    /// Bound to an address other hosts can reach: a page without the token gets nothing.
    pub exposed: bool,
    /// The description-file editor's directory and participant (`None`: no editor).
    pub editor: Option<EditorSetup>,
}

/// What each page's editor is made with.
#[derive(Clone)]
pub struct EditorSetup {
    /// The directory it edits (canonical).
    pub root: std::path::PathBuf,
    /// The participant its checks build network bindings with (as `ndds run --check`).
    pub participant: ndds_client::Participant,
}

#[derive(Clone)]
struct AppState {
    hub: Arc<Hub>,
    access: Access,
    /// When this server started (ms since the epoch): a Foxglove client's session id.
    session: String,
}

/// The router of the studio's web server.
pub fn router(hub: Arc<Hub>, access: Access) -> axum::Router {
    let mut router = axum::Router::new()
        .route("/ws", get(upgrade))
        .route("/foxglove", get(foxglove_upgrade));
    for (path, content_type, bytes) in ASSETS {
        router = router.route(
            path,
            get(move || async move {
                (
                    [
                        (header::CONTENT_TYPE, *content_type),
                        (header::CACHE_CONTROL, "no-cache"),
                    ],
                    *bytes,
                )
            }),
        );
    }
    router
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found") })
        .with_state(AppState {
            hub,
            access,
            session: std::time::SystemTime::now()
                .duration_since(std::time::SystemTime::UNIX_EPOCH)
                .map_or(0, |d| d.as_millis())
                .to_string(),
        })
}

async fn upgrade(ws: WebSocketUpgrade, State(state): State<AppState>) -> Response {
    // A page's requests are small but for a description file's whole text (corrected in the
    // editor); a larger message is refused by the WebSocket layer.
    ws.max_message_size(ndds_runtime::system::MAX_FILE_BYTES as usize + 64 * 1024)
        .on_upgrade(move |socket| page(socket, state))
        .into_response()
}

/// The token in a URL's query (`?token=...`), if any.
fn query_token(uri: &axum::http::Uri) -> Option<&str> {
    uri.query()?
        .split('&')
        .find_map(|pair| pair.strip_prefix("token="))
}

/// A Foxglove client (the Foxglove WebSocket protocol, read-only). On loopback anyone local may
/// look, as on the page; off loopback only with the token in the URL's query.
async fn foxglove_upgrade(
    ws: WebSocketUpgrade,
    uri: axum::http::Uri,
    State(state): State<AppState>,
) -> Response {
    if state.access.exposed && !query_token(&uri).is_some_and(|t| same(t, &state.access.token)) {
        return (
            StatusCode::UNAUTHORIZED,
            "this studio needs its token: connect to the Foxglove URL `ndds studio` printed",
        )
            .into_response();
    }
    let bridge = state.hub.foxglove();
    let session = state.session.clone();
    ws.protocols([crate::foxglove::SUBPROTOCOL])
        .max_message_size(64 * 1024)
        .on_upgrade(move |socket| crate::foxglove::serve(socket, bridge, session))
        .into_response()
}

/// Compares without leaking where two texts first differ.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len()
        && a.bytes()
            .zip(b.bytes())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0
}

async fn send(socket: &mut WebSocket, text: &str) -> bool {
    socket
        .send(WsMessage::Text(text.to_owned().into()))
        .await
        .is_ok()
}

/// One page's connection.
async fn page(mut socket: WebSocket, state: AppState) {
    let AppState { hub, access, .. } = state;
    let mut authorized = false;
    // Off loopback, nothing before the token.
    if access.exposed {
        let first = tokio::time::timeout(std::time::Duration::from_secs(10), socket.recv()).await;
        let token = match first {
            Ok(Some(Ok(WsMessage::Text(text)))) => serde_json::from_str::<serde_json::Value>(&text)
                .ok()
                .and_then(|v| v.get("token").and_then(|t| t.as_str()).map(str::to_owned)),
            _ => None,
        };
        if !token.is_some_and(|t| same(&t, &access.token)) {
            let refusal = json!({"type": "error", "text": "this studio needs its token: open the URL `ndds studio` printed"});
            let _ = send(&mut socket, &refusal.to_string()).await;
            return;
        }
        authorized = true;
    }
    let hello =
        json!({"type": "hello", "writable": authorized, "version": env!("CARGO_PKG_VERSION")});
    if !send(&mut socket, &hello.to_string()).await {
        return;
    }
    let mut messages = hub.subscribe();
    for message in hub.snapshot() {
        if !send(&mut socket, &message).await {
            return;
        }
    }
    let mut watched: BTreeSet<String> = BTreeSet::new();
    // This page's editor, made when it first edits.
    let mut editor: Option<Arc<std::sync::Mutex<Editor>>> = None;
    loop {
        tokio::select! {
            message = messages.recv() => match message {
                Ok(text) => {
                    if text.starts_with("{\"type\":\"points\"")
                        && !watched.iter().any(|t| points_of(&text, t))
                    {
                        continue;
                    }
                    if !send(&mut socket, &text).await {
                        break;
                    }
                }
                // A slow page misses messages; the next network message is whole again.
                Err(RecvError::Lagged(_)) => continue,
                Err(RecvError::Closed) => break,
            },
            incoming = socket.recv() => {
                let Some(Ok(incoming)) = incoming else { break };
                let WsMessage::Text(text) = incoming else { continue };
                let answer = match serde_json::from_str::<serde_json::Value>(&text) {
                    Err(e) => Some(json!({"type": "error", "text": format!("not JSON: {e}")})),
                    Ok(value) if value.get("type").and_then(|t| t.as_str()) == Some("edit") => {
                        edit(&access, authorized, &mut editor, &value).await
                    }
                    Ok(value) => {
                        request(&hub, &access, &mut authorized, &mut watched, &value).await
                    }
                };
                if let Some(answer) = answer
                    && !send(&mut socket, &answer.to_string()).await
                {
                    break;
                }
            }
        }
    }
    for topic in watched {
        hub.unwatch(&topic);
    }
}

/// Whether a `points` message (as the hub writes it: type, topic, data, in that order) is of
/// `topic`.
fn points_of(text: &str, topic: &str) -> bool {
    text.starts_with(&format!(
        "{{\"type\":\"points\",\"topic\":{},",
        json!(topic)
    ))
}

/// Handles one request of a page; the answer to send back, if any.
async fn request(
    hub: &Arc<Hub>,
    access: &Access,
    authorized: &mut bool,
    watched: &mut BTreeSet<String>,
    value: &serde_json::Value,
) -> Option<serde_json::Value> {
    let kind = value.get("type").and_then(|t| t.as_str()).unwrap_or("");
    let topic = value
        .get("topic")
        .and_then(|t| t.as_str())
        .unwrap_or("")
        .to_owned();
    match kind {
        "auth" => {
            let token = value.get("token").and_then(|t| t.as_str()).unwrap_or("");
            *authorized = *authorized || same(token, &access.token);
            Some(
                json!({"type": "hello", "writable": *authorized, "version": env!("CARGO_PKG_VERSION")}),
            )
        }
        "watch" => {
            if watched.contains(&topic) {
                return None;
            }
            let hub = Arc::clone(hub);
            let t = topic.clone();
            match tokio::task::spawn_blocking(move || hub.watch(&t)).await {
                Ok(Ok(())) => {
                    watched.insert(topic);
                    None
                }
                Ok(Err(e)) => Some(json!({"type": "error", "topic": topic, "text": e})),
                Err(e) => Some(json!({"type": "error", "text": e.to_string()})),
            }
        }
        "unwatch" => {
            if watched.remove(&topic) {
                hub.unwatch(&topic);
            }
            None
        }
        "command" => {
            let id = value.get("id").cloned().unwrap_or(serde_json::Value::Null);
            let command: Command = match value.get("command").cloned().map(serde_json::from_value) {
                Some(Ok(c)) => c,
                Some(Err(e)) => {
                    return Some(
                        json!({"type": "reply", "id": id, "ok": false, "text": format!("not a command: {e}")}),
                    );
                }
                None => {
                    return Some(
                        json!({"type": "reply", "id": id, "ok": false, "text": "no command"}),
                    );
                }
            };
            if command.changes() && !*authorized {
                return Some(json!({"type": "reply", "id": id, "ok": false,
                    "text": "this page may only look: open the URL with the token that `ndds studio` printed"}));
            }
            let hub = Arc::clone(hub);
            let answer = tokio::task::spawn_blocking(move || hub.command(&command)).await;
            Some(match answer {
                Ok(Ok(text)) => json!({"type": "reply", "id": id, "ok": true, "text": text}),
                Ok(Err(text)) => json!({"type": "reply", "id": id, "ok": false, "text": text}),
                Err(e) => json!({"type": "reply", "id": id, "ok": false, "text": e.to_string()}),
            })
        }
        other => Some(json!({"type": "error", "text": format!("unknown request `{other}`")})),
    }
}

/// Handles one request of a page's editor (`{"type": "edit", "id", "op": {...}}`, see
/// [`EditOp`]): the answer is `{"type": "editor", "id", "ok", "text", "state"}` (the state
/// also after a refused edit, unchanged), and `palette` the first time.
async fn edit(
    access: &Access,
    authorized: bool,
    editor: &mut Option<Arc<std::sync::Mutex<Editor>>>,
    value: &serde_json::Value,
) -> Option<serde_json::Value> {
    let id = value.get("id").cloned().unwrap_or(serde_json::Value::Null);
    let refuse = |text: &str| Some(json!({"type": "editor", "id": id, "ok": false, "text": text}));
    let Some(setup) = &access.editor else {
        return refuse("this studio edits no files: start it with `ndds studio --files DIR`");
    };
    if !authorized {
        return refuse(
            "the editor reads and writes files: open the URL with the token that `ndds studio` printed",
        );
    }
    let op: EditOp = match value.get("op").cloned().map(serde_json::from_value) {
        Some(Ok(op)) => op,
        Some(Err(e)) => return refuse(&format!("not an edit: {e}")),
        None => return refuse("no edit"),
    };
    let first = editor.is_none();
    let shared = match editor {
        Some(e) => Arc::clone(e),
        None => {
            let library = ndds_components::library();
            match Editor::new(&setup.root, library, Some(setup.participant.clone())) {
                Ok(e) => Arc::clone(editor.insert(Arc::new(std::sync::Mutex::new(e)))),
                Err(e) => return refuse(&e.to_string()),
            }
        }
    };
    // Loading a system to check it designs its controllers: not on the server's threads.
    let answer = tokio::task::spawn_blocking(move || {
        let mut editor = shared
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let result = editor.apply(&op);
        let palette = first.then(|| palette(&ndds_components::library()));
        (result, editor.state(), palette)
    })
    .await;
    Some(match answer {
        Ok((result, state, palette)) => {
            let (ok, text) = match result {
                Ok(text) => (true, text),
                Err(e) => (false, e.to_string()),
            };
            json!({"type": "editor", "id": id, "ok": ok, "text": text, "state": state, "palette": palette})
        }
        Err(e) => json!({"type": "editor", "id": id, "ok": false, "text": e.to_string()}),
    })
}

/// Serves the studio on `listener` until `shutdown` resolves.
pub async fn serve(
    listener: tokio::net::TcpListener,
    hub: Arc<Hub>,
    access: Access,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    axum::serve(listener, router(hub, access))
        .with_graceful_shutdown(shutdown)
        .await
}

/// Whether `addr` is reachable from this host only.
pub fn is_loopback(addr: &SocketAddr) -> bool {
    addr.ip().is_loopback()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_token_is_taken_from_the_query() {
        let uri: axum::http::Uri = "/foxglove?x=1&token=abc".parse().unwrap();
        assert_eq!(query_token(&uri), Some("abc"));
        let uri: axum::http::Uri = "/foxglove".parse().unwrap();
        assert_eq!(query_token(&uri), None);
    }
}

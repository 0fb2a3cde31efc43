//! The client's session with its daemon over the Unix socket: framing, handshake, and
//! request/answer bookkeeping. A reader thread (started by the participant) hands every frame
//! to [`Session::complete`] or to the participant's router.

use std::collections::HashMap;
use std::io::{self, Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::time::Duration;

use ndds_core::ipc::{
    self, ClientMessage, DaemonMessage, EndpointDecl, FRAME_PREFIX, Graph, Hello, MAX_FRAME,
    Welcome,
};
use ndds_core::wire::Guid;

/// One page of the daemon's graph and the guid to continue after.
type GraphPage = (Graph, Option<Guid>);

use ndds_daemon::DaemonConfig;
use ndds_daemon::local;

use crate::error::{ConnectError, DeclareError, QueryError};
use crate::sync::lock;

/// How long the handshake and each request wait for the daemon.
pub(crate) const ANSWER_TIMEOUT: Duration = Duration::from_secs(5);

/// Writes one frame.
pub(crate) fn write_frame(stream: &mut impl Write, message: &ClientMessage) -> io::Result<()> {
    let frame = ipc::encode_frame(message).map_err(io::Error::other)?;
    stream.write_all(&frame)
}

/// Reads one frame; `Ok(None)` when the daemon closed the connection between frames.
pub(crate) fn read_frame(stream: &mut impl Read) -> io::Result<Option<DaemonMessage>> {
    let mut prefix = [0u8; FRAME_PREFIX];
    // End of stream before a frame starts is a clean close; inside a frame it is an error.
    let first = loop {
        match stream.read(&mut prefix[..1]) {
            Ok(n) => break n,
            Err(err) if err.kind() == io::ErrorKind::Interrupted => {}
            Err(err) => return Err(err),
        }
    };
    if first == 0 {
        return Ok(None);
    }
    stream.read_exact(&mut prefix[1..])?;
    let len = u32::from_be_bytes(prefix) as usize;
    if len > MAX_FRAME {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("frame of {len} bytes exceeds {MAX_FRAME}"),
        ));
    }
    // The buffer grows with the bytes that arrive, not with the length the prefix claims.
    let mut body = Vec::new();
    let read = stream.take(len as u64).read_to_end(&mut body)?;
    if read < len {
        return Err(io::Error::new(
            io::ErrorKind::UnexpectedEof,
            format!("the daemon closed the connection {read} bytes into a {len}-byte frame"),
        ));
    }
    ipc::decode_body(&body)
        .map(Some)
        .map_err(|err| io::Error::new(io::ErrorKind::InvalidData, err))
}

/// Connects to the daemon at `path` and opens a session.
pub(crate) fn handshake(path: &Path, hello: Hello) -> Result<(UnixStream, Welcome), ConnectError> {
    let mut stream = UnixStream::connect(path).map_err(|err| ConnectError::NoDaemon {
        path: path.to_owned(),
        reason: no_daemon_reason(&err),
    })?;
    let failed = |reason: String| ConnectError::Handshake {
        path: path.to_owned(),
        reason,
    };
    // Before a byte is sent: a squatter must not even learn our Hello.
    let daemon = local::peer_cred(&stream).map_err(|e| failed(e.to_string()))?;
    local::check_daemon(path, daemon)?;
    stream
        .set_read_timeout(Some(ANSWER_TIMEOUT))
        .map_err(|e| failed(e.to_string()))?;
    write_frame(&mut stream, &ClientMessage::Hello(hello)).map_err(|e| failed(e.to_string()))?;
    let answer = read_frame(&mut stream).map_err(|e| failed(e.to_string()))?;
    stream
        .set_read_timeout(None)
        .map_err(|e| failed(e.to_string()))?;
    match answer {
        Some(DaemonMessage::Welcome(welcome)) => Ok((stream, welcome)),
        Some(DaemonMessage::Refused { reason }) => Err(ConnectError::Refused {
            path: path.to_owned(),
            reason,
        }),
        Some(other) => Err(failed(format!("unexpected first frame {other:?}"))),
        None => Err(failed("the daemon closed the connection".to_owned())),
    }
}

/// Why nobody answered on the socket, in words: a socket file nobody listens on is a stale
/// one, left by a daemon (or a program that embedded one) that did not exit cleanly.
fn no_daemon_reason(err: &io::Error) -> String {
    match err.kind() {
        io::ErrorKind::ConnectionRefused => "a stale socket file: the process that ran the \
             daemon there exited without removing it"
            .to_owned(),
        io::ErrorKind::NotFound => "no socket file".to_owned(),
        _ => err.to_string(),
    }
}

/// The writing half of a session plus the requests waiting for answers.
#[derive(Debug)]
pub(crate) struct Session {
    path: PathBuf,
    hello: Hello,
    writer: Mutex<UnixStream>,
    declares: Mutex<HashMap<u32, SyncSender<Result<(), String>>>>,
    /// Pages of the graph asked for, with the guid to continue after.
    queries: Mutex<HashMap<u32, SyncSender<GraphPage>>>,
    next_request: AtomicU32,
    open: AtomicBool,
    /// Set once the participant is being dropped: no more reconnecting.
    ending: AtomicBool,
    /// The embedded daemon to start when the daemon went away and none answers any more
    /// (`None`: the policy forbids embedding).
    takeover: Option<Takeover>,
    /// Pid of the process whose daemon the session is (or was last) open with.
    daemon_pid: AtomicU32,
    /// Interface address of that daemon.
    daemon_interface: AtomicU32,
}

/// The embedded daemon a participant may start when its daemon went away.
#[derive(Clone, Debug)]
pub(crate) struct Takeover {
    /// Its configuration.
    pub(crate) config: DaemonConfig,
    /// True when the configuration was the application's own choice; otherwise the daemon
    /// takes the interface of the daemon it replaces (where this participant's data socket is).
    pub(crate) explicit: bool,
}

impl Session {
    /// A session on `stream`, opened with `welcome`; `takeover` as in [`Session::takeover`].
    pub(crate) fn new(
        path: PathBuf,
        hello: Hello,
        (stream, welcome): (UnixStream, &Welcome),
        takeover: Option<Takeover>,
    ) -> Self {
        let _ = stream.set_write_timeout(Some(ANSWER_TIMEOUT));
        Session {
            path,
            hello,
            writer: Mutex::new(stream),
            declares: Mutex::new(HashMap::new()),
            queries: Mutex::new(HashMap::new()),
            next_request: AtomicU32::new(1),
            open: AtomicBool::new(true),
            ending: AtomicBool::new(false),
            takeover,
            daemon_pid: AtomicU32::new(welcome.pid),
            daemon_interface: AtomicU32::new(u32::from_be_bytes(welcome.interface)),
        }
    }

    /// The embedded daemon this participant may start to take the role over from a daemon
    /// that went away: `None` when the policy forbids embedding, or when the daemon lost was
    /// this process's own (stopped on purpose, or at exit: not to be restarted here).
    pub(crate) fn takeover(&self) -> Option<DaemonConfig> {
        if self.daemon_pid.load(Ordering::Relaxed) == std::process::id() {
            return None;
        }
        let takeover = self.takeover.as_ref()?;
        let mut config = takeover.config.clone();
        if !takeover.explicit {
            let interface = self.daemon_interface.load(Ordering::Relaxed);
            config.interface = std::net::Ipv4Addr::from(interface);
        }
        Some(config)
    }

    /// The daemon's socket path.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// True until the daemon connection is lost or closed.
    pub(crate) fn is_open(&self) -> bool {
        self.open.load(Ordering::Acquire)
    }

    /// Sends a frame; a failure marks the session closed.
    pub(crate) fn send(&self, message: &ClientMessage) -> io::Result<()> {
        if !self.is_open() {
            return Err(io::Error::new(
                io::ErrorKind::NotConnected,
                "session closed",
            ));
        }
        let result = write_frame(&mut *lock(&self.writer), message);
        if result.is_err() {
            self.mark_closed();
        }
        result
    }

    /// Declares an endpoint and waits for the daemon's verdict.
    pub(crate) fn declare(&self, decl: EndpointDecl) -> Result<(), DeclareError> {
        let (entity, topic) = (decl.entity, decl.topic.clone());
        let (tx, rx) = sync_channel(1);
        lock(&self.declares).insert(entity, tx);
        if self.send(&ClientMessage::Declare(decl)).is_err() {
            lock(&self.declares).remove(&entity);
            return Err(DeclareError::Disconnected);
        }
        let answer = self.wait(&rx, || lock(&self.declares).remove(&entity));
        match answer {
            Some(Ok(())) => Ok(()),
            Some(Err(reason)) => Err(DeclareError::Rejected { topic, reason }),
            None if self.is_open() => Err(DeclareError::Timeout(topic)),
            None => Err(DeclareError::Disconnected),
        }
    }

    /// Asks for the daemon's graph, page by page; endpoints sorted by topic, then guid.
    pub(crate) fn query_graph(&self) -> Result<Graph, QueryError> {
        let (mut graph, mut next) = self.query_graph_page(None)?;
        while let Some(after) = next {
            let (page, more) = self.query_graph_page(Some(after))?;
            graph.endpoints.extend(page.endpoints);
            next = more.filter(|more| *more > after);
        }
        graph.endpoints.sort_by(|a, b| {
            (a.info.topic.as_str(), a.info.guid).cmp(&(b.info.topic.as_str(), b.info.guid))
        });
        Ok(graph)
    }

    fn query_graph_page(&self, after: Option<Guid>) -> Result<GraphPage, QueryError> {
        let request = self.next_request.fetch_add(1, Ordering::Relaxed);
        let (tx, rx) = sync_channel(1);
        lock(&self.queries).insert(request, tx);
        if self
            .send(&ClientMessage::QueryGraph { request, after })
            .is_err()
        {
            lock(&self.queries).remove(&request);
            return Err(QueryError::Disconnected);
        }
        match self.wait(&rx, || lock(&self.queries).remove(&request)) {
            Some(page) => Ok(page),
            None if self.is_open() => Err(QueryError::Timeout),
            None => Err(QueryError::Disconnected),
        }
    }

    /// Waits for an answer; gives up at the timeout or when the session closes.
    fn wait<T, R>(&self, rx: &Receiver<T>, forget: impl FnOnce() -> R) -> Option<T> {
        let answer = rx.recv_timeout(ANSWER_TIMEOUT).ok();
        if answer.is_none() {
            forget();
        }
        answer
    }

    /// Hands an answer frame to the request waiting for it. Returns the frame back if it is
    /// not an answer.
    pub(crate) fn complete(&self, message: DaemonMessage) -> Option<DaemonMessage> {
        match message {
            DaemonMessage::Declared { entity, result } => {
                if let Some(tx) = lock(&self.declares).remove(&entity) {
                    let _ = tx.try_send(result);
                }
                None
            }
            DaemonMessage::Graph {
                request,
                graph,
                next,
            } => {
                if let Some(tx) = lock(&self.queries).remove(&request) {
                    let _ = tx.try_send((graph, next));
                }
                None
            }
            other => Some(other),
        }
    }

    /// Marks the session closed and wakes every waiting request.
    pub(crate) fn mark_closed(&self) {
        self.open.store(false, Ordering::Release);
        lock(&self.declares).clear();
        lock(&self.queries).clear();
    }

    /// Closes the connection (both directions) for good.
    pub(crate) fn shutdown(&self) {
        self.ending.store(true, Ordering::Release);
        self.mark_closed();
        let _ = lock(&self.writer).shutdown(std::net::Shutdown::Both);
    }

    /// True once [`Session::shutdown`] was called.
    pub(crate) fn is_ending(&self) -> bool {
        self.ending.load(Ordering::Acquire)
    }

    /// Opens a new session with the daemon at the same path, as the same participant; returns
    /// the new connection's reading half and the daemon's welcome.
    pub(crate) fn reconnect(&self) -> Result<(UnixStream, Welcome), ConnectError> {
        let (stream, welcome) = handshake(&self.path, self.hello.clone())?;
        let reader = stream.try_clone().map_err(ConnectError::Thread)?;
        self.daemon_pid.store(welcome.pid, Ordering::Relaxed);
        let interface = u32::from_be_bytes(welcome.interface);
        self.daemon_interface.store(interface, Ordering::Relaxed);
        let _ = stream.set_write_timeout(Some(ANSWER_TIMEOUT));
        *lock(&self.writer) = stream;
        if self.is_ending() {
            let _ = lock(&self.writer).shutdown(std::net::Shutdown::Both);
        } else {
            self.open.store(true, Ordering::Release);
        }
        Ok((reader, welcome))
    }

    /// Declares an endpoint without waiting for the answer (used when re-declaring after a
    /// reconnection, from the thread that reads the answers).
    pub(crate) fn declare_async(&self, decl: EndpointDecl) -> io::Result<()> {
        self.send(&ClientMessage::Declare(decl))
    }
}

//! Participants, producers and consumers: the SDK's, with samples encoded by the type's codec.
//!
//! Every call that may block releases the GIL, and waits in slices of [`SLICE`] so that a
//! signal (Ctrl-C) raised meanwhile interrupts it with `KeyboardInterrupt`.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use ndds_client::{
    Batching, ConsumerMode, ConsumerQos, EmbeddedPolicy, Notification, Participant, PollStatus,
    ProducerQos, RawConsumer, RawEvent, RawProducer, RawSample, RecvError, Reliability,
    SampleStatus, WhenFull,
};
use ndds_core::types::{builtin, fingerprint_hex};
use ndds_core::wire::Guid;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::errors::{self, closed};
use crate::typedesc::{DataType, Kind};

/// The longest a blocking call waits without looking for signals.
pub(crate) const SLICE: Duration = Duration::from_millis(50);

/// Seconds (a Python float) as a duration; negative, NaN and infinite values are refused.
pub(crate) fn seconds(what: &str, value: f64) -> PyResult<Duration> {
    Duration::try_from_secs_f64(value).map_err(|_| {
        PyValueError::new_err(format!(
            "{what} must be a finite number of seconds >= 0, got {value}"
        ))
    })
}

/// Runs `attempt` (given how long it may wait) without the GIL, in slices, until it returns
/// something other than "not yet" or `timeout` passes (`None`: no limit). Between slices it
/// checks for signals, so Ctrl-C raises `KeyboardInterrupt`. Returns `Ok(None)` at the timeout.
pub(crate) fn wait_sliced<T, E: Send>(
    py: Python<'_>,
    timeout: Option<Duration>,
    mut attempt: impl FnMut(Duration) -> Result<Option<T>, E> + Send,
    error: impl Fn(E) -> PyErr,
) -> PyResult<Option<T>>
where
    T: Send,
{
    let deadline = timeout.map(|t| Instant::now() + t);
    loop {
        let slice = match deadline {
            Some(deadline) => deadline
                .saturating_duration_since(Instant::now())
                .min(SLICE),
            None => SLICE,
        };
        match py.detach(|| attempt(slice)) {
            Ok(Some(value)) => return Ok(Some(value)),
            Ok(None) => {}
            Err(err) => return Err(error(err)),
        }
        py.check_signals()?;
        if deadline.is_some_and(|d| Instant::now() >= d) {
            return Ok(None);
        }
    }
}

/// Waits up to `timeout` seconds, in slices (see [`wait_sliced`]), until `ready(slice)` says
/// yes; false at the timeout.
fn wait_for(
    py: Python<'_>,
    timeout: f64,
    ready: impl Fn(Duration) -> bool + Sync,
) -> PyResult<bool> {
    let found = wait_sliced(
        py,
        Some(seconds("timeout", timeout)?),
        |slice| Ok::<_, ()>(ready(slice).then_some(())),
        |()| unreachable!("the wait cannot fail"),
    )?;
    Ok(found.is_some())
}

fn epoch_seconds(time: SystemTime) -> f64 {
    time.duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// A connection to the domain: the local daemon, else an embedded one.
#[pyclass(module = "ndds._ndds", name = "Participant", subclass)]
pub(crate) struct PyParticipant {
    /// `None` once closed.
    inner: Mutex<Option<Participant>>,
}

impl PyParticipant {
    /// The participant, or ndds.Disconnected once closed.
    pub(crate) fn get(&self) -> PyResult<Participant> {
        self.inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
            .ok_or_else(|| errors::Disconnected::new_err("the participant is closed"))
    }
}

#[pymethods]
impl PyParticipant {
    #[new]
    #[pyo3(signature = (*, domain=None, socket=None, key_file=None, integrity_only=false, name=None, embedded="auto"))]
    fn new(
        py: Python<'_>,
        domain: Option<u16>,
        socket: Option<PathBuf>,
        key_file: Option<PathBuf>,
        integrity_only: bool,
        name: Option<String>,
        embedded: &str,
    ) -> PyResult<Self> {
        let policy: EmbeddedPolicy = embedded.parse().map_err(|err: String| {
            PyValueError::new_err(format!("embedded: {err} (auto, never or always)"))
        })?;
        let mut builder = Participant::builder().embedded(policy);
        if let Some(domain) = domain {
            builder = builder.domain(domain);
        }
        if let Some(socket) = socket {
            builder = builder.socket(socket);
        }
        if let Some(key_file) = key_file {
            builder = builder.key_file(key_file).integrity_only(integrity_only);
        }
        builder = builder.name(name.unwrap_or_else(|| "python".to_owned()));
        let inner = py
            .detach(|| builder.connect())
            .map_err(errors::connect_error)?;
        Ok(PyParticipant {
            inner: Mutex::new(Some(inner)),
        })
    }

    /// This participant's id (16 hex digits), as tools show it.
    #[getter]
    fn id(&self) -> PyResult<String> {
        Ok(format!("{:016x}", self.get()?.id()))
    }

    /// Whether the connection to the daemon is up.
    #[getter]
    fn connected(&self) -> bool {
        self.get().is_ok_and(|p| p.is_connected())
    }

    /// Closes this handle on the connection: later declarations raise ndds.Disconnected.
    /// Endpoints declared already keep working until they are closed or collected (each
    /// holds the connection too).
    fn close(&self) {
        self.inner.lock().unwrap_or_else(|p| p.into_inner()).take();
    }

    /// Declares a producer (see `ndds.Participant.producer`).
    #[pyo3(signature = (topic, data_type, *, strength=0, persistence=1.0, reliable=false, history=None,
        batching=None, when_full="block", write_timeout=1.0, late_joiners=0))]
    #[allow(clippy::too_many_arguments)]
    fn _producer(
        &self,
        py: Python<'_>,
        topic: &str,
        data_type: Py<DataType>,
        strength: i32,
        persistence: f64,
        reliable: bool,
        history: Option<u32>,
        batching: Option<(f64, usize)>,
        when_full: &str,
        write_timeout: f64,
        late_joiners: usize,
    ) -> PyResult<PyProducer> {
        let qos = ProducerQos {
            strength,
            persistence: seconds("persistence", persistence)?,
            reliability: reliability(reliable, history)?,
            batching: match batching {
                None => Batching::Off,
                Some((max_delay, max_bytes)) => Batching::On {
                    max_delay: seconds("batching delay", max_delay)?,
                    max_bytes,
                },
            },
            when_full: match when_full {
                "block" => WhenFull::Block,
                "drop_oldest" => WhenFull::DropOldest,
                other => {
                    return Err(PyValueError::new_err(format!(
                        "when_full: {other:?} is not block or drop_oldest"
                    )));
                }
            },
            write_timeout: seconds("write_timeout", write_timeout)?,
            late_joiners,
        };
        let desc = data_type.get().desc.clone();
        let participant = self.get()?;
        let topic = topic.to_owned();
        let raw = py
            .detach(move || participant.raw_producer(&topic, desc, qos))
            .map_err(errors::declare_error)?;
        Ok(PyProducer {
            raw: Mutex::new(Some(Arc::new(raw))),
            data_type,
        })
    }

    /// Declares a consumer (see `ndds.Participant.consumer`).
    #[pyo3(signature = (topic, data_type, *, mode="immediate", depth=64, min_separation=0.0,
        deadline=None, reliable=false, history=None, every_producer=false))]
    #[allow(clippy::too_many_arguments)]
    fn _consumer(
        &self,
        py: Python<'_>,
        topic: &str,
        data_type: Py<DataType>,
        mode: &str,
        depth: usize,
        min_separation: f64,
        deadline: Option<f64>,
        reliable: bool,
        history: Option<u32>,
        every_producer: bool,
    ) -> PyResult<PyConsumer> {
        let qos = ConsumerQos {
            mode: match mode {
                "immediate" => ConsumerMode::Immediate,
                "polled" => ConsumerMode::Polled,
                other => {
                    return Err(PyValueError::new_err(format!(
                        "mode: {other:?} is not immediate or polled"
                    )));
                }
            },
            depth,
            min_separation: seconds("min_separation", min_separation)?,
            deadline: deadline.map(|d| seconds("deadline", d)).transpose()?,
            reliability: reliability(reliable, history)?,
            every_producer,
        };
        if depth == 0 {
            return Err(PyValueError::new_err("depth must be at least 1"));
        }
        let desc = data_type.get().desc.clone();
        let participant = self.get()?;
        let topic = topic.to_owned();
        let raw = py
            .detach(move || participant.raw_consumer(&topic, desc, qos))
            .map_err(errors::declare_error)?;
        Ok(PyConsumer {
            raw: Mutex::new(Some(Arc::new(raw))),
            data_type,
        })
    }

    /// The type announced on `topic` by its endpoints (producers first), as an untyped
    /// DataType (structs as dicts), or None while no endpoint of the topic is known.
    fn _topic_type(
        &self,
        py: Python<'_>,
        topic: &str,
        csmat: Py<PyAny>,
    ) -> PyResult<Option<DataType>> {
        let participant = self.get()?;
        let graph = py
            .detach(move || participant.graph())
            .map_err(errors::query_error)?;
        let mut endpoints: Vec<_> = graph
            .endpoints
            .iter()
            .filter(|e| e.info.topic == topic)
            .collect();
        // Producers first (theirs is the type the samples have), and among them those whose
        // type has a layout (an opaque one cannot be decoded).
        endpoints.sort_by_key(|e| {
            (
                !matches!(e.info.kind(), ndds_core::wire::EndpointKind::Producer),
                e.info.type_desc.layout.is_none(),
            )
        });
        let Some(endpoint) = endpoints.first() else {
            return Ok(None);
        };
        let desc = endpoint.info.type_desc.clone();
        if desc.name == builtin::CSMAT {
            return Ok(Some(crate::typedesc::csmat_type(csmat)));
        }
        DataType::plain(py, desc).map(Some)
    }

    /// The daemon's view of the domain: nodes, clients and endpoints, as `ndds topics` shows.
    fn topics(&self, py: Python<'_>) -> PyResult<Vec<(String, String, String, String)>> {
        let participant = self.get()?;
        let graph = py
            .detach(move || participant.graph())
            .map_err(errors::query_error)?;
        Ok(graph
            .endpoints
            .iter()
            .map(|e| {
                (
                    e.info.topic.clone(),
                    format!("{:?}", e.info.kind()).to_lowercase(),
                    e.info.type_desc.name.clone(),
                    fingerprint_hex(e.info.fingerprint),
                )
            })
            .collect())
    }

    fn __repr__(&self) -> String {
        match self.get() {
            Ok(p) => format!("<ndds.Participant {:016x}>", p.id()),
            Err(_) => "<ndds.Participant (closed)>".to_owned(),
        }
    }
}

fn reliability(reliable: bool, history: Option<u32>) -> PyResult<Reliability> {
    match (reliable, history) {
        (false, None) => Ok(Reliability::BestEffort),
        (false, Some(_)) => Err(PyValueError::new_err(
            "history applies to reliable endpoints: pass reliable=True",
        )),
        (true, Some(0)) => Err(PyValueError::new_err("history must be at least 1")),
        (true, depth) => Ok(Reliability::Reliable {
            depth: depth.unwrap_or(DEFAULT_HISTORY),
        }),
    }
}

/// A reliable endpoint's history when none is given (the SDK's examples use 64).
const DEFAULT_HISTORY: u32 = 64;

/// Encodes `value` as a sample of `kind`.
pub(crate) fn encode(kind: &Kind, value: &Bound<'_, PyAny>) -> PyResult<Vec<u8>> {
    match kind {
        Kind::Dynamic(codec) => codec.encode(value),
        Kind::CsMat(_) => encode_csmat(value),
    }
}

/// Decodes a sample of `kind`.
pub(crate) fn decode<'py>(
    py: Python<'py>,
    kind: &Kind,
    payload: &[u8],
) -> PyResult<Bound<'py, PyAny>> {
    match kind {
        Kind::Dynamic(codec) => codec.decode(py, payload),
        Kind::CsMat(factory) => decode_csmat(py, factory, payload),
    }
}

/// `ndds.CsMat` → the runtime's CSMat encoding. The object gives its parts with `_wire()`:
/// `(name, rows, cols, data, row_fields, col_fields)`, data as row-major float64 bytes.
fn encode_csmat(value: &Bound<'_, PyAny>) -> PyResult<Vec<u8>> {
    type Wire = (
        String,
        usize,
        usize,
        Vec<u8>,
        Vec<(String, String)>,
        Vec<(String, String)>,
    );
    let wire = value.call_method0("_wire").map_err(|_| {
        PyTypeError::new_err(format!(
            "sample: expected an ndds.CsMat, got {}",
            value
                .get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default()
        ))
    })?;
    let (name, rows, cols, bytes, row_fields, col_fields): Wire = wire.extract()?;
    let data: Vec<f64> = bytes
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
        .collect();
    fn pairs(list: &[(String, String)]) -> impl Iterator<Item = (&str, &str)> {
        list.iter().map(|(n, u)| (n.as_str(), u.as_str()))
    }
    let mut mat = ndds_runtime::CsMat::from_row_slice(name, rows, cols, &data)
        .map_err(|err| PyValueError::new_err(err.to_string()))?;
    // No fields on an axis is allowed; otherwise one per row (column), checked by the runtime.
    if !row_fields.is_empty() {
        mat = mat
            .with_row_fields(pairs(&row_fields))
            .map_err(|err| PyValueError::new_err(err.to_string()))?;
    }
    if !col_fields.is_empty() {
        mat = mat
            .with_col_fields(pairs(&col_fields))
            .map_err(|err| PyValueError::new_err(err.to_string()))?;
    }
    postcard::to_stdvec(&mat).map_err(|err| PyValueError::new_err(err.to_string()))
}

fn decode_csmat<'py>(
    py: Python<'py>,
    factory: &Py<PyAny>,
    payload: &[u8],
) -> PyResult<Bound<'py, PyAny>> {
    let mut mat = ndds_runtime::CsMat::zeros("", 0, 0);
    mat.decode_into(payload)
        .map_err(|err| PyValueError::new_err(format!("the CSMat sample does not decode: {err}")))?;
    csmat_object(py, factory, &mat)
}

/// An `ndds.CsMat` made by `factory` from the runtime's CSMat.
pub(crate) fn csmat_object<'py>(
    py: Python<'py>,
    factory: &Py<PyAny>,
    mat: &ndds_runtime::CsMat,
) -> PyResult<Bound<'py, PyAny>> {
    let (rows, cols) = mat.shape();
    let m = mat.matrix();
    // Row-major, as NumPy's default order and the wire's.
    let mut bytes = Vec::with_capacity(rows.saturating_mul(cols).saturating_mul(8));
    for r in 0..rows {
        for c in 0..cols {
            bytes.extend_from_slice(&m[(r, c)].to_le_bytes());
        }
    }
    let fields = |list: &[ndds_runtime::Field]| -> Vec<(String, String)> {
        list.iter()
            .map(|f| (f.name.clone(), f.unit.clone()))
            .collect()
    };
    let args = (
        mat.name().to_owned(),
        rows,
        cols,
        PyBytes::new(py, &bytes),
        fields(mat.row_fields()),
        fields(mat.col_fields()),
    );
    factory.bind(py).call1(args)
}

/// A producer of one topic.
#[pyclass(module = "ndds._ndds", name = "Producer", subclass)]
pub(crate) struct PyProducer {
    raw: Mutex<Option<Arc<RawProducer>>>,
    data_type: Py<DataType>,
}

impl PyProducer {
    fn raw(&self) -> PyResult<Arc<RawProducer>> {
        self.raw
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
            .ok_or_else(closed)
    }
}

#[pymethods]
impl PyProducer {
    /// Writes one sample. A value that does not fit the type raises TypeError naming the
    /// field; a reliable producer whose consumers lag blocks up to `write_timeout`, then
    /// raises ndds.Timeout.
    fn write(&self, py: Python<'_>, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let bytes = encode(&self.data_type.get().kind, value)?;
        let raw = self.raw()?;
        if raw.qos().reliability == Reliability::BestEffort {
            // Best effort never blocks: no need to give up the GIL.
            return raw.write_bytes(&bytes).map_err(errors::write_error);
        }
        py.detach(|| raw.write_bytes(&bytes))
            .map_err(errors::write_error)
    }

    /// Sends what batching holds now.
    fn flush(&self, py: Python<'_>) -> PyResult<()> {
        let raw = self.raw()?;
        py.detach(|| raw.flush()).map_err(errors::write_error)
    }

    /// Waits until at least `count` consumers are matched; False at the timeout.
    #[pyo3(signature = (count=1, timeout=5.0))]
    fn wait_for_consumers(&self, py: Python<'_>, count: usize, timeout: f64) -> PyResult<bool> {
        let raw = self.raw()?;
        wait_for(py, timeout, |slice| raw.wait_for_consumers(count, slice))
    }

    /// Reliable: waits until every matched consumer acknowledged everything written; False
    /// at the timeout.
    #[pyo3(signature = (timeout=5.0))]
    fn wait_for_acknowledgments(&self, py: Python<'_>, timeout: f64) -> PyResult<bool> {
        let raw = self.raw()?;
        wait_for(py, timeout, |slice| raw.wait_for_acknowledgments(slice))
    }

    /// The number of consumers matched now.
    #[getter]
    fn matched(&self) -> PyResult<usize> {
        Ok(self.raw()?.matched().len())
    }

    /// Samples written so far.
    #[getter]
    fn written(&self) -> PyResult<u64> {
        Ok(self.raw()?.written())
    }

    /// The topic.
    #[getter]
    fn topic(&self) -> PyResult<String> {
        Ok(self.raw()?.topic().to_owned())
    }

    /// The sample type.
    #[getter]
    fn data_type(&self, py: Python<'_>) -> Py<DataType> {
        self.data_type.clone_ref(py)
    }

    /// Withdraws the producer; later calls raise ndds.Disconnected.
    fn close(&self) {
        self.raw.lock().unwrap_or_else(|p| p.into_inner()).take();
    }
}

/// A sample as a consumer receives it.
#[pyclass(module = "ndds._ndds", name = "Sample", frozen)]
pub(crate) struct PySample {
    value: Py<PyAny>,
    writer: Guid,
    seq: u64,
    source_time: f64,
    reception_time: f64,
    strength: i32,
    status: SampleStatus,
}

#[pymethods]
impl PySample {
    /// The value: an instance of the consumer's type, a dict (untyped) or an ndds.CsMat.
    #[getter]
    fn value(&self, py: Python<'_>) -> Py<PyAny> {
        self.value.clone_ref(py)
    }

    /// The producer, `participant.entity` (the participant in hex), as tools show it.
    #[getter]
    fn writer(&self) -> String {
        self.writer.to_string()
    }

    /// The producer's sequence number.
    #[getter]
    fn seq(&self) -> u64 {
        self.seq
    }

    /// When it was written: seconds since the epoch, by the producer's clock.
    #[getter]
    fn source_time(&self) -> f64 {
        self.source_time
    }

    /// When it arrived: seconds since the epoch.
    #[getter]
    fn reception_time(&self) -> f64 {
        self.reception_time
    }

    /// The producer's strength.
    #[getter]
    fn strength(&self) -> i32 {
        self.strength
    }

    /// `fresh`, or `took_over` for the first sample of a producer that took over the topic
    /// from another (see `previous_writer`).
    #[getter]
    fn status(&self) -> &'static str {
        match self.status {
            SampleStatus::Fresh => "fresh",
            SampleStatus::TookOver { .. } => "took_over",
        }
    }

    /// The producer in charge before this one took over, if it did.
    #[getter]
    fn previous_writer(&self) -> Option<String> {
        match self.status {
            SampleStatus::Fresh => None,
            SampleStatus::TookOver { previous } => Some(previous.to_string()),
        }
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let value = self
            .value
            .bind(py)
            .repr()
            .map(|r| r.to_string())
            .unwrap_or_default();
        format!(
            "Sample(value={value}, writer={}, seq={})",
            self.writer, self.seq
        )
    }
}

fn sample(py: Python<'_>, kind: &Kind, raw: RawSample) -> PyResult<PySample> {
    let value = decode(py, kind, &raw.payload)?.unbind();
    let info = raw.info;
    Ok(PySample {
        value,
        writer: info.writer,
        seq: info.seq,
        source_time: epoch_seconds(info.source_timestamp),
        reception_time: epoch_seconds(info.reception_timestamp),
        strength: info.strength,
        status: info.status,
    })
}

/// `TookOver { previous: .. }` → `took_over`.
fn snake(debug: &str) -> String {
    let head = debug.split([' ', '{', '(']).next().unwrap_or(debug);
    let mut out = String::new();
    for (i, c) in head.chars().enumerate() {
        if c.is_uppercase() {
            if i > 0 {
                out.push('_');
            }
            out.extend(c.to_lowercase());
        } else {
            out.push(c);
        }
    }
    out
}

/// A notification: something a consumer is told without a sample.
#[pyclass(module = "ndds._ndds", name = "Notification", frozen, get_all)]
pub(crate) struct PyNotification {
    /// `no_new_data`, `never_received`, `old_data`, `producer_lost`, `incompatible`,
    /// `not_permitted`, `samples_lost` or `deserialization_error`.
    kind: String,
    /// What happened, in words.
    message: String,
    /// The producer concerned, if one is.
    writer: Option<String>,
    /// Seconds without data (`no_new_data`, `never_received`).
    silent_for: Option<f64>,
    /// The lost sequence numbers `[first, end)` (`samples_lost`).
    lost: Option<(u64, u64)>,
}

#[pymethods]
impl PyNotification {
    fn __repr__(&self) -> String {
        format!("Notification({}: {})", self.kind, self.message)
    }
}

fn notification(n: Notification) -> PyNotification {
    let kind = snake(&format!("{n:?}"));
    let (message, writer, silent_for, lost) = match &n {
        Notification::NoNewData { silent_for } => (
            format!("no new data for {:.3} s", silent_for.as_secs_f64()),
            None,
            Some(silent_for.as_secs_f64()),
            None,
        ),
        Notification::NeverReceived { waited } => (
            format!("no sample ever received ({:.3} s)", waited.as_secs_f64()),
            None,
            Some(waited.as_secs_f64()),
            None,
        ),
        Notification::OldData { writer, seq } => (
            format!("old sample {seq} from {writer} dropped"),
            Some(writer.to_string()),
            None,
            None,
        ),
        Notification::ProducerLost {
            writer,
            was_current,
        } => (
            format!(
                "producer {writer} lost{}",
                if *was_current {
                    " (it was in charge)"
                } else {
                    ""
                }
            ),
            Some(writer.to_string()),
            None,
            None,
        ),
        Notification::Incompatible {
            reason,
            writer,
            type_name,
            fingerprint,
            local_type,
            local_fingerprint,
        } => (
            format!(
                "incompatible producer {writer} ({reason:?}): it writes {type_name} ({}), this \
                 consumer takes {local_type} ({})",
                fingerprint_hex(*fingerprint),
                fingerprint_hex(*local_fingerprint)
            ),
            Some(writer.to_string()),
            None,
            None,
        ),
        Notification::NotPermitted { writer, reason } => (
            format!("producer {writer} not permitted: {reason}"),
            Some(writer.to_string()),
            None,
            None,
        ),
        Notification::DeserializationError { writer, seq, error } => (
            format!("sample {seq} from {writer} does not decode: {error}"),
            Some(writer.to_string()),
            None,
            None,
        ),
        Notification::SamplesLost { writer, from, to } => (
            format!("samples {from}..{to} of {writer} are lost"),
            Some(writer.to_string()),
            None,
            Some((*from, *to)),
        ),
    };
    PyNotification {
        kind,
        message,
        writer,
        silent_for,
        lost,
    }
}

/// A consumer of one topic.
#[pyclass(module = "ndds._ndds", name = "Consumer", subclass)]
pub(crate) struct PyConsumer {
    raw: Mutex<Option<Arc<RawConsumer>>>,
    data_type: Py<DataType>,
}

impl PyConsumer {
    fn is_closed(&self) -> bool {
        self.raw.lock().unwrap_or_else(|p| p.into_inner()).is_none()
    }

    fn raw(&self) -> PyResult<Arc<RawConsumer>> {
        self.raw
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
            .ok_or_else(closed)
    }
}

/// A timeout given in seconds (`None`: wait forever).
fn timeout_arg(timeout: Option<f64>) -> PyResult<Option<Duration>> {
    timeout.map(|t| seconds("timeout", t)).transpose()
}

#[pymethods]
impl PyConsumer {
    /// Waits for the next sample (notifications are skipped) up to `timeout` seconds
    /// (None: no limit); raises ndds.Timeout, whose message names producers of the topic
    /// that are not matched with this consumer and why (another type, for instance).
    #[pyo3(signature = (timeout=None))]
    fn recv(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<PySample> {
        let raw = self.raw()?;
        let timeout = timeout_arg(timeout)?;
        // A sample already queued is taken without giving up the GIL (which costs more than
        // the take itself when samples stream in).
        match raw.try_recv_raw() {
            Ok(raw_sample) => return sample(py, &self.data_type.get().kind, raw_sample),
            Err(RecvError::Empty | RecvError::Timeout) => {}
            Err(err) => return Err(errors::recv_error(err)),
        }
        let got = wait_sliced(
            py,
            timeout,
            |slice| match raw.recv_raw_wait(slice) {
                // Closed from another thread meanwhile.
                Err(RecvError::Timeout) if self.is_closed() => Err(RecvError::Closed),
                Ok(sample) => Ok(Some(sample)),
                Err(RecvError::Timeout) => Ok(None),
                Err(err) => Err(err),
            },
            errors::recv_error,
        )?;
        match got {
            Some(raw_sample) => sample(py, &self.data_type.get().kind, raw_sample),
            // One last look, which explains the timeout (unmatched producers).
            None => match raw.recv_raw_timeout(Duration::ZERO) {
                Ok(raw_sample) => sample(py, &self.data_type.get().kind, raw_sample),
                Err(RecvError::Timeout) => Err(crate::errors::Timeout::new_err(format!(
                    "no sample on `{}` within {:.3} s",
                    raw.topic(),
                    timeout.unwrap_or_default().as_secs_f64()
                ))),
                // The explanation of the last look: it waited the whole timeout, not zero.
                Err(RecvError::TimeoutUnmatched(mut unmatched)) => {
                    unmatched.waited = timeout.unwrap_or_default();
                    Err(errors::recv_error(RecvError::TimeoutUnmatched(unmatched)))
                }
                Err(err) => Err(errors::recv_error(err)),
            },
        }
    }

    /// The next queued sample, or None without waiting.
    fn try_recv(&self, py: Python<'_>) -> PyResult<Option<PySample>> {
        let raw = self.raw()?;
        match raw.try_recv_raw() {
            Ok(raw_sample) => sample(py, &self.data_type.get().kind, raw_sample).map(Some),
            Err(RecvError::Empty | RecvError::Timeout) => Ok(None),
            Err(err) => Err(errors::recv_error(err)),
        }
    }

    /// Waits for the next sample or notification up to `timeout` seconds; returns an
    /// ndds.Sample or an ndds.Notification, or raises ndds.Timeout.
    #[pyo3(signature = (timeout=None))]
    fn recv_event(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<Py<PyAny>> {
        let raw = self.raw()?;
        let timeout = timeout_arg(timeout)?;
        let got = wait_sliced(
            py,
            timeout,
            |slice| match raw.recv_raw_event_timeout(slice) {
                Err(RecvError::Timeout) if self.is_closed() => Err(RecvError::Closed),
                Ok(event) => Ok(Some(event)),
                Err(RecvError::Timeout) => Ok(None),
                Err(err) => Err(err),
            },
            errors::recv_error,
        )?;
        match got {
            Some(RawEvent::Sample(raw_sample)) => {
                Ok(Py::new(py, sample(py, &self.data_type.get().kind, raw_sample)?)?.into_any())
            }
            Some(RawEvent::Notification(n)) => Ok(Py::new(py, notification(n))?.into_any()),
            None => Err(crate::errors::Timeout::new_err(format!(
                "no sample or notification on `{}` within {:.3} s",
                raw.topic(),
                timeout.unwrap_or_default().as_secs_f64()
            ))),
        }
    }

    /// Polled mode: `(sample or None, status)`, status one of `never_received`, `fresh`,
    /// `unchanged`, `no_new_data`. Never waits.
    fn poll(&self, py: Python<'_>) -> PyResult<(Option<PySample>, String)> {
        let raw = self.raw()?;
        let (got, status) = raw.poll_raw().map_err(errors::recv_error)?;
        let status = match status {
            PollStatus::NeverReceived => "never_received",
            PollStatus::Fresh => "fresh",
            PollStatus::Unchanged => "unchanged",
            PollStatus::NoNewData => "no_new_data",
        };
        let got = got
            .map(|s| sample(py, &self.data_type.get().kind, s))
            .transpose()?;
        Ok((got, status.to_owned()))
    }

    /// Polled mode: the notifications raised since the last call.
    fn take_notifications(&self) -> PyResult<Vec<PyNotification>> {
        let raw = self.raw()?;
        Ok(raw
            .take_notifications()
            .map_err(errors::recv_error)?
            .into_iter()
            .map(notification)
            .collect())
    }

    /// Waits until at least `count` producers are matched; False at the timeout.
    #[pyo3(signature = (count=1, timeout=5.0))]
    fn wait_for_producers(&self, py: Python<'_>, count: usize, timeout: f64) -> PyResult<bool> {
        let raw = self.raw()?;
        wait_for(py, timeout, |slice| raw.wait_for_producers(count, slice))
    }

    /// The number of producers matched now.
    #[getter]
    fn matched(&self) -> PyResult<usize> {
        Ok(self.raw()?.matched().len())
    }

    /// Producers of the topic this consumer is not matched with, and why.
    #[getter]
    fn incompatible(&self) -> PyResult<Vec<(String, String, String)>> {
        Ok(self
            .raw()?
            .incompatible()
            .into_iter()
            .map(|e| {
                (
                    e.guid.to_string(),
                    e.type_desc.name.clone(),
                    fingerprint_hex(e.fingerprint),
                )
            })
            .collect())
    }

    /// The topic.
    #[getter]
    fn topic(&self) -> PyResult<String> {
        Ok(self.raw()?.topic().to_owned())
    }

    /// The sample type.
    #[getter]
    fn data_type(&self, py: Python<'_>) -> Py<DataType> {
        self.data_type.clone_ref(py)
    }

    /// Whether `close()` was called.
    #[getter]
    fn closed(&self) -> bool {
        self.is_closed()
    }

    /// Withdraws the consumer; a blocked `recv` ends within 50 ms with ndds.Disconnected.
    fn close(&self) {
        self.raw.lock().unwrap_or_else(|p| p.into_inner()).take();
    }
}

//! Ports: the SDK's `PortUser` and `PortOwner` over messages encoded by the types' codecs
//! (`Encoded`, declared with the types' descriptions, so a Python user matches a Rust owner of
//! the same message shapes and the other way round).

use std::sync::{Arc, Mutex};

use ndds_client::ports::{
    Encoded, PortError, PortOwner, PortUser, ReplyHandle, Restrictions, Usage,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::endpoints::{PyParticipant, decode, encode, seconds, wait_sliced};
use crate::errors;
use crate::typedesc::{DataType, Kind};

fn usage(name: &str) -> PyResult<Usage> {
    Ok(match name {
        "send" => Usage::Send,
        "query" => Usage::Query,
        "receive" => Usage::Receive,
        "receive_all" => Usage::ReceiveAll,
        "response" => Usage::Response,
        "send_all" => Usage::SendAll,
        "call_all" => Usage::CallAll,
        other => {
            return Err(PyValueError::new_err(format!(
                "unknown usage {other:?} (send, query, receive, receive_all, response, \
                 send_all, call_all)"
            )));
        }
    })
}

fn usages(names: &[String]) -> PyResult<Vec<Usage>> {
    names.iter().map(|n| usage(n)).collect()
}

/// A user of a port: sends requests to its owner and takes what the owner sends to all.
#[pyclass(module = "ndds._ndds", name = "PortUser", subclass)]
pub(crate) struct PyPortUser {
    inner: Arc<PortUser<Encoded, Encoded>>,
    request: Arc<Kind>,
    reply: Arc<Kind>,
}

#[pymethods]
impl PyPortUser {
    #[new]
    #[pyo3(signature = (participant, port, task, request_type, reply_type, usages=vec!["send".to_owned()]))]
    fn new(
        py: Python<'_>,
        participant: PyRef<'_, PyParticipant>,
        port: &str,
        task: &str,
        request_type: PyRef<'_, DataType>,
        reply_type: PyRef<'_, DataType>,
        usages: Vec<String>,
    ) -> PyResult<Self> {
        let usages = self::usages(&usages)?;
        let (request_desc, reply_desc) = (request_type.desc.clone(), reply_type.desc.clone());
        let participant = participant.get()?;
        let (port, task) = (port.to_owned(), task.to_owned());
        let inner = py
            .detach(move || {
                PortUser::declare_described(
                    &participant,
                    &port,
                    &task,
                    &usages,
                    &request_desc,
                    &reply_desc,
                )
            })
            .map_err(errors::port_error)?;
        Ok(Self {
            inner: Arc::new(inner),
            request: request_type.kind.clone(),
            reply: reply_type.kind.clone(),
        })
    }

    /// Sends `value` to the owner and waits up to `timeout` seconds for its reply.
    #[pyo3(signature = (value, timeout=5.0))]
    fn send(&self, py: Python<'_>, value: &Bound<'_, PyAny>, timeout: f64) -> PyResult<Py<PyAny>> {
        self.call(py, value, timeout, false)
    }

    /// Queries the owner (its responders answer by priority) and waits up to `timeout`.
    #[pyo3(signature = (value, timeout=5.0))]
    fn query(&self, py: Python<'_>, value: &Bound<'_, PyAny>, timeout: f64) -> PyResult<Py<PyAny>> {
        self.call(py, value, timeout, true)
    }

    /// Takes the next message the owner sent to all users (`sendall`), waiting up to
    /// `timeout` seconds, answers it with `answer(message)` and returns the message. If
    /// `answer` raises, the owner gets no reply from this user and the exception is raised
    /// here. The wait is not sliced (the SDK's own timing of the reply depends on it): Ctrl-C
    /// takes effect when it ends.
    #[pyo3(signature = (answer, timeout=5.0))]
    fn receive_all(&self, py: Python<'_>, answer: Py<PyAny>, timeout: f64) -> PyResult<Py<PyAny>> {
        let inner = self.inner.clone();
        let limit = seconds("timeout", timeout)?;
        let (request, reply) = (self.request.clone(), self.reply.clone());
        // The answer runs on this thread with the GIL taken back; its error is kept and
        // raised once the call returns.
        let mut failure: Option<PyErr> = None;
        let got = py.detach(|| {
            inner.receive_all_or_decline(limit, |message: &Encoded| {
                Python::attach(|py| {
                    let result = decode(py, &request, &message.0)
                        .and_then(|m| answer.bind(py).call1((m,)))
                        .and_then(|r| encode(&reply, &r));
                    match result {
                        Ok(bytes) => Some(Encoded(bytes)),
                        Err(err) => {
                            failure = Some(err);
                            None
                        }
                    }
                })
            })
        });
        if let Some(err) = failure {
            return Err(err);
        }
        let message = got.map_err(errors::port_error)?;
        Ok(decode(py, &self.request, &message.0)?.unbind())
    }

    /// The port's name.
    #[getter]
    fn port(&self) -> String {
        self.inner.port().to_owned()
    }
}

impl PyPortUser {
    fn call(
        &self,
        py: Python<'_>,
        value: &Bound<'_, PyAny>,
        timeout: f64,
        query: bool,
    ) -> PyResult<Py<PyAny>> {
        let message = Encoded(encode(&self.request, value)?);
        let timeout = seconds("timeout", timeout)?;
        let inner = self.inner.clone();
        // Not sliced: a request is sent once and waited for up to its timeout.
        let reply = py
            .detach(move || {
                if query {
                    inner.query(&message, timeout)
                } else {
                    inner.send(&message, timeout)
                }
            })
            .map_err(errors::port_error)?;
        Ok(decode(py, &self.reply, &reply.0)?.unbind())
    }
}

/// The owner of a port: receives requests and replies to each.
#[pyclass(module = "ndds._ndds", name = "PortOwner", subclass)]
pub(crate) struct PyPortOwner {
    inner: Arc<PortOwner<Encoded, Encoded>>,
    request: Arc<Kind>,
    reply: Arc<Kind>,
}

#[pymethods]
impl PyPortOwner {
    #[new]
    #[pyo3(signature = (participant, port, task, request_type, reply_type, *, usages=Vec::new(),
        users=Vec::new(), max_users=None, timeout=None, priority=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        participant: PyRef<'_, PyParticipant>,
        port: &str,
        task: &str,
        request_type: PyRef<'_, DataType>,
        reply_type: PyRef<'_, DataType>,
        usages: Vec<String>,
        users: Vec<String>,
        max_users: Option<u32>,
        timeout: Option<f64>,
        priority: Option<i32>,
    ) -> PyResult<Self> {
        let restrictions = Restrictions {
            usages: self::usages(&usages)?,
            users,
            max_users,
            timeout_ms: timeout
                .map(|t| seconds("timeout", t).map(|d| d.as_millis() as u64))
                .transpose()?,
            priority,
            ..Restrictions::default()
        };
        let (request_desc, reply_desc) = (request_type.desc.clone(), reply_type.desc.clone());
        let participant = participant.get()?;
        let (port, task) = (port.to_owned(), task.to_owned());
        let inner = py
            .detach(move || {
                PortOwner::declare_described(
                    &participant,
                    &port,
                    &task,
                    restrictions,
                    &request_desc,
                    &reply_desc,
                )
            })
            .map_err(errors::port_error)?;
        Ok(Self {
            inner: Arc::new(inner),
            request: request_type.kind.clone(),
            reply: reply_type.kind.clone(),
        })
    }

    /// Waits up to `timeout` seconds (None: no limit) for the next request; returns it as an
    /// ndds.Request, whose `reply(value)` answers its sender.
    #[pyo3(signature = (timeout=None))]
    fn receive(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<PyRequest> {
        let inner = self.inner.clone();
        let limit = timeout.map(|t| seconds("timeout", t)).transpose()?;
        let got = wait_sliced(
            py,
            limit,
            |slice| match inner.receive(slice) {
                Ok(got) => Ok(Some(got)),
                Err(PortError::Timeout { .. }) => Ok(None),
                Err(err) => Err(err),
            },
            errors::port_error,
        )?;
        let Some((message, handle)) = got else {
            return Err(errors::Timeout::new_err(format!(
                "port `{}`: no request within {:.3} s",
                self.inner.port(),
                limit.unwrap_or_default().as_secs_f64()
            )));
        };
        Ok(PyRequest {
            value: decode(py, &self.request, &message.0)?.unbind(),
            sender: handle.sender().to_owned(),
            handle: Mutex::new(Some(handle)),
            reply: self.reply.clone(),
        })
    }

    /// `sendall`: sends `value` to every user that takes messages to all and waits up to
    /// `timeout` seconds for the first reply; then takes the replies that come within
    /// `collect` seconds more. Returns `[(user, reply), ...]`, first first; raises
    /// ndds.Timeout if nobody replied.
    #[pyo3(signature = (value, timeout=5.0, collect=0.0))]
    fn sendall(
        &self,
        py: Python<'_>,
        value: &Bound<'_, PyAny>,
        timeout: f64,
        collect: f64,
    ) -> PyResult<Vec<(String, Py<PyAny>)>> {
        let message = Encoded(encode(&self.request, value)?);
        let limit = seconds("timeout", timeout)?;
        let collect = seconds("collect", collect)?;
        let inner = self.inner.clone();
        let replies = py
            .detach(move || -> Result<Vec<(String, Encoded)>, PortError> {
                let replies = inner.sendall(&message, limit)?;
                let mut all = vec![replies.first().clone()];
                let end = std::time::Instant::now() + collect;
                loop {
                    let left = end.saturating_duration_since(std::time::Instant::now());
                    if left.is_zero() {
                        break;
                    }
                    match replies.next(left) {
                        Some(Ok(reply)) => all.push(reply),
                        Some(Err(_)) | None => break,
                    }
                }
                Ok(all)
            })
            .map_err(errors::port_error)?;
        replies
            .into_iter()
            .map(|(user, reply)| Ok((user, decode(py, &self.reply, &reply.0)?.unbind())))
            .collect()
    }

    /// `callall`: sends `value` to every user that takes messages to all and is admitted
    /// now, and waits up to `timeout` seconds until each answered. Returns `(replies,
    /// missing)`: `[(user, reply), ...]` in the order they came, and the users that did not
    /// answer in time.
    #[pyo3(signature = (value, timeout=5.0))]
    #[allow(clippy::type_complexity)]
    fn callall(
        &self,
        py: Python<'_>,
        value: &Bound<'_, PyAny>,
        timeout: f64,
    ) -> PyResult<(Vec<(String, Py<PyAny>)>, Vec<String>)> {
        let message = Encoded(encode(&self.request, value)?);
        let limit = seconds("timeout", timeout)?;
        let inner = self.inner.clone();
        let answers = py
            .detach(move || inner.callall(&message, limit))
            .map_err(errors::port_error)?;
        let replies = answers
            .replies
            .into_iter()
            .map(|(user, reply)| Ok((user, decode(py, &self.reply, &reply.0)?.unbind())))
            .collect::<PyResult<_>>()?;
        Ok((replies, answers.missing))
    }

    /// The users present now, each as `task [usages]`.
    #[getter]
    fn users(&self) -> Vec<String> {
        self.inner.present_users()
    }

    /// Users a `sendall` reaches now (matched on the port's broadcast topic).
    #[getter]
    fn reached(&self) -> usize {
        self.inner.users()
    }

    /// Users refused so far, with the restriction each broke.
    #[getter]
    fn refusals(&self) -> Vec<String> {
        self.inner.refusals()
    }

    /// The port's name.
    #[getter]
    fn port(&self) -> String {
        self.inner.port().to_owned()
    }
}

/// A request received by a port's owner.
#[pyclass(module = "ndds._ndds", name = "Request")]
pub(crate) struct PyRequest {
    /// The request's value.
    #[pyo3(get)]
    value: Py<PyAny>,
    /// The task that sent it.
    #[pyo3(get)]
    sender: String,
    handle: Mutex<Option<ReplyHandle<Encoded>>>,
    reply: Arc<Kind>,
}

#[pymethods]
impl PyRequest {
    /// Replies to the sender (once). The first reply to a user may wait briefly (at most
    /// 2 s) for the reply stream to that user to match; the GIL is free meanwhile.
    fn reply(&self, py: Python<'_>, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let bytes = encode(&self.reply, value)?;
        let handle = self
            .handle
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
            .ok_or_else(|| errors::Error::new_err("this request was replied to already"))?;
        py.detach(|| handle.reply(&Encoded(bytes)))
            .map_err(errors::port_error)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let value = self
            .value
            .bind(py)
            .repr()
            .map(|r| r.to_string())
            .unwrap_or_default();
        format!("Request(value={value}, sender={:?})", self.sender)
    }
}

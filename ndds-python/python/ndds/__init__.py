"""ndds for Python: typed publish/subscribe with NDDS semantics, CSMats as NumPy arrays, ports
and ControlShell systems.

>>> import dataclasses, ndds
>>> @dataclasses.dataclass
... class Pose:
...     x: float
...     y: float
>>> with ndds.Participant() as p:                      # local daemon, else an embedded one
...     producer = p.producer("arm/pose", Pose)
...     consumer = p.consumer("arm/pose", Pose)
...     producer.wait_for_consumers(1)
...     producer.write(Pose(1.0, 2.0))
...     consumer.recv(timeout=1.0).value
True
True
Pose(x=1.0, y=2.0)

Sample types are dataclasses with type hints (see ``ndds._types`` for the table of Python
hints and the Rust types they match); a Python type and the Rust type of the same shape have
the same fingerprint, so their endpoints match. ``consumer(topic)`` without a type takes the
topic's announced type and delivers dicts.
"""

from __future__ import annotations

import asyncio
import sys
import threading
import traceback
from typing import Any, Callable, Iterator, List, Optional, Sequence, Tuple

from . import _ndds
from ._csmat import CsMat
from ._ndds import (
    DataType,
    Disconnected,
    Error,
    IncompatibleType,
    Notification,
    Refused,
    Request,
    Sample,
    Timeout,
)
from ._types import array, data_type, f32, f64, i8, i16, i32, i64, u8, u16, u32, u64

__all__ = [
    "__version__", "Participant", "Producer", "Consumer", "Sample", "Notification", "DataType", "data_type",
    "CsMat", "PortUser", "PortOwner", "Request", "System",
    "Error", "Timeout", "Refused", "Disconnected", "IncompatibleType",
    "i8", "i16", "i32", "i64", "u8", "u16", "u32", "u64", "f32", "f64", "array",
]


def _check_int(name: str, value: Any, low: int, high: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{name} must be an int, got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"{name} must be between {low} and {high}, got {value}")


try:
    from importlib.metadata import version as _version

    __version__ = _version("ndds")
except Exception:  # running from a source tree
    __version__ = "0.0.0+source"


class Participant(_ndds.Participant):
    """A connection to an ndds domain through this host's daemon (or an embedded daemon when
    none runs, as the Rust SDK does).

    Participant(*, domain=None, socket=None, key_file=None, integrity_only=False, name=None,
    embedded="auto")

    - ``domain``: the domain number (default: ``NDDS_DOMAIN`` or 0).
    - ``socket``: the daemon's Unix socket (default: the domain's).
    - ``key_file``: a sealed domain's key file (``ndds key new``); ``integrity_only``:
      authenticated, not encrypted.
    - ``name``: the name tools show for this process.
    - ``embedded``: ``"auto"`` (embed a daemon when none answers), ``"never"``, ``"always"``.

    Use it as a context manager, or call ``close()``; endpoints are withdrawn when closed or
    collected.
    """

    def producer(
        self,
        topic: str,
        type: Any,
        *,
        strength: int = 0,
        persistence: float = 1.0,
        reliable: bool = False,
        history: Optional[int] = None,
        batching: Optional[Tuple[float, int]] = None,
        when_full: str = "block",
        write_timeout: float = 1.0,
        late_joiners: int = 0,
    ) -> "Producer":
        """Declares a producer of ``type`` samples on ``topic``.

        NDDS semantics: among the producers of a topic, consumers take the strongest
        (``strength``); it stays in charge while it writes at least once per ``persistence``
        seconds. ``reliable=True`` resends what a consumer missed (``history`` samples kept,
        64 by default; ``when_full``: ``"block"`` up to ``write_timeout`` seconds, or
        ``"drop_oldest"``); ``late_joiners``: the last N samples are replayed to reliable
        consumers that join later. ``batching=(max_delay_s, max_bytes)`` packs small samples
        into one datagram.
        """
        _check_int("strength", strength, -(2**31), 2**31 - 1)
        _check_int("late_joiners", late_joiners, 0, 2**32)
        native = self._producer(
            topic,
            data_type(type),
            strength=strength,
            persistence=persistence,
            reliable=reliable,
            history=history,
            batching=batching,
            when_full=when_full,
            write_timeout=write_timeout,
            late_joiners=late_joiners,
        )
        return Producer(native)

    def consumer(
        self,
        topic: str,
        type: Any = None,
        *,
        mode: str = "immediate",
        depth: int = 64,
        min_separation: float = 0.0,
        deadline: Optional[float] = None,
        reliable: bool = False,
        history: Optional[int] = None,
        every_producer: bool = False,
        callback: Optional[Callable[[Any], None]] = None,
        wait: float = 5.0,
    ) -> "Consumer":
        """Declares a consumer of ``topic``.

        ``type``: the sample type; ``None`` takes the type the topic's endpoints announce
        (waiting up to ``wait`` seconds for one to appear) and delivers dicts, as ``ndds echo``
        does. ``mode``: ``"immediate"`` (queued, ``depth`` deep) or ``"polled"`` (latest value,
        see ``poll()``). ``min_separation``: at most one sample per this many seconds.
        ``deadline``: a ``no_new_data`` notification when no sample came for this long.
        ``reliable``: take a reliable stream (``history`` deep). ``every_producer``: samples
        of every producer, not only the strongest. ``callback``: called with each sample (and
        notification) on a thread of its own; see ``Consumer.on_event``.
        """
        _check_int("depth", depth, 1, 2**32)
        if history is not None:
            _check_int("history", history, 1, 2**32 - 1)
        if type is None:
            dtype = self._wait_for_type(topic, wait)
        else:
            dtype = data_type(type)
        native = self._consumer(
            topic,
            dtype,
            mode=mode,
            depth=depth,
            min_separation=min_separation,
            deadline=deadline,
            reliable=reliable,
            history=history,
            every_producer=every_producer,
        )
        consumer = Consumer(native)
        if callback is not None:
            consumer.on_event(callback)
        return consumer

    def _wait_for_type(self, topic: str, wait: float) -> DataType:
        import time

        end = time.monotonic() + wait
        while True:
            found = self._topic_type(topic, CsMat._from_wire)
            if found is not None:
                return found
            if time.monotonic() >= end:
                raise Timeout(
                    f"no endpoint of topic {topic!r} is known after {wait} s: its type cannot be "
                    "taken from it (pass the type, or a longer wait=)"
                )
            time.sleep(0.05)

    def __new__(cls, *, domain: Optional[int] = None, **kwargs: Any) -> "Participant":
        if domain is not None:
            _check_int("domain", domain, 0, 232)
        return super().__new__(cls, domain=domain, **kwargs)

    def __enter__(self) -> "Participant":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class _Endpoint:
    """What producers and consumers share: the native endpoint, its topic and type, what it is
    matched with, closing."""

    __slots__ = ("_native",)

    def __init__(self, native: Any) -> None:
        """Made by ``Participant.producer`` / ``Participant.consumer``, not directly."""
        self._native = native

    def __repr__(self) -> str:
        kind = type(self).__name__
        return f"<ndds.{kind} {self._native.topic!r} {self._native.data_type.shape}>"

    @property
    def matched(self) -> int:
        """Endpoints of the other kind matched now (consumers of a producer, producers of a
        consumer)."""
        return self._native.matched

    @property
    def topic(self) -> str:
        return self._native.topic

    @property
    def data_type(self) -> DataType:
        return self._native.data_type

    def close(self) -> None:
        """Withdraws the endpoint; later calls raise ndds.Disconnected."""
        self._native.close()

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class Producer(_Endpoint):
    """A producer of one topic (``Participant.producer``)."""

    __slots__ = ()

    def write(self, value: Any) -> None:
        """Writes one sample. A value that does not fit the type raises TypeError naming the
        field; a reliable producer whose consumers lag blocks up to its ``write_timeout``,
        then raises ndds.Timeout."""
        self._native.write(value)

    def flush(self) -> None:
        """Sends what batching holds now."""
        self._native.flush()

    def wait_for_consumers(self, count: int = 1, timeout: float = 5.0) -> bool:
        """Waits until at least ``count`` consumers are matched; False at the timeout."""
        return self._native.wait_for_consumers(count, timeout)

    def wait_for_acknowledgments(self, timeout: float = 5.0) -> bool:
        """Reliable: waits until every matched consumer acknowledged every sample."""
        return self._native.wait_for_acknowledgments(timeout)

    @property
    def written(self) -> int:
        """Samples written so far."""
        return self._native.written



class Consumer(_Endpoint):
    """A consumer of one topic (``Participant.consumer``).

    Iterating yields samples until the consumer is closed; ``async for`` does the same in
    asyncio; ``on_sample``/``on_event`` call a function on a thread of their own.
    """

    __slots__ = ("_thread",)

    def __init__(self, native: Any) -> None:
        """Made by ``Participant.consumer``, not directly."""
        super().__init__(native)
        self._thread: Optional[threading.Thread] = None

    def recv(self, timeout: Optional[float] = None) -> Sample:
        """The next sample, waiting up to ``timeout`` seconds (None: no limit), without
        holding the GIL; Ctrl-C interrupts the wait. Raises ndds.Timeout, whose message names
        producers of the topic this consumer is not matched with and why (another type, for
        instance). Notifications that arrive meanwhile are skipped (``recv_event`` returns
        them)."""
        return self._native.recv(timeout)

    def try_recv(self) -> Optional[Sample]:
        """The next queued sample, or None, without waiting."""
        return self._native.try_recv()

    def recv_event(self, timeout: Optional[float] = None) -> Any:
        """The next sample or notification (ndds.Sample or ndds.Notification)."""
        return self._native.recv_event(timeout)

    def poll(self) -> Tuple[Optional[Sample], str]:
        """Polled mode: ``(latest sample or None, status)`` without waiting; status is
        ``never_received``, ``fresh``, ``unchanged`` or ``no_new_data``."""
        return self._native.poll()

    def take_notifications(self) -> List[Notification]:
        """Polled mode: the notifications since the last call."""
        return self._native.take_notifications()

    def wait_for_producers(self, count: int = 1, timeout: float = 5.0) -> bool:
        """Waits until at least ``count`` producers are matched; False at the timeout."""
        return self._native.wait_for_producers(count, timeout)

    @property
    def incompatible(self) -> List[Tuple[str, str, str]]:
        """Producers of the topic not matched with this consumer: (writer, type, fingerprint)."""
        return self._native.incompatible

    @property
    def closed(self) -> bool:
        return self._native.closed

    def close(self) -> None:
        """Withdraws the consumer; a blocked ``recv`` and a callback thread end within 50 ms."""
        self._native.close()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=1.0)

    # Iteration.
    def __iter__(self) -> Iterator[Sample]:
        while True:
            try:
                yield self._native.recv(None)
            except Disconnected:
                return

    # asyncio.
    def __aiter__(self) -> "Consumer":
        return self

    async def __anext__(self) -> Sample:
        try:
            return await self.recv_async()
        except Disconnected:
            raise StopAsyncIteration from None

    async def recv_async(self, timeout: Optional[float] = None) -> Sample:
        """``recv`` for asyncio: waits on a worker thread (in steps of 0.1 s), the event loop
        keeps running. If the awaiting task is cancelled, a sample the worker takes in that
        last step is lost to it."""
        sample = self._native.try_recv()
        if sample is not None:
            return sample
        loop = asyncio.get_running_loop()
        deadline = None if timeout is None else loop.time() + timeout
        while True:
            step = 0.1 if deadline is None else max(0.0, min(0.1, deadline - loop.time()))
            try:
                return await loop.run_in_executor(None, self._native.recv, step)
            except Timeout:
                if deadline is not None and loop.time() >= deadline:
                    raise Timeout(f"no sample on {self.topic!r} within {timeout} s") from None

    # Callbacks.
    def on_sample(self, callback: Callable[[Sample], None]) -> None:
        """Calls ``callback(sample)`` for each sample, on a thread of its own, until the
        consumer is closed (the thread holds the consumer: close it, or use ``with``)."""
        self._start(callback, samples_only=True)

    def on_event(self, callback: Callable[[Any], None]) -> None:
        """Calls ``callback(sample_or_notification)`` for each, on a thread of its own, until
        closed. An exception in the callback is printed and the thread goes on."""
        self._start(callback, samples_only=False)

    def _start(self, callback: Callable[[Any], None], samples_only: bool) -> None:
        if self._thread is not None:
            raise Error("this consumer already has a callback")
        native = self._native

        def run() -> None:
            while True:
                try:
                    event = native.recv(0.1) if samples_only else native.recv_event(0.1)
                except Timeout:
                    continue
                except Disconnected:
                    return
                except Exception:  # a sample that does not decode: said, and skipped
                    print(f"ndds: a sample on {native.topic!r} was dropped:", file=sys.stderr)
                    traceback.print_exc()
                    continue
                try:
                    callback(event)
                except Exception:
                    print(f"ndds: callback on {native.topic!r} raised:", file=sys.stderr)
                    traceback.print_exc()

        self._thread = threading.Thread(target=run, name=f"ndds-callback", daemon=True)
        self._thread.start()


class PortUser:
    """A user of a port (Shin's port-directed communication): ``send`` a request and wait for
    the owner's reply, ``query`` the owner's responders, take what the owner sends to all.

    PortUser(participant, port, task, request=Type, reply=Type, usages=("send",))

    ``usages`` are what this user declares (``send``, ``query``, ``receive_all``, ...): the
    owner's restrictions are checked against them, and a refused user's calls raise
    ndds.Refused naming the restriction.
    """

    def __init__(
        self,
        participant: Participant,
        port: str,
        task: str,
        request: Any,
        reply: Any = type(None),
        usages: Sequence[str] = ("send",),
    ) -> None:
        self._native = _ndds.PortUser(
            participant, port, task, data_type(request), data_type(reply), list(usages)
        )

    def send(self, value: Any, timeout: float = 5.0) -> Any:
        """Sends ``value`` and returns the owner's reply; ndds.Timeout after ``timeout`` s."""
        return self._native.send(value, timeout)

    def query(self, value: Any, timeout: float = 5.0) -> Any:
        """Queries the owner's responders (by priority) and returns the response."""
        return self._native.query(value, timeout)

    def receive_all(self, answer: Callable[[Any], Any], timeout: float = 5.0) -> Any:
        """Takes the next message the owner sent to all users, answers it with
        ``answer(message)`` and returns the message."""
        return self._native.receive_all(answer, timeout)

    @property
    def port(self) -> str:
        return self._native.port


class PortOwner:
    """The owner of a port: ``receive`` requests and reply to each; ``sendall`` and
    ``callall`` to every user.

    PortOwner(participant, port, task, request=Type, reply=Type, *, usages=(), users=(),
    max_users=None, timeout=None, priority=None)

    The keyword arguments are the port's restrictions: the owner's usages, the tasks allowed
    to use it, the number of active users, the longest timeout of its operations, its
    priority. Users that break them are refused (their calls raise ndds.Refused).
    """

    def __init__(
        self,
        participant: Participant,
        port: str,
        task: str,
        request: Any,
        reply: Any = type(None),
        *,
        usages: Sequence[str] = (),
        users: Sequence[str] = (),
        max_users: Optional[int] = None,
        timeout: Optional[float] = None,
        priority: Optional[int] = None,
    ) -> None:
        self._native = _ndds.PortOwner(
            participant,
            port,
            task,
            data_type(request),
            data_type(reply),
            usages=list(usages),
            users=list(users),
            max_users=max_users,
            timeout=timeout,
            priority=priority,
        )

    def receive(self, timeout: Optional[float] = None) -> Request:
        """The next request (``.value``, ``.sender``, ``.reply(value)``); ndds.Timeout after
        ``timeout`` seconds. Ctrl-C interrupts the wait."""
        return self._native.receive(timeout)

    def sendall(self, value: Any, timeout: float = 5.0, collect: float = 0.0) -> List[Tuple[str, Any]]:
        """Sends ``value`` to every user taking messages to all, waits up to ``timeout``
        seconds for the first reply, then takes the replies that come within ``collect``
        seconds more: ``[(user, reply), ...]``, first first. ndds.Timeout if nobody replied."""
        return self._native.sendall(value, timeout, collect)

    def callall(self, value: Any, timeout: float = 5.0) -> Tuple[List[Tuple[str, Any]], List[str]]:
        """Sends ``value`` to every admitted user taking messages to all and waits up to
        ``timeout`` seconds until each answered: ``(replies, missing)``."""
        return self._native.callall(value, timeout)

    @property
    def users(self) -> List[str]:
        """The users present now, each as `task [usages]`."""
        return self._native.users

    @property
    def reached(self) -> int:
        """Users a ``sendall`` or ``callall`` reaches now (matched on the port's broadcast
        topic)."""
        return self._native.reached

    @property
    def refusals(self) -> List[str]:
        """Users refused so far, with the restriction each broke."""
        return self._native.refusals

    @property
    def port(self) -> str:
        return self._native.port


class System:
    """A ControlShell system loaded from a description file, with the built-in component
    library, run in this process as ``ndds run`` runs it.

    >>> system = ndds.System.load("examples/arm.toml", participant)   # doctest: +SKIP
    >>> system.start(); system.switch("track"); system.status()["configuration"]
    """

    def __init__(self, native: Any, simulated: bool = False) -> None:
        """Made by ``System.load``."""
        self._native = native
        self._simulated = simulated
        self._started = False

    def __repr__(self) -> str:
        return f"<ndds.System {self._native.name!r}>"

    @classmethod
    def load(
        cls,
        path: str,
        participant: Optional[Participant] = None,
        *,
        simulated: bool = False,
        name: Optional[str] = None,
        check: bool = False,
    ) -> "System":
        """Reads, checks and builds the system described by ``path`` (raises ndds.Error with
        file:line:column for a bad file). A system that publishes, subscribes or declares
        ports needs ``participant``. ``simulated``: its habitats run only in ``simulate()``,
        in simulated time. ``check``: load to verify only."""
        return cls(
            _ndds.System(
                str(path),
                CsMat._from_wire,
                participant=participant,
                simulated=simulated,
                name=name,
                check=check,
            ),
            simulated,
        )

    @property
    def name(self) -> str:
        return self._native.name

    @property
    def topics(self) -> List[str]:
        """The topics it publishes and subscribes to."""
        return self._native.topics

    @property
    def machines(self) -> List[str]:
        """Its state machines."""
        return self._native.machines

    @property
    def configuration(self) -> Optional[str]:
        """The active configuration (None before any switch)."""
        return self._native.configuration

    def start(self) -> None:
        """Starts its habitats, state machines and ports (once: to run it again, load it
        again)."""
        self._native.start()
        self._started = True

    def stop(self) -> None:
        """Stops it (also done when collected)."""
        self._native.stop()
        self._started = False

    def simulate(self, seconds: float) -> int:
        """Runs ``seconds`` of simulated time (loaded with ``simulated=True``, and started);
        returns the samples run."""
        if not self._simulated:
            raise Error(
                f"system {self.name!r} runs in real time: load it with simulated=True to simulate"
            )
        if not self._started:
            raise Error(f"system {self.name!r} is not running: start() it first")
        return self._native.simulate(seconds)

    def switch(self, configuration: str) -> None:
        """Switches to ``configuration``."""
        self._native.switch(configuration)

    def stimulus(self, machine: str, name: str, value: Optional[str] = None) -> None:
        """Sends stimulus ``name`` to state machine ``machine``."""
        self._native.stimulus(machine, name, value)

    def state(self, machine: str) -> str:
        """The current state of state machine ``machine``."""
        return self._native.state(machine)

    def wait_for_state(self, machine: str, state: str, timeout: float = 5.0) -> bool:
        """Waits up to ``timeout`` seconds until state machine ``machine`` is in ``state``;
        False if it is not by then."""
        import time

        end = time.monotonic() + timeout
        while True:
            if self._native.state(machine) == state:
                return True
            if time.monotonic() >= end:
                return False
            time.sleep(0.01)

    def mat(self, name: str) -> CsMat:
        """The value of CSMat ``name`` as the habitat's last completed sample left it (a sample's
        output may be on its topic a moment, about one period, before it shows here)."""
        return self._native.mat(name)

    def status(self) -> dict:
        """``{"system", "configuration", "habitats": {name: stats}, "machines": {name:
        state}, "display": {name: CsMat}}``."""
        return self._native.status()

    def __enter__(self) -> "System":
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

"""zenoh-python adapter for bench.py.

Loopback only: peer mode, the "a" side listens on tcp/127.0.0.1:PORT, the "b" side
connects to it (and listens on an ephemeral 127.0.0.1 port only); multicast
scouting is disabled, so nothing is multicast and the one TCP connection over lo
is the only link.

Receive styles (the harness uses ECHO_STYLE for pong and SINK_STYLE for the
throughput sink; ping always pulls with `Subscriber.recv`):
- pull: zenoh's native FIFO channel (`FifoChannel`), read with `try_recv` and,
  when empty, the blocking `recv` (bounded by a timer, see `_recv_with_alarm`).
- callback: zenoh calls a Python function on its own receive thread.
Chosen by measurement on this machine (paired runs, order alternated; the
machine's speed drifts by up to 2x over minutes, so only paired runs compare):
- pong echoes from the callback: p50 lower than a pull loop in 4 of 5 pairs (by
  up to 35%), equal in the fifth; the reply leaves without waking another thread.
- the sink counts in the callback: against pulling, 2 pairs of 5 better, 3 worse,
  all within 20%, so the idiomatic style (zenoh's own throughput examples) wins.
"""

from __future__ import annotations

import signal
import threading
import time
from importlib import metadata
from typing import Callable, Optional

import zenoh

NAME = "zenoh"

# Where the harness has a choice (pong's echo, throughput sink), which style to use.
ECHO_STYLE = "callback"
SINK_STYLE = "callback"


def library_version() -> str:
    return "eclipse-zenoh " + metadata.version("eclipse-zenoh")


class Publisher:
    def __init__(self, pub: "zenoh.Publisher"):
        self._pub = pub
        self.put = pub.put  # bytes in, no copy on the Python side


class _Alarm(Exception):
    pass


_alarm_armed = False
_alarm_installed = False


def _on_alarm(signum, frame) -> None:
    # Raises only while a recv is waiting: a late signal must not land elsewhere.
    if _alarm_armed:
        raise _Alarm()


def _recv_with_alarm(sub: "zenoh.Subscriber", timeout: float):
    """Blocking native recv, bounded by a one-shot SIGALRM.

    zenoh-python's Handler.recv() has no timeout, but it runs Python signal
    handlers while it waits (so that Ctrl-C works); an interval timer whose
    handler raises therefore ends the wait. Measured here, this is about 10%
    faster at the median than handing samples from a callback to a
    queue.SimpleQueue, and much cheaper than polling try_recv. Signals reach the
    main thread only (hence the fallback), and this module then owns SIGALRM.
    """
    global _alarm_armed, _alarm_installed
    if timeout <= 0:
        return sub.try_recv()
    if not _alarm_installed:
        signal.signal(signal.SIGALRM, _on_alarm)
        _alarm_installed = True
    sample = None
    try:
        try:
            _alarm_armed = True
            signal.setitimer(signal.ITIMER_REAL, timeout)
            sample = sub.recv()
        finally:
            _alarm_armed = False
            signal.setitimer(signal.ITIMER_REAL, 0)
    except _Alarm:  # also when it is raised just after recv returned: the sample is kept
        _alarm_armed = False
    return sample


def _recv_polling(sub: "zenoh.Subscriber", timeout: float):
    deadline = time.perf_counter() + timeout
    while True:
        sample = sub.try_recv()
        if sample is not None or time.perf_counter() >= deadline:
            return sample
        time.sleep(0.0002)


class Subscriber:
    def __init__(self, sub: "zenoh.Subscriber", pull: bool):
        self._sub = sub
        self._pull = pull

    def recv(self, timeout: Optional[float]) -> Optional[bytes]:
        """One payload, or None after `timeout` seconds (None: wait for ever)."""
        if not self._pull:
            raise RuntimeError("subscriber was declared with a callback")
        sample = self._sub.try_recv()
        if sample is None:
            if timeout is None:
                sample = self._sub.recv()
            elif threading.current_thread() is threading.main_thread():
                sample = _recv_with_alarm(self._sub, timeout)
            else:
                sample = _recv_polling(self._sub, timeout)
            if sample is None:
                return None
        return sample.payload.to_bytes()


class Node:
    """One zenoh session. side "a" listens on 127.0.0.1:port, side "b" connects to it."""

    def __init__(self, side: str, port: int):
        self._side = side
        self._port = port
        self._session: Optional[zenoh.Session] = None

    def open(self) -> None:
        conf = zenoh.Config()
        conf.insert_json5("mode", '"peer"')
        conf.insert_json5("scouting/multicast/enabled", "false")
        endpoint = f'["tcp/127.0.0.1:{self._port}"]'
        if self._side == "a":
            conf.insert_json5("listen/endpoints", endpoint)
            conf.insert_json5("connect/endpoints", "[]")
        else:
            # An empty list would fall back to zenoh's default (tcp/[::]:0, every
            # interface); an ephemeral loopback port keeps even the listener on lo.
            conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
            conf.insert_json5("connect/endpoints", endpoint)
        self._session = zenoh.open(conf)

    def publisher(self, topic: str, reliable: bool = True) -> Publisher:
        # reliable: block the writer when the transmit queue is full instead of dropping
        # the sample (zenoh's default, DROP). Batching is left on (express=False): with
        # one ping outstanding express=True made no measurable difference here.
        cc = zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
        return Publisher(self._session.declare_publisher(topic, congestion_control=cc))

    def subscriber(
        self,
        topic: str,
        reliable: bool = True,
        on_data: Optional[Callable[[bytes], None]] = None,
    ) -> Subscriber:
        # zenoh's reliability is chosen by the publisher; `reliable` is unused here.
        if on_data is not None:
            sub = self._session.declare_subscriber(
                topic, lambda sample: on_data(sample.payload.to_bytes())
            )
            return Subscriber(sub, pull=False)
        sub = self._session.declare_subscriber(topic, zenoh.handlers.FifoChannel(4096))
        return Subscriber(sub, pull=True)

    def close(self) -> None:
        if self._session is not None:
            self._session.close()
            self._session = None

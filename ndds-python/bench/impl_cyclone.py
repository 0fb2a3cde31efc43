"""cyclonedds-python adapter for bench.py.

Loopback only: the domain is configured (CYCLONEDDS_URI, set before the first
participant is created) to use interface `lo` alone, with multicast off; SPDP
discovery goes by unicast to 127.0.0.1 (the participant-index ports of the domain).

The sample type is one IDL struct holding the 64-byte payload as `octet data[64]`
(`array[uint8, 64]` in cyclonedds' Python IDL). cyclonedds-python serialises that
as one block of bytes and hands it back as `bytes`; `sequence[uint8]` would be
packed and unpacked element by element (a list of ints), and a plain `bytes`
field cannot be given an XTypes type object by this version.

Receive styles (the harness uses ECHO_STYLE for pong and SINK_STYLE for the
throughput sink; ping always pulls with `Subscriber.recv`):
- pull: a WaitSet on a ReadCondition, then `take` of up to 256 samples at a time,
  handed out one by one by `Subscriber.recv`. WaitSet.wait goes through ctypes,
  which releases the GIL while it blocks.
- callback: a Listener's on_data_available, run on Cyclone's receive thread, takes
  the samples and calls the Python function for each.
Chosen by measurement on this machine (paired runs, order alternated): pull for
both. For pong there was no consistent difference (medians of 9 pairs within
noise, pull a little lower at p90), and pulling keeps Python off Cyclone's receive
thread. For the sink it matters: a listener sink lost 40-57% of best-effort
samples, because the listener runs on the receive thread, which then waits for
the GIL while the UDP socket buffer overflows; pulling lost none.
"""

# No `from __future__ import annotations`: cyclonedds reads the field types of
# IdlStruct classes at run time and cannot resolve them from strings.
import os
import time
from dataclasses import dataclass
from importlib import metadata
from typing import Callable, List, Optional

NAME = "cyclone"

ECHO_STYLE = "pull"
SINK_STYLE = "pull"

_TAKE_BATCH = 256


def _loopback_config(domain_id: int) -> str:
    return f"""<CycloneDDS xmlns="https://cdds.io/config">
  <Domain Id="{domain_id}">
    <General>
      <Interfaces><NetworkInterface name="lo"/></Interfaces>
      <AllowMulticast>false</AllowMulticast>
    </General>
    <Discovery>
      <ParticipantIndex>auto</ParticipantIndex>
      <MaxAutoParticipantIndex>8</MaxAutoParticipantIndex>
      <Peers><Peer Address="127.0.0.1"/></Peers>
    </Discovery>
  </Domain>
</CycloneDDS>"""


# The configuration must be in the environment before cyclonedds creates its
# first domain; the harness's children import this module before anything else.
# The domain id comes from bench.py (one per run, so concurrent runs do not meet).
_DOMAIN_ID = int(os.environ.get("PYBENCH_DDS_DOMAIN", "0"))
os.environ["CYCLONEDDS_URI"] = _loopback_config(_DOMAIN_ID)

from cyclonedds.core import Listener, Qos, Policy, ReadCondition, ViewState, InstanceState, SampleState, WaitSet  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import array, uint8  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402


@dataclass
class Payload(IdlStruct, typename="bench::Payload"):
    data: array[uint8, 64]  # IDL: octet data[64]


def library_version() -> str:
    return "cyclonedds " + metadata.version("cyclonedds")


def _qos(reliable: bool) -> Qos:
    if reliable:
        # Reliable, keep-all: the writer blocks (up to 10 s) rather than lose a sample.
        return Qos(
            Policy.Reliability.Reliable(max_blocking_time=10_000_000_000),
            Policy.History.KeepAll,
        )
    # Best effort; a deep reader history so that a sample is only lost on the wire or
    # when the reader falls more than 100000 samples behind.
    return Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(100_000))


class Publisher:
    def __init__(self, writer: DataWriter):
        self._writer = writer
        write = writer.write
        self.put = lambda payload: write(Payload(data=payload))


class Subscriber:
    def __init__(self, reader: DataReader, participant: DomainParticipant, pull: bool):
        self._reader = reader
        self._pending: List[bytes] = []
        if pull:
            self._cond = ReadCondition(
                reader, ViewState.Any | InstanceState.Any | SampleState.NotRead
            )
            self._waitset = WaitSet(participant)
            self._waitset.attach(self._cond)
        else:
            self._waitset = None

    def recv(self, timeout: Optional[float]) -> Optional[bytes]:
        """One payload, or None after `timeout` seconds (None: wait for ever)."""
        if self._waitset is None:
            raise RuntimeError("subscriber was declared with a callback")
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._pending:
            samples = self._reader.take(N=_TAKE_BATCH, condition=self._cond)
            if samples:
                # Kept reversed so that pop() hands them out in arrival order; samples
                # without data (a writer's unregistration or disposal) are left out.
                self._pending = [s.data for s in reversed(samples) if s.sample_info.valid_data]
                continue
            if deadline is None:
                wait_ns = 10**15
            else:
                wait_ns = int((deadline - time.monotonic()) * 1e9)
                if wait_ns <= 0:
                    return None
            if self._waitset.wait(wait_ns) == 0:
                return None
        return self._pending.pop()


class Node:
    """One DomainParticipant; `side` and `port` are not needed by DDS discovery."""

    def __init__(self, side: str, port: int):
        self._dp: Optional[DomainParticipant] = None
        self._topics = {}
        self._listeners = []  # keep the ctypes callbacks alive

    def open(self) -> None:
        self._dp = DomainParticipant(_DOMAIN_ID)

    def _topic(self, name: str) -> Topic:
        if name not in self._topics:
            self._topics[name] = Topic(self._dp, name, Payload)
        return self._topics[name]

    def publisher(self, topic: str, reliable: bool = True) -> Publisher:
        return Publisher(DataWriter(self._dp, self._topic(topic), qos=_qos(reliable)))

    def subscriber(
        self,
        topic: str,
        reliable: bool = True,
        on_data: Optional[Callable[[bytes], None]] = None,
    ) -> Subscriber:
        if on_data is None:
            reader = DataReader(self._dp, self._topic(topic), qos=_qos(reliable))
            return Subscriber(reader, self._dp, pull=True)

        def on_data_available(reader: DataReader) -> None:
            for sample in reader.take(N=_TAKE_BATCH):
                if sample.sample_info.valid_data:
                    on_data(sample.data)

        listener = Listener(on_data_available=on_data_available)
        self._listeners.append(listener)
        reader = DataReader(self._dp, self._topic(topic), qos=_qos(reliable), listener=listener)
        return Subscriber(reader, self._dp, pull=False)

    def close(self) -> None:
        if self._dp is not None:
            # Readers with listeners must stop calling into Python before teardown.
            for child in self._dp.get_children():
                try:
                    child.set_listener(None)
                except Exception:
                    pass
            # cyclonedds-python deletes an entity when its last Python reference goes.
            self._dp = None
            self._topics.clear()

"""Publish/subscribe from Python: within a process, between Python processes, reliable
delivery, deadlines, polled mode, iteration, asyncio and callbacks."""

from __future__ import annotations

import asyncio
import dataclasses
import enum
import threading
from typing import Dict, List, Optional, Tuple

import pytest

import ndds
from conftest import finish, read_line


class Mode(enum.Enum):
    Idle = 1
    Moving = 2


@dataclasses.dataclass
class Point:
    x: float
    y: float


@dataclasses.dataclass
class Everything:
    flag: bool
    small: ndds.u8
    signed: ndds.i16
    big: ndds.u64
    count: int
    ratio: ndds.f32
    value: float
    name: str
    blob: bytes
    raw: List[ndds.u8]
    points: List[Point]
    pair: Tuple[int, str]
    fixed: ndds.array(float, 3)
    maybe: Optional[Point]
    table: Dict[str, float]
    mode: Mode


def everything() -> Everything:
    return Everything(
        flag=True,
        small=255,
        signed=-300,
        big=2**64 - 1,
        count=-(2**40),
        ratio=0.1,
        value=3.25,
        name="bras ✓",
        blob=b"\x00\x01\xff",
        raw=[1, 2, 3],
        points=[Point(1.0, 2.0), Point(-1.0, 0.5)],
        pair=(7, "seven"),
        fixed=[1.0, 2.0, 3.0],
        maybe=None,
        table={"a": 1.5, "b": -2.0},
        mode=Mode.Moving,
    )


def test_every_field_type_round_trips_in_one_process(participant):
    producer = participant.producer("py/everything", Everything)
    consumer = participant.consumer("py/everything", Everything)
    assert producer.wait_for_consumers(1, timeout=5)
    sent = everything()
    producer.write(sent)
    got = consumer.recv(timeout=5).value
    # `raw` (a Vec<u8>) and `fixed` come back as lists; `ratio` (f32) as its shortest decimal.
    assert got == sent
    assert isinstance(got.maybe, type(None)) and got.mode is Mode.Moving
    sent.maybe = Point(0.0, 0.0)
    sent.raw = b"\x09\x08"  # bytes are accepted for a list of u8
    producer.write(sent)
    got = consumer.recv(timeout=5).value
    assert got.maybe == Point(0.0, 0.0) and got.raw == [9, 8]


def test_sample_metadata(participant):
    producer = participant.producer("py/meta", Point, strength=5)
    consumer = participant.consumer("py/meta", Point)
    assert producer.wait_for_consumers(1, timeout=5)
    producer.write(Point(1, 2))
    sample = consumer.recv(timeout=5)
    assert sample.seq == 1 and sample.strength == 5
    assert sample.reception_time >= sample.source_time - 1.0
    assert "." in sample.writer
    assert consumer.try_recv() is None


PUBLISHER = """
import dataclasses, sys, ndds
@dataclasses.dataclass
class Point:
    x: float
    y: float
p = ndds.Participant()
producer = p.producer("py/points", Point, reliable=True, history=4096, write_timeout=20)
print("ready", flush=True)
assert producer.wait_for_consumers(1, timeout=20)
for i in range(int(sys.argv[1])):
    producer.write(Point(float(i), -float(i)))
assert producer.wait_for_acknowledgments(timeout=20)
print("done", flush=True)
"""


def test_between_python_processes_reliable_and_in_order(domain, participant):
    consumer = participant.consumer("py/points", Point, reliable=True, history=2000, depth=2000)
    publisher = domain.python(PUBLISHER, "2000")
    assert read_line(publisher) == "ready"
    got = [consumer.recv(timeout=20).value for _ in range(2000)]
    assert [p.x for p in got] == [float(i) for i in range(2000)]
    assert read_line(publisher) == "done"
    finish(publisher)


def test_deadline_notification(participant):
    producer = participant.producer("py/deadline", Point)
    consumer = participant.consumer("py/deadline", Point, deadline=0.2)
    assert producer.wait_for_consumers(1, timeout=5)
    producer.write(Point(1, 1))
    # Under load, the deadline may pass before the first sample (never_received): skip those.
    first = consumer.recv_event(timeout=5)
    while isinstance(first, ndds.Notification) and first.kind == "never_received":
        first = consumer.recv_event(timeout=5)
    assert isinstance(first, ndds.Sample), first
    # Nothing more is written: within a few deadlines, a no_new_data notification.
    event = consumer.recv_event(timeout=5)
    assert isinstance(event, ndds.Notification), event
    assert event.kind == "no_new_data"
    assert event.silent_for >= 0.15


def test_polled_mode_gives_the_latest_value(participant):
    producer = participant.producer("py/polled", Point)
    consumer = participant.consumer("py/polled", Point, mode="polled")
    assert consumer.poll() == (None, "never_received")
    assert producer.wait_for_consumers(1, timeout=5)
    for i in range(5):
        producer.write(Point(float(i), 0))
    import time

    deadline = time.monotonic() + 10
    while True:
        sample, status = consumer.poll()
        if (sample is not None and sample.value.x == 4.0) or time.monotonic() > deadline:
            break
        time.sleep(0.02)
    assert sample is not None and sample.value == Point(4.0, 0) and status == "fresh"
    assert consumer.poll()[1] == "unchanged"
    with pytest.raises(ndds.Error, match="mode"):
        consumer.recv(timeout=0.1)


def test_iteration_and_close(participant):
    producer = participant.producer("py/iter", Point)
    consumer = participant.consumer("py/iter", Point)
    assert producer.wait_for_consumers(1, timeout=5)
    for i in range(3):
        producer.write(Point(float(i), 0))
    seen = []
    for sample in consumer:
        seen.append(sample.value.x)
        if len(seen) == 3:
            consumer.close()
    assert seen == [0.0, 1.0, 2.0]
    assert consumer.closed
    with pytest.raises(ndds.Disconnected):
        consumer.recv(timeout=0.1)


def test_asyncio_consumption(participant):
    producer = participant.producer("py/async", Point)
    consumer = participant.consumer("py/async", Point)
    assert producer.wait_for_consumers(1, timeout=5)

    async def main():
        ticks = 0

        async def ticker():
            nonlocal ticks
            while True:
                await asyncio.sleep(0.01)
                ticks += 1

        task = asyncio.create_task(ticker())

        def write_later():
            import time

            time.sleep(0.3)
            for i in range(3):
                producer.write(Point(float(i), 1))

        threading.Thread(target=write_later).start()
        got = []
        async for sample in consumer:
            got.append(sample.value.x)
            if len(got) == 3:
                break
        task.cancel()
        return got, ticks

    got, ticks = asyncio.run(main())
    assert got == [0.0, 1.0, 2.0]
    # The event loop kept running while the consumer waited.
    assert ticks >= 5


def test_callbacks_run_on_their_own_thread(participant):
    producer = participant.producer("py/callback", Point)
    got = []
    done = threading.Event()
    threads = set()

    def on_sample(sample):
        got.append(sample.value.x)
        threads.add(threading.current_thread().name)
        if len(got) == 3:
            done.set()

    consumer = participant.consumer("py/callback", Point)
    consumer.on_sample(on_sample)
    assert producer.wait_for_consumers(1, timeout=5)
    for i in range(3):
        producer.write(Point(float(i), 0))
    assert done.wait(timeout=5)
    assert got == [0.0, 1.0, 2.0]
    assert threads == {"ndds-callback"}
    consumer.close()


def test_strength_decides_which_producer_is_heard(participant):
    weak = participant.producer("py/strength", Point, strength=1)
    strong = participant.producer("py/strength", Point, strength=9)
    consumer = participant.consumer("py/strength", Point)
    assert weak.wait_for_consumers(1, timeout=5) and strong.wait_for_consumers(1, timeout=5)
    strong.write(Point(9, 9))
    assert consumer.recv(timeout=5).value == Point(9, 9)
    weak.write(Point(1, 1))  # the strong producer is in charge: dropped
    strong.write(Point(9, 8))
    assert consumer.recv(timeout=5).value == Point(9, 8)


def test_help_shows_the_methods_and_the_version_is_known():
    import pydoc

    text = pydoc.render_doc(ndds.Consumer, renderer=pydoc.plaintext)
    assert "recv(self, timeout" in text and "ndds.Timeout" in text
    assert "write(self, value" in pydoc.render_doc(ndds.Producer, renderer=pydoc.plaintext)
    assert ndds.__version__


def test_fingerprint_and_shape(participant):
    t = ndds.data_type(Point)
    assert t.name == "Point"
    assert t.shape == "Point{x: f64, y: f64}"
    assert len(t.fingerprint) == 16
    assert ndds.data_type(Point) is t  # cached


LINGERING = """
import dataclasses, time, ndds
@dataclasses.dataclass
class Point:
    x: float
    y: float
p = ndds.Participant()
producer = p.producer("py/lost", Point)
print("ready", flush=True)
assert producer.wait_for_consumers(1, timeout=20)
producer.write(Point(1.0, 2.0))
time.sleep(60)
"""


def test_a_producer_that_goes_is_reported(domain, participant):
    consumer = participant.consumer("py/lost", Point)
    publisher = domain.python(LINGERING)
    assert read_line(publisher) == "ready"
    assert consumer.recv(timeout=20).value == Point(1.0, 2.0)
    publisher.kill()  # no goodbye: its daemon notices the client gone
    event = consumer.recv_event(timeout=20)
    assert isinstance(event, ndds.Notification) and event.kind == "producer_lost", event
    assert event.writer is not None and "lost" in event.message

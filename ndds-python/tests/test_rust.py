"""Python and Rust on one topic: a dataclass `Pose` and the Rust `Pose` of `pose_peer`
(ndds-client/examples/pose_peer.rs) match both ways; an untyped consumer takes the Rust
topic as dicts; a type of another shape is reported as incompatible, naming both."""

from __future__ import annotations

import dataclasses
import enum
from typing import List, Optional

import pytest

import ndds
from conftest import binary, finish, read_line


class Mode(enum.Enum):
    Idle = "idle"
    Moving = "moving"
    Fault = "fault"


@dataclasses.dataclass
class Pose:
    x: float
    y: float
    theta: ndds.f32
    frame: str
    seq: ndds.u32
    tags: List[str]
    covariance: Optional[ndds.array(float, 3)]
    mode: Mode


def test_the_fingerprint_is_the_rust_types(domain):
    import subprocess

    out = subprocess.run(
        [binary("pose_peer", "NDDS_POSE_PEER"), "fingerprint"],
        env=domain.env(),
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    t = ndds.data_type(Pose)
    assert t.fingerprint == out[0]
    assert t.canonical == out[1]


def test_rust_producer_to_python_consumer(domain, participant):
    consumer = participant.consumer("x/pose", Pose, reliable=True, history=256, depth=256)
    peer = domain.rust("publish", "x/pose", "20")
    assert read_line(peer) == "ready"
    got = [consumer.recv(timeout=20).value for _ in range(20)]
    assert [p.seq for p in got] == list(range(20))
    assert got[2] == Pose(2.0, -2.0, 0.5, "map", 2, ["rust"], [0.1, 0.2, 0.3], Mode.Moving)
    assert got[3].covariance is None and got[3].mode is Mode.Idle
    assert read_line(peer) == "published 20"
    finish(peer)


def test_python_producer_to_rust_and_back(domain, participant):
    producer = participant.producer("x/to_rust", Pose, reliable=True)
    consumer = participant.consumer("x/from_rust", Pose, reliable=True)
    peer = domain.rust("echo", "x/to_rust", "x/from_rust", "3")
    assert read_line(peer) == "ready"
    assert producer.wait_for_consumers(1, timeout=20)
    assert consumer.wait_for_producers(1, timeout=20)
    for i in range(3):
        producer.write(Pose(float(i), 1.0, 0.25, "odom", i, ["py", "thon"], None, Mode.Fault))
    for i in range(3):
        line = read_line(peer)
        # What Rust decoded, in Rust's Debug form.
        assert line.startswith(f"got Pose {{ x: {float(i)}, y: 1.0, theta: 0.25, frame: \"odom\", seq: {i}")
        assert 'tags: ["py", "thon"], covariance: None, mode: Fault' in line
    back = [consumer.recv(timeout=20).value for _ in range(3)]
    assert [p.x for p in back] == [1.0, 2.0, 3.0]
    assert back[0].tags == ["py", "thon"] and back[0].mode is Mode.Fault
    finish(peer)


def test_untyped_consumer_takes_the_rust_topic_as_dicts(domain, participant):
    peer = domain.rust("publish", "x/untyped", "4")
    assert read_line(peer) == "ready"
    # No type: the one the topic's producer announces.
    consumer = participant.consumer("x/untyped", reliable=True, wait=10)
    assert consumer.data_type.fingerprint == ndds.data_type(Pose).fingerprint
    got = [consumer.recv(timeout=20).value for _ in range(4)]
    assert got[0] == {
        "x": 0.0,
        "y": -0.0,
        "theta": 0.5,
        "frame": "map",
        "seq": 0,
        "tags": ["rust"],
        "covariance": [0.1, 0.2, 0.3],
        "mode": "Moving",
    }
    assert got[1]["covariance"] is None and got[1]["mode"] == "Idle"
    finish(peer)


def test_untyped_consumer_of_an_unknown_topic_says_so(participant):
    with pytest.raises(ndds.Timeout, match="no endpoint of topic 'x/nobody'"):
        participant.consumer("x/nobody", wait=0.2)


@dataclasses.dataclass
class Pose2D:  # another shape on the same topic
    x: float
    y: float


def test_a_type_mismatch_names_both_sides(domain, participant):
    consumer = participant.consumer("x/mismatch", Pose2D, reliable=True)
    peer = domain.rust("publish", "x/mismatch", "1")
    assert read_line(peer) == "ready"
    # A notification (recv_event), then every timeout explains itself (recv).
    event = consumer.recv_event(timeout=5)
    assert event.kind == "incompatible", event
    assert "Pose2D" in event.message and ndds.data_type(Pose2D).fingerprint in event.message
    assert ndds.data_type(Pose).fingerprint in event.message
    with pytest.raises(ndds.Timeout) as err:
        consumer.recv(timeout=1)
    message = str(err.value)
    assert "Pose2D" in message and "Pose" in message.replace("Pose2D", ""), message
    assert "after 0 ms" not in message and "1" in message.split("waiting")[0], message
    assert len(consumer.incompatible) == 1
    peer.kill()

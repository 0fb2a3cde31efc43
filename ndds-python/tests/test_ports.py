"""Ports from Python: send/receive/reply between Python tasks, with the Rust `pose_peer`
both ways, restrictions refused with ndds.Refused, timeouts with ndds.Timeout, sendall."""

from __future__ import annotations

import dataclasses
import threading

import pytest

import ndds
from conftest import finish, read_line
from test_rust import Mode, Pose


@dataclasses.dataclass
class Move:
    joint: str
    angle: float


def serve(owner: ndds.PortOwner, count: int, answer) -> threading.Thread:
    def run():
        for _ in range(count):
            request = owner.receive(timeout=20)
            request.reply(answer(request))

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_send_and_reply_between_python_tasks(participant):
    owner = ndds.PortOwner(participant, "gripper", "server", Move, float)
    user = ndds.PortUser(participant, "gripper", "client", Move, float)
    thread = serve(owner, 2, lambda r: r.value.angle * 2)
    assert user.send(Move("wrist", 0.5), timeout=10) == 1.0
    assert user.send(Move("wrist", -2.0), timeout=10) == -4.0
    thread.join(timeout=10)
    assert owner.users == ["client [Send]"]  # each user with the usages it declared


def test_the_request_carries_its_sender_and_is_replied_once(participant):
    owner = ndds.PortOwner(participant, "once", "server", Move, float)
    user = ndds.PortUser(participant, "once", "client", Move, float)
    replies = []
    threading.Thread(target=lambda: replies.append(user.send(Move("a", 1), timeout=10))).start()
    request = owner.receive(timeout=10)
    assert request.sender == "client" and request.value == Move("a", 1.0)
    request.reply(3.0)
    with pytest.raises(ndds.Error, match="replied to already"):
        request.reply(4.0)
    import time

    deadline = time.monotonic() + 10
    while not replies and time.monotonic() < deadline:
        time.sleep(0.01)
    assert replies == [3.0]


def test_python_user_rust_owner(domain, participant):
    peer = domain.rust("owner", "pose_port", "1")
    assert read_line(peer) == "ready"
    user = ndds.PortUser(participant, "pose_port", "py_user", Pose, float)
    pose = Pose(2.0, 3.0, 0.0, "map", 1, [], None, Mode.Idle)
    assert user.send(pose, timeout=20) == 5.0
    assert read_line(peer).startswith("request Pose { x: 2.0, y: 3.0")
    finish(peer)


def test_rust_user_python_owner(domain, participant):
    owner = ndds.PortOwner(participant, "pose_port2", "py_owner", Pose, float)
    peer = domain.rust("user", "pose_port2")
    assert read_line(peer) == "ready"
    request = owner.receive(timeout=20)
    assert request.sender == "rust_user"
    assert request.value.x == 2.0 and request.value.y == 3.0 and request.value.mode is Mode.Moving
    request.reply(request.value.x * request.value.y)
    assert read_line(peer) == "reply 6"
    finish(peer)


def test_a_user_the_owner_does_not_allow_is_refused(participant):
    owner = ndds.PortOwner(participant, "private", "server", Move, float, users=["trusted"])
    intruder = ndds.PortUser(participant, "private", "intruder", Move, float)
    serve(owner, 1, lambda r: 0.0)
    with pytest.raises(ndds.Refused) as err:
        intruder.send(Move("a", 1), timeout=10)
    message = str(err.value)
    assert "private" in message and "intruder" in message and "server" in message, message


def test_a_send_without_owner_times_out(participant):
    user = ndds.PortUser(participant, "nobody_home", "client", Move, float)
    with pytest.raises(ndds.Timeout, match="nobody_home"):
        user.send(Move("a", 1), timeout=0.5)


def test_other_message_types_are_reported(participant):
    owner = ndds.PortOwner(participant, "typed", "server", Move, float)
    user = ndds.PortUser(participant, "typed", "client", Pose, float)
    serve(owner, 1, lambda r: 0.0)
    with pytest.raises(ndds.IncompatibleType, match="formats"):
        user.send(Pose(0, 0, 0, "", 0, [], None, Mode.Idle), timeout=5)
    del owner


def broadcast_port(participant, port):
    owner = ndds.PortOwner(participant, port, "server", str, int, usages=["send_all", "call_all"])
    users = [
        ndds.PortUser(participant, port, f"u{i}", str, int, usages=["receive_all"])
        for i in range(2)
    ]
    got = []

    def take(user, i):
        got.append(user.receive_all(lambda message: len(message) + i, timeout=20))

    threads = [threading.Thread(target=take, args=(u, i)) for i, u in enumerate(users)]
    for t in threads:
        t.start()
    import time

    deadline = time.monotonic() + 20
    while owner.reached < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert owner.reached == 2, owner.users
    return owner, threads, got


def test_callall_waits_for_every_user(participant):
    owner, threads, got = broadcast_port(participant, "callall")
    replies, missing = owner.callall("stop", timeout=10)
    for t in threads:
        t.join(timeout=20)
    assert got == ["stop", "stop"]
    assert sorted(replies) == [("u0", 4), ("u1", 5)] and missing == []


def test_sendall_returns_the_first_reply_and_collects_more(participant):
    owner, threads, got = broadcast_port(participant, "sendall")
    replies = owner.sendall("go", timeout=10, collect=5.0)
    for t in threads:
        t.join(timeout=20)
    assert got == ["go", "go"]
    assert sorted(replies) == [("u0", 2), ("u1", 3)]


def test_query_is_answered_by_the_owner(participant):
    owner = ndds.PortOwner(participant, "lookup", "server", str, int)
    user = ndds.PortUser(participant, "lookup", "client", str, int, usages=["query"])
    thread = serve(owner, 1, lambda r: len(r.value))
    assert user.query("seven", timeout=10) == 5
    thread.join(timeout=10)
    # A usage the user did not declare is refused where it is made.
    with pytest.raises(ndds.Error, match="Send was not declared") as err:
        user.send("x", timeout=1)
    assert not isinstance(err.value, ndds.Timeout), err.value

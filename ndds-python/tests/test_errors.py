"""Bad input and bad times: samples that do not fit their type, types ndds cannot describe,
bad QoS values, a daemon that goes away, Ctrl-C during a blocking recv."""

from __future__ import annotations

import dataclasses
import signal
import time
from typing import Dict, List, Optional, Union

import pytest

import ndds
from conftest import read_line


@dataclasses.dataclass
class Inner:
    value: ndds.u8


@dataclasses.dataclass
class Outer:
    name: str
    inner: Inner
    items: List[Inner]
    table: Dict[str, float]
    maybe: Optional[int] = None


def good() -> Outer:
    return Outer("a", Inner(1), [Inner(2)], {"k": 1.0})


@pytest.fixture
def producer(participant):
    return participant.producer("err/outer", Outer)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda o: setattr(o, "name", 5), "sample field `name`: expected a str, got int 5"),
        (lambda o: setattr(o.inner, "value", 300), "sample field `inner.value`: 300 does not fit u8"),
        (lambda o: setattr(o.inner, "value", -1), "sample field `inner.value`: -1 does not fit u8"),
        (lambda o: setattr(o.inner, "value", 1.5), "sample field `inner.value`: expected an int (u8), got float 1.5"),
        (lambda o: setattr(o, "items", [Inner(1), Inner("x")]), "sample field `items[1].value`"),
        (lambda o: setattr(o, "items", "abc"), "sample field `items`: expected a list"),
        (lambda o: setattr(o, "table", {"k": "v"}), "sample field `table['k']`: expected a float"),
        (lambda o: setattr(o, "inner", {"value": 1, "extra": 2}), "sample field `inner`: unknown field str 'extra'"),
        (lambda o: setattr(o, "inner", {}), "sample field `inner.value`: missing"),
        (lambda o: setattr(o, "inner", 7), "sample field `inner`: expected a Inner"),
    ],
)
def test_a_sample_that_does_not_fit_raises_type_error_naming_the_field(producer, change, message):
    sample = good()
    change(sample)
    with pytest.raises(TypeError) as err:
        producer.write(sample)
    assert message in str(err.value)
    producer.write(good())  # nothing is broken


def test_the_wrong_sample_type_is_refused(producer):
    with pytest.raises(TypeError, match="expected a Outer"):
        producer.write(Inner(1))
    # A dict with the fields is accepted.
    producer.write({"name": "d", "inner": {"value": 3}, "items": [], "table": {}})


def test_types_without_an_ndds_counterpart_are_refused_with_advice(participant):
    @dataclasses.dataclass
    class Bad:
        x: Union[int, str]

    with pytest.raises(TypeError, match="Bad.x: .* is a union; only Optional"):
        participant.producer("err/bad", Bad)

    @dataclasses.dataclass
    class Worse:
        x: set

    with pytest.raises(TypeError, match="Worse.x: .* has no ndds type"):
        participant.producer("err/worse", Worse)

    with pytest.raises(TypeError, match="list needs an item type"):
        ndds.data_type(list)

    class Plain:
        x: float

    with pytest.raises(TypeError, match="Plain is a class but not a dataclass: add @dataclasses.dataclass"):
        participant.producer("err/plain", Plain)

    A1 = type("Same", (), {})
    first = dataclasses.make_dataclass("Same", [("x", float)])
    second = dataclasses.make_dataclass("Same", [("y", int)])
    both = dataclasses.make_dataclass("Both", [("a", first), ("b", second)])
    with pytest.raises(TypeError, match="two types named Same"):
        ndds.data_type(both)
    del A1


def test_bad_qos_values_say_what_is_allowed(participant):
    with pytest.raises(ValueError, match="persistence must be a finite number of seconds"):
        participant.producer("err/qos", Inner, persistence=-1)
    with pytest.raises(ValueError, match="history applies to reliable endpoints"):
        participant.consumer("err/qos", Inner, history=10)
    with pytest.raises(ValueError, match="immediate or polled"):
        participant.consumer("err/qos", Inner, mode="lazy")
    with pytest.raises(ValueError, match="block or drop_oldest"):
        participant.producer("err/qos", Inner, when_full="never")
    with pytest.raises(ValueError, match="auto, never or always"):
        ndds.Participant(embedded="sometimes")
    with pytest.raises(ValueError, match="timeout must be a finite number"):
        participant.consumer("err/qos", Inner).recv(timeout=float("nan"))
    with pytest.raises(ValueError, match="depth must be between 1 and"):
        participant.consumer("err/qos", Inner, depth=-1)
    with pytest.raises(TypeError, match="strength must be an int, got 'high'"):
        participant.producer("err/qos", Inner, strength="high")
    with pytest.raises(ValueError, match="domain must be between 0 and 232, got 100000"):
        ndds.Participant(domain=100000)


def test_no_daemon_and_no_embedding_is_a_clear_error(tmp_path):
    with pytest.raises(ndds.Disconnected, match="cannot connect"):
        ndds.Participant(domain=7, socket=str(tmp_path / "none.sock"), embedded="never")


def test_a_daemon_that_goes_away_raises_and_never_hangs(domain, participant):
    consumer = participant.consumer("err/gone", Inner)
    domain.daemons["a"].kill()
    domain.daemons["a"].wait()
    # A blocking call ends at its timeout.
    start = time.monotonic()
    with pytest.raises(ndds.Timeout):
        consumer.recv(timeout=1.0)
    assert time.monotonic() - start < 3.0
    # Declaring needs the daemon: once the connection is found gone, it raises.
    start = time.monotonic()
    deadline = start + 30
    while True:
        try:
            participant.producer("err/gone2", Inner)
        except ndds.Error as err:
            assert isinstance(err, (ndds.Disconnected, ndds.Timeout)), err
            break
        assert time.monotonic() < deadline, "declaring kept succeeding without a daemon"
        time.sleep(0.2)
    assert not participant.connected


WAITER = """
import ndds, dataclasses
@dataclasses.dataclass
class Inner:
    value: ndds.u8
p = ndds.Participant()
c = p.consumer("err/ctrl_c", Inner)
try:
    print("waiting", flush=True)
    c.recv()  # no timeout
except KeyboardInterrupt:
    print("interrupted", flush=True)
"""


def test_ctrl_c_interrupts_a_blocking_recv(domain):
    waiter = domain.python(WAITER)
    assert read_line(waiter) == "waiting"
    time.sleep(0.3)
    start = time.monotonic()
    waiter.send_signal(signal.SIGINT)
    assert read_line(waiter, timeout=5) == "interrupted"
    assert time.monotonic() - start < 2.0
    waiter.wait(timeout=10)
    assert waiter.returncode == 0


def test_a_closed_participant_declares_nothing(domain):
    p = domain.participant()
    p.close()
    with pytest.raises(ndds.Disconnected, match="closed"):
        p.producer("err/closed", Inner)


# Decoding what arrives, whatever arrives: DataType.decode is what a consumer runs on each
# payload.


@dataclasses.dataclass
class Node:
    value: int
    next: Optional["Node"] = None


def chain(length: int) -> Node:
    node = None
    for i in range(length):
        node = Node(i, node)
    return node


def test_bad_payloads_raise_value_error_saying_where():
    t = ndds.data_type(Outer)
    good_bytes = t.encode(good())
    assert t.decode(good_bytes) == good()
    with pytest.raises(ValueError, match="does not decode"):
        t.decode(good_bytes[:-3])
    with pytest.raises(ValueError, match="bytes after its value"):
        t.decode(good_bytes + b"\x00")
    with pytest.raises(ValueError):
        t.decode(b"")
    import enum

    class Mode(enum.Enum):
        Idle = 1
        Busy = 2

    m = ndds.data_type(Mode)
    assert m.decode(m.encode(Mode.Busy)) is Mode.Busy
    with pytest.raises(ValueError, match="Mode has no variant 7"):
        m.decode(b"\x07")


def test_a_length_claiming_billions_of_values_is_refused_without_allocating():
    t = ndds.data_type(List[None])  # Rust Vec<()>: values of no bytes
    with pytest.raises(ValueError, match="more than 1064 values"):
        t.decode(b"\xff\xff\xff\xff\x0f")  # 2^32 - 1 elements claimed in 5 bytes: at most 1024 + 8 per byte


def test_recursive_types_nest_to_the_same_depth_both_ways():
    # Each Node is two levels (the struct's field, the option): 64 levels hold 32 nodes.
    t = ndds.data_type(Node)
    deep = chain(30)
    assert t.decode(t.encode(deep)) == deep
    with pytest.raises(TypeError, match="nest deeper than 64"):
        t.encode(chain(40))
    # 40 nodes written by hand (value 0, then `Some`, ..., then `None`): refused when read.
    with pytest.raises(ValueError, match="nest deeper than 64"):
        t.decode(b"\x00\x01" * 39 + b"\x00\x00")


def test_keys_that_are_sequences_come_back_as_tuples():
    t = ndds.data_type(Dict[ndds.array(int, 2), float])
    assert t.decode(t.encode({(1, 2): 0.5})) == {(1, 2): 0.5}


def test_keyword_only_dataclasses_and_str_enums():
    import enum

    @dataclasses.dataclass(kw_only=True)
    class Settings:
        gain: float
        name: str

    t = ndds.data_type(Settings)
    assert t.decode(t.encode(Settings(gain=2.0, name="a"))) == Settings(gain=2.0, name="a")

    class Color(enum.StrEnum):
        Red = "red"
        Green = "green"

    c = ndds.data_type(Color)
    # By name, as the Rust enum's variants: the member's value plays no part.
    assert c.encode(Color.Green) == b"\x01"
    assert c.decode(b"\x01") is Color.Green


def test_a_misspelled_optional_field_is_not_taken_for_a_missing_one(producer):
    with pytest.raises(TypeError, match="unknown field str 'mayeb'"):
        producer.write({"name": "d", "inner": {"value": 3}, "items": [], "table": {}, "mayeb": 5})

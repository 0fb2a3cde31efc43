"""CSMats as NumPy arrays, and ControlShell systems loaded, driven and switched from Python."""

from __future__ import annotations

import pathlib
import time

import numpy as np
import pytest

import ndds

REPO = pathlib.Path(__file__).resolve().parents[2]


def test_csmat_wraps_without_copy_and_checks_fields():
    a = np.array([[1.0, 2.0], [3.0, 4.0]])
    m = ndds.CsMat(a, "K", rows=[("q1", "rad"), ("q2", "rad")], cols=["a", "b"])
    assert m.array is a  # float64 already: wrapped, not copied
    assert m.shape == (2, 2)
    assert m["q2", "a"] == 3.0 and m[0, 1] == 2.0
    assert m.row_units == ["rad", "rad"] and m.col_units == ["", ""]
    assert ndds.CsMat([1, 2, 3]).shape == (3, 1)  # a vector is a column
    with pytest.raises(ValueError, match="3 given for 2 rows"):
        ndds.CsMat(a, rows=["a", "b", "c"])
    with pytest.raises(KeyError, match="no row field 'q3'"):
        m["q3", "a"]


def test_csmat_round_trip_with_names_and_units(participant):
    producer = participant.producer("mat/state", ndds.CsMat)
    consumer = participant.consumer("mat/state", ndds.CsMat)
    assert producer.data_type.name == "ndds::CsMat"
    assert producer.wait_for_consumers(1, timeout=5)
    sent = ndds.CsMat(
        np.arange(6.0).reshape(3, 2),
        "state",
        rows=[("x", "m"), ("y", "m"), ("z", "m")],
        cols=[("pos", ""), ("vel", "m/s")],
    )
    producer.write(sent)
    got = consumer.recv(timeout=5).value
    assert got == sent
    assert got.array.dtype == np.float64 and not got.array.flags.writeable  # a view
    assert got["z", "vel"] == 5.0
    with pytest.raises(TypeError, match="expected an ndds.CsMat"):
        producer.write([[1.0]])


GAIN = """
[system]
name = "gain"
configuration = "Low"

[[habitat]]
name = "loop"
rate = 200.0

[[subscribe]]
mat = "setpoint"
topic = "gain/setpoint"
habitat = "loop"
shape = [1, 1]

[[component]]
name = "low"
type = "sum"
habitat = "loop"
group = "gain/low"
inputs = ["setpoint"]
signs = [2.0]
output = "out"

[[component]]
name = "high"
type = "sum"
habitat = "loop"
group = "gain/high"
inputs = ["setpoint"]
signs = [10.0]
output = "out"

[[configuration]]
name = "Low"
groups = ["gain/low"]

[[configuration]]
name = "High"
groups = ["gain/high"]

[[publish]]
mat = "out"
topic = "gain/out"
habitat = "loop"
"""


def latest(consumer, predicate, seconds=10.0):
    """The first sample whose value satisfies `predicate`, waiting up to `seconds`."""
    end = time.monotonic() + seconds
    last = None
    while time.monotonic() < end:
        try:
            last = consumer.recv(timeout=0.5).value
        except ndds.Timeout:
            continue
        if predicate(last):
            return last
    raise AssertionError(f"no matching sample within {seconds} s; last: {last!r}")


def test_a_live_system_driven_and_switched_from_python(tmp_path, participant):
    path = tmp_path / "gain.toml"
    path.write_text(GAIN)
    system = ndds.System.load(path, participant)
    assert system.name == "gain"
    assert system.topics == ["gain/out", "gain/setpoint"]
    setpoint = participant.producer("gain/setpoint", ndds.CsMat)
    out = participant.consumer("gain/out", ndds.CsMat)
    with system:
        assert system.configuration == "Low"
        assert setpoint.wait_for_consumers(1, timeout=10)
        # Written repeatedly: the system's subscription takes the latest.
        def drive(value):
            setpoint.write(ndds.CsMat([[value]], "setpoint"))

        drive(1.5)
        assert latest(out, lambda m: (drive(1.5), m.array[0, 0] == 3.0)[1]).name == "out"
        system.switch("High")
        assert system.configuration == "High"
        assert latest(out, lambda m: (drive(1.5), m.array[0, 0] == 15.0)[1])
        # Outside the habitat, the value is the one its last completed sample left: the
        # topic may carry a sample's output a moment before the system's own view has it.
        end = time.monotonic() + 2
        while system.mat("out")[0, 0] != 15.0 and time.monotonic() < end:
            time.sleep(0.005)
        assert system.mat("out")[0, 0] == 15.0
        status = system.status()
        assert status["configuration"] == "High"
        assert status["habitats"]["loop"]["running"] is True
        assert status["habitats"]["loop"]["samples"] > 0
        with pytest.raises(ndds.Error, match="Medium"):
            system.switch("Medium")
        with pytest.raises(ndds.Error, match="no CSMat `nope`"):
            system.mat("nope")
        with pytest.raises(ndds.Error, match="simulated=True"):
            system.simulate(1.0)


def test_a_state_machine_sequence_in_simulated_time():
    system = ndds.System.load(REPO / "examples" / "sequence.toml", simulated=True)
    assert system.machines == ["task"]
    with pytest.raises(ndds.Error, match="not running: start"):
        system.simulate(1.0)
    system.start()
    try:
        assert system.state("task") == "MovingToA"
        assert system.configuration == "ToA"
        # The triggers drive the machine through A, B and home within 10 simulated seconds.
        # The machine reacts in real time on its own thread: simulate in steps, giving it a
        # moment between them.
        simulated = 0.0
        deadline = time.monotonic() + 60
        while not system.wait_for_state("task", "Done", timeout=0.02):
            assert time.monotonic() < deadline and simulated < 120, (
                f"{system.state('task')} after {simulated:.1f} simulated seconds"
            )
            system.simulate(0.1)
            simulated += 0.1
        assert simulated > 4.0  # the three moves take 1.5 + 2 + 1 s
        assert system.configuration == "Home"
        assert abs(system.mat("position")[0, 0]) < 0.01
        assert set(system.status()["display"]) == {"position", "setpoint"}
    finally:
        system.stop()


def test_a_stimulus_from_python(tmp_path):
    (tmp_path / "m.toml").write_text(
        'main = "m"\n[stimuli]\nGo = "transient"\n'
        '[[machine]]\nname = "m"\nstart = "Idle"\nstates = ["Idle", "Running"]\n'
        '[[machine.transition]]\nfrom = "Idle"\nwhen = "Go"\naction = "switch Run"\n'
        'next = { 0 = "Running", 1 = "Idle" }\n'
    )
    (tmp_path / "s.toml").write_text(
        '[system]\nname = "s"\n[[habitat]]\nname = "h"\nrate = 100.0\n'
        '[[mat]]\nname = "one"\nvalue = 1.0\n'
        '[[component]]\nname = "c"\ntype = "sum"\nhabitat = "h"\ngroup = "g/run"\n'
        'inputs = ["one"]\noutput = "o"\n'
        '[[configuration]]\nname = "Run"\ngroups = ["g/run"]\n'
        '[[state_machine]]\nfile = "m.toml"\n'
    )
    system = ndds.System.load(tmp_path / "s.toml", simulated=True)
    with system:
        assert system.state("m") == "Idle"
        system.stimulus("m", "Go")
        deadline = time.monotonic() + 10
        while system.state("m") != "Running" and time.monotonic() < deadline:
            time.sleep(0.02)
        assert system.state("m") == "Running" and system.configuration == "Run"
        with pytest.raises(ndds.Error, match="unknown|Stop"):
            system.stimulus("m", "Stop")
        with pytest.raises(ndds.Error, match="no running state machine `other`"):
            system.stimulus("other", "Go")


def test_a_bad_description_file_names_the_place(tmp_path, participant):
    path = tmp_path / "bad.toml"
    path.write_text('[[habitat]]\nname = "h"\nrate = 100.0\n\n[[component]]\nname = "c"\ntype = "sinus"\nhabitat = "h"\n')
    with pytest.raises(ndds.Error) as err:
        ndds.System.load(path, participant)
    message = str(err.value)
    assert "bad.toml:7" in message and "sinus" in message and "sine" in message, message
    with pytest.raises(ndds.Error, match="needs a participant|participant"):
        ndds.System.load(REPO / "examples" / "arm.toml")

"""Fixtures of the Python suite: a real `ndds-daemon` per test on loopback (its own domain,
discovery port, multicast group and socket, so tests never see each other), participants on
it, and helpers to run Python and Rust peer processes in the same domain.

The daemon is `NDDS_DAEMON`, else `target/debug/ndds-daemon` of this checkout; the Rust peer
is `NDDS_POSE_PEER`, else `target/debug/pose_peer` (built with `cargo build -p interop-tests
--bin pose_peer`). `cargo test -p interop-tests --test python` sets both.
"""

from __future__ import annotations

import os
import pathlib
import random
import socket
import subprocess
import sys
import time
from typing import Dict, List, Optional

import pytest

import ndds

REPO = pathlib.Path(__file__).resolve().parents[2]

# Discovery every 200 ms and 1 s leases, as the Rust interop tests use: matching in well under
# a second, dead peers noticed in about one.
PERIOD_MS = 200
LEASE_MS = 1000


def binary(name: str, env: str) -> str:
    path = os.environ.get(env) or str(REPO / "target" / "debug" / name)
    if not os.path.exists(path):
        pytest.fail(
            f"{path} is missing: build it (cargo build -p interop-tests --bin pose_peer; "
            "cargo build -p ndds-daemon) or set {env}"
        )
    return path


class Domain:
    """One isolated ndds domain on loopback, with its daemons."""

    def __init__(self, directory: pathlib.Path) -> None:
        rng = random.Random()
        self.domain = rng.randint(1, 232)
        self.port = rng.randint(20000, 59999)
        self.group = f"239.255.{rng.randint(100, 254)}.{rng.randint(1, 254)}"
        self.dir = directory
        self.daemons: Dict[str, subprocess.Popen] = {}
        self.children: List[subprocess.Popen] = []

    def socket(self, name: str = "a") -> str:
        return str(self.dir / f"{name}.sock")

    def start_daemon(self, name: str = "a") -> subprocess.Popen:
        log = open(self.dir / f"{name}.log", "ab")
        args = [
            binary("ndds-daemon", "NDDS_DAEMON"),
            "--domain", str(self.domain),
            "--socket", self.socket(name),
            "--interface", "127.0.0.1",
            "--multicast-group", self.group,
            "--discovery-port", str(self.port),
            "--announce-period-ms", str(PERIOD_MS),
            "--lease-ms", str(LEASE_MS),
        ]
        process = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log)
        self.daemons[name] = process
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                with socket.socket(socket.AF_UNIX) as s:
                    s.connect(self.socket(name))
                return process
            except OSError:
                time.sleep(0.02)
        raise AssertionError(f"daemon {name} did not start: {self.log(name)}")

    def log(self, name: str = "a") -> str:
        path = self.dir / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def env(self, name: str = "a") -> Dict[str, str]:
        """The environment of a peer process on daemon `name`."""
        env = dict(os.environ)
        env.update(
            NDDS_DOMAIN=str(self.domain),
            NDDS_SOCKET=self.socket(name),
            NDDS_EMBEDDED="never",
        )
        return env

    def participant(self, name: str = "a") -> ndds.Participant:
        return ndds.Participant(domain=self.domain, socket=self.socket(name), embedded="never")

    def spawn(self, args: List[str], name: str = "a") -> subprocess.Popen:
        """A peer process in this domain; its output is read with `read_line`."""
        process = subprocess.Popen(
            args,
            env=self.env(name),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.children.append(process)
        return process

    def python(self, code: str, *args: str) -> subprocess.Popen:
        """A Python peer process running `code` (with `sys.argv[1:] == args`)."""
        return self.spawn([sys.executable, "-c", code, *args])

    def rust(self, *args: str) -> subprocess.Popen:
        """The Rust peer (`pose_peer`) with `args`."""
        return self.spawn([binary("pose_peer", "NDDS_POSE_PEER"), *args])

    def close(self) -> None:
        for process in self.children + list(self.daemons.values()):
            if process.poll() is None:
                process.kill()
            process.wait(timeout=10)


def read_line(process: subprocess.Popen, timeout: float = 20.0) -> str:
    """The next line the process prints, failing with its stderr if it ends first."""
    import selectors

    selector = selectors.DefaultSelector()
    selector.register(process.stdout, selectors.EVENT_READ)
    if not selector.select(timeout):
        raise AssertionError(f"no output within {timeout} s from {process.args}")
    line = process.stdout.readline()
    if not line:
        process.wait(timeout=10)
        raise AssertionError(
            f"{process.args} ended (status {process.returncode}): {process.stderr.read()}"
        )
    return line.strip()


def finish(process: subprocess.Popen, timeout: float = 30.0) -> str:
    """Waits for a peer to end successfully; returns the rest of its output."""
    out, err = process.communicate(timeout=timeout)
    assert process.returncode == 0, f"{process.args} failed ({process.returncode}): {err}"
    return out


@pytest.fixture
def domain(tmp_path: pathlib.Path):
    d = Domain(tmp_path)
    d.start_daemon("a")
    yield d
    d.close()


@pytest.fixture
def participant(domain: Domain) -> ndds.Participant:
    p = domain.participant()
    yield p
    p.close()

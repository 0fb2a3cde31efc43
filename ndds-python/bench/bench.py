#!/usr/bin/env python3
"""Compare Python pub/sub bindings: 64 B round trip and 64 B one-way throughput.

Every measurement runs two processes, both this script started again with
`--role`, talking over loopback only; the parent process only starts them,
passes a few control lines between them through their stdin/stdout, and
kills any that outlives its deadline.

An implementation is a module `impl_<name>.py` beside this file; see README.md
for the interface it provides. One that fails to import is skipped, with the
reason.

    python bench.py [--impl zenoh,cyclone,ndds] [--rt-count N] [--seconds S] [--json FILE]
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import queue
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Dict, List, Optional

HERE = os.path.dirname(os.path.abspath(__file__))
ALL_IMPLS = ["zenoh", "cyclone", "ndds"]

PAYLOAD_SIZE = 64
PING_TOPIC = "bench/ping"
PONG_TOPIC = "bench/pong"
TP_TOPIC = "bench/throughput"

# Every payload is 64 bytes: a kind byte, a signed 64-bit sequence number, zero padding.
HEADER = struct.Struct("<cq")
SYNC = b"S"  # ping -> pong until the first echo comes back (matching)
RT = b"R"  # a measured (or warm-up) round trip
STOP = b"X"  # ping -> pong: exit
PROBE = b"P"  # source -> sink until the sink has seen one (matching)
DATA = b"D"  # a counted throughput sample
END = b"E"  # source -> sink: the run is over

MATCH_TIMEOUT_S = 30.0  # how long the two sides may take to find each other


def make_payload(kind: bytes, seq: int = 0) -> bytes:
    return HEADER.pack(kind, seq).ljust(PAYLOAD_SIZE, b"\0")


# --------------------------------------------------------------------------------------
# Child side
# --------------------------------------------------------------------------------------

_emit_lock = threading.Lock()


def emit(tag: str, payload: Any = None) -> None:
    """One control line to the parent: `TAG` or `TAG <json>`."""
    line = tag if payload is None else f"{tag} {json.dumps(payload)}"
    with _emit_lock:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def start_watchdog(seconds: float) -> None:
    """Exit hard if this child is still alive after `seconds` (a library may hang in close)."""

    def expire() -> None:
        sys.stderr.write(f"child deadline of {seconds:.0f} s reached, exiting\n")
        sys.stderr.flush()
        os._exit(3)

    timer = threading.Timer(seconds, expire)
    timer.daemon = True
    timer.start()


def watch_stdin(events: Dict[str, threading.Event]) -> None:
    """Set events[line] for each control line from the parent; EOF sets STOP."""

    def run() -> None:
        for line in sys.stdin:
            ev = events.get(line.strip())
            if ev is not None:
                ev.set()
        events["STOP"].set()

    threading.Thread(target=run, daemon=True).start()


def style(mod, attr: str) -> str:
    """The receive style the impl prefers, or the override PYBENCH_<attr> (for trying both)."""
    value = os.environ.get(f"PYBENCH_{attr}") or getattr(mod, attr, "pull")
    if value not in ("callback", "pull"):
        raise SystemExit(f"{attr} must be callback or pull, not {value!r}")
    return value


def role_pong(mod, node, args) -> None:
    """Echo every ping on the pong topic until told to stop."""
    pub = node.publisher(PONG_TOPIC, reliable=True)
    stop = threading.Event()
    watch_stdin({"STOP": stop})
    echoed = 0

    def on_ping(data: bytes) -> None:
        nonlocal echoed
        if data[:1] == STOP:
            stop.set()
            return
        pub.put(data)
        echoed += 1

    if style(mod, "ECHO_STYLE") == "callback":
        # Keep the subscriber referenced: some bindings undeclare it when it is collected.
        sub = node.subscriber(PING_TOPIC, reliable=True, on_data=on_ping)  # noqa: F841
        emit("READY")
        stop.wait(args.deadline)
    else:
        sub = node.subscriber(PING_TOPIC, reliable=True)
        emit("READY")
        while not stop.is_set():
            data = sub.recv(0.2)
            if data is not None:
                on_ping(data)
    emit("RESULT", {"echoed": echoed})


def role_ping(mod, node, args) -> None:
    """Send pings one at a time and time each until its echo comes back."""
    sub = node.subscriber(PONG_TOPIC, reliable=True)
    pub = node.publisher(PING_TOPIC, reliable=True)

    # Matching: keep sending SYNC pings (each with a new number) until one is echoed.
    give_up = time.monotonic() + MATCH_TIMEOUT_S
    seq = 0
    matched = False
    while not matched:
        if time.monotonic() > give_up:
            raise SystemExit("ping: no answer from pong within the matching timeout")
        seq -= 1
        msg = make_payload(SYNC, seq)
        pub.put(msg)
        retry_at = time.monotonic() + 0.1
        while not matched and time.monotonic() < retry_at:
            got = sub.recv(max(0.0, retry_at - time.monotonic()))
            matched = got == msg
    # Let the echoes of earlier SYNC pings arrive and throw them away.
    while sub.recv(0.3) is not None:
        pass

    recv = sub.recv
    put = pub.put
    clock = time.perf_counter_ns

    def round_trip(seq: int) -> Optional[int]:
        msg = make_payload(RT, seq)
        t0 = clock()
        put(msg)
        while True:
            got = recv(args.rt_timeout)
            if got is None:
                return None  # lost (counted, not timed)
            if got == msg:
                return clock() - t0

    lost = 0
    for i in range(args.warmup):
        if round_trip(i) is None:
            lost += 1
    samples: List[int] = []
    for i in range(args.warmup, args.warmup + args.rt_count):
        rtt = round_trip(i)
        if rtt is None:
            lost += 1
        else:
            samples.append(rtt)

    for _ in range(3):  # the stop message is reliable, but pong also stops on its stdin
        put(make_payload(STOP))
    samples.sort()
    emit("RESULT", {"count": len(samples), "lost": lost, **latency_stats(samples)})


def latency_stats(samples_ns: List[int]) -> Dict[str, float]:
    """Nearest-rank percentiles (and min/max/mean) of sorted nanosecond samples, in µs."""
    if not samples_ns:
        return {}

    def pct(p: float) -> float:
        rank = max(1, -(-len(samples_ns) * p // 100))  # ceil(n * p / 100)
        return samples_ns[int(rank) - 1] / 1000.0

    return {
        "min_us": samples_ns[0] / 1000.0,
        "p50_us": pct(50),
        "p90_us": pct(90),
        "p99_us": pct(99),
        "max_us": samples_ns[-1] / 1000.0,
        "mean_us": sum(samples_ns) / len(samples_ns) / 1000.0,
    }


class SinkCounter:
    """Counts DATA samples; the window runs from the first to the last one received."""

    def __init__(self) -> None:
        self.count = 0
        self.first_ns = 0
        self.last_ns = 0
        self.probed = False
        self.done = threading.Event()

    def on_data(self, data: bytes) -> None:
        kind = data[:1]
        if kind == DATA:
            now = time.perf_counter_ns()
            if not self.count:
                self.first_ns = now
            self.last_ns = now
            self.count += 1
        elif kind == PROBE:
            if not self.probed:
                self.probed = True
                emit("MATCHED")
        elif kind == END:
            self.done.set()


def role_sink(mod, node, args) -> None:
    counter = SinkCounter()
    # The run ends on the source's END marker, or on STOP from the parent (best effort
    # may lose every END).
    watch_stdin({"STOP": counter.done})
    if style(mod, "SINK_STYLE") == "callback":
        sub = node.subscriber(TP_TOPIC, reliable=args.tp_reliable, on_data=counter.on_data)  # noqa: F841
        emit("READY")
        counter.done.wait(args.deadline)
    else:
        sub = node.subscriber(TP_TOPIC, reliable=args.tp_reliable)
        emit("READY")
        on_data = counter.on_data
        recv = sub.recv
        while not counter.done.is_set():
            data = recv(0.2)
            if data is not None:
                on_data(data)
    window_s = (counter.last_ns - counter.first_ns) / 1e9
    rate = (counter.count - 1) / window_s if window_s > 0 else 0.0
    emit("RESULT", {"received": counter.count, "window_s": window_s, "rate": rate})


def role_source(mod, node, args) -> None:
    pub = node.publisher(TP_TOPIC, reliable=args.tp_reliable)
    go, stop = threading.Event(), threading.Event()
    watch_stdin({"GO": go, "STOP": stop})

    # Matching: probe until the parent relays that the sink has seen a probe.
    give_up = time.monotonic() + MATCH_TIMEOUT_S
    probe = make_payload(PROBE)
    while not go.wait(0.05):
        if stop.is_set() or time.monotonic() > give_up:
            raise SystemExit("source: the sink never saw a probe")
        pub.put(probe)

    data = make_payload(DATA)
    put = pub.put
    clock = time.perf_counter
    sent = 0
    t0 = clock()
    t_end = t0 + args.seconds
    while True:
        put(data)
        sent += 1
        if not sent & 255 and clock() >= t_end:  # read the clock every 256 samples
            break
    elapsed = clock() - t0

    time.sleep(0.2)
    end = make_payload(END)
    for _ in range(5):
        put(end)
        time.sleep(0.02)
    emit("RESULT", {"sent": sent, "send_s": elapsed, "send_rate": sent / elapsed})


def role_info(mod, args) -> None:
    emit("INFO", {
        "version": mod.library_version(),
        "echo_style": style(mod, "ECHO_STYLE"),
        "sink_style": style(mod, "SINK_STYLE"),
    })


def run_child(args) -> None:
    start_watchdog(args.deadline)
    sys.path.insert(0, HERE)
    mod = importlib.import_module(f"impl_{args.impl}")
    if args.role == "info":
        role_info(mod, args)
        return
    node = mod.Node(args.side, args.port)
    node.open()
    try:
        {"ping": role_ping, "pong": role_pong, "sink": role_sink, "source": role_source}[
            args.role
        ](mod, node, args)
    finally:
        node.close()
    sys.stdout.flush()
    # Skip interpreter teardown: some bindings' background threads make it slow.
    os._exit(0)


# --------------------------------------------------------------------------------------
# Parent side
# --------------------------------------------------------------------------------------


class ChildFailed(Exception):
    def last_line(self) -> str:
        lines = str(self).strip().splitlines()
        return lines[-1] if lines else ""


class Child:
    """A child process of this script, with its stdout read line by line on a thread."""

    def __init__(self, impl: str, role: str, side: str, port: int, args, env: Dict[str, str]):
        self.name = f"{impl}/{role}"
        self.deadline_s = args.child_timeout
        cmd = [
            sys.executable, os.path.abspath(__file__),
            "--impl", impl, "--role", role, "--side", side, "--port", str(port),
            "--deadline", str(args.child_timeout),
            "--rt-count", str(args.rt_count), "--warmup", str(args.warmup),
            "--rt-timeout", str(args.rt_timeout), "--seconds", str(args.seconds),
        ]
        if args.tp_reliable:
            cmd.append("--tp-reliable")
        self.stderr = tempfile.TemporaryFile(mode="w+")
        self.proc = subprocess.Popen(
            cmd, cwd=HERE, env=env, text=True, bufsize=1,
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.stderr,
        )
        self.started = time.monotonic()
        self.lines: "queue.Queue[Optional[str]]" = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))
        self.lines.put(None)

    def expect(self, tag: str, timeout: float) -> Any:
        """Wait for the control line `tag`; return its JSON payload (or None)."""
        # The child's own watchdog fires at deadline_s; give it a moment to say so.
        limit = min(time.monotonic() + timeout, self.started + self.deadline_s + 5)
        while True:
            remaining = limit - time.monotonic()
            try:
                line = self.lines.get(timeout=max(0.0, remaining))
            except queue.Empty:
                waited = time.monotonic() - self.started
                raise ChildFailed(
                    f"{self.name}: no {tag} after {waited:.0f} s{self.stderr_tail()}"
                )
            if line is None:
                self.proc.wait()
                raise ChildFailed(
                    f"{self.name}: exited ({self.proc.returncode}) before {tag}{self.stderr_tail()}"
                )
            word, _, rest = line.partition(" ")
            if word == tag:
                return json.loads(rest) if rest else None

    def send(self, line: str) -> None:
        try:
            self.proc.stdin.write(line + "\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError):
            pass

    def finish(self, grace: float = 10.0) -> None:
        """Close stdin (the child's cue to stop), wait a little, then kill it."""
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            sys.stderr.write(f"  {self.name}: still running, killed\n")
            self.proc.kill()
            self.proc.wait()
        self.stderr.close()

    def stderr_tail(self, chars: int = 2000) -> str:
        self.stderr.flush()
        self.stderr.seek(0)
        tail = self.stderr.read()[-chars:].strip()
        return f"\n--- {self.name} stderr ---\n{tail}" if tail else ""


def free_loopback_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def child_env() -> Dict[str, str]:
    env = dict(os.environ)
    env["PYTHONUNBUFFERED"] = "1"
    # One DDS domain per harness run, so that two runs on one host do not meet.
    env.setdefault("PYBENCH_DDS_DOMAIN", str(1 + os.getpid() % 200))
    return env


def probe_impl(impl: str, args, env) -> Dict[str, Any]:
    child = Child(impl, "info", "a", 0, args, env)
    try:
        return child.expect("INFO", 60)
    finally:
        child.finish()


def measure_round_trip(impl: str, args, env) -> Dict[str, Any]:
    port = free_loopback_port()
    pong = Child(impl, "pong", "a", port, args, env)  # side a listens (zenoh)
    ping = None
    try:
        pong.expect("READY", 60)
        ping = Child(impl, "ping", "b", port, args, env)
        result = ping.expect("RESULT", args.child_timeout)
        pong.send("STOP")
        pong.expect("RESULT", 10)
        return result
    finally:
        if ping is not None:
            ping.finish()
        pong.finish()


def measure_throughput(impl: str, args, env) -> Dict[str, Any]:
    port = free_loopback_port()
    sink = Child(impl, "sink", "a", port, args, env)
    source = None
    try:
        sink.expect("READY", 60)
        source = Child(impl, "source", "b", port, args, env)
        sink.expect("MATCHED", MATCH_TIMEOUT_S + 30)
        source.send("GO")
        sent = source.expect("RESULT", args.seconds + 60)
        time.sleep(1.0)  # samples still queued reach the sink (unless END already did)
        sink.send("STOP")
        got = sink.expect("RESULT", 30)
        result = {**sent, **got}
        result["loss_pct"] = 100.0 * (1 - got["received"] / sent["sent"]) if sent["sent"] else 0.0
        return result
    finally:
        if source is not None:
            source.finish()
        sink.finish()


def fmt(value: Optional[float], spec: str) -> str:
    return "—" if value is None else format(value, spec)


def table(rows: List[Dict[str, Any]]) -> str:
    out = [
        "| impl | version | RT p50 µs | RT p90 µs | RT p99 µs | RT n (lost) "
        "| TP samples/s | TP received | TP sent | TP loss |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        rt = row.get("round_trip") or {}
        tp = row.get("throughput") or {}
        rt_n = f"{rt['count']} ({rt['lost']})" if "count" in rt else "—"
        out.append(
            f"| {row['impl']} | {row.get('version', '—')} "
            f"| {fmt(rt.get('p50_us'), '.1f')} | {fmt(rt.get('p90_us'), '.1f')} "
            f"| {fmt(rt.get('p99_us'), '.1f')} | {rt_n} "
            f"| {fmt(tp.get('rate'), ',.0f')} | {fmt(tp.get('received'), ',d')} "
            f"| {fmt(tp.get('sent'), ',d')} | {fmt(tp.get('loss_pct'), '.1f')}{'%' if 'loss_pct' in tp else ''} |"
        )
    return "\n".join(out)


def run_parent(args) -> int:
    impls = [name.strip() for name in args.impl.split(",") if name.strip()]
    tests = [t.strip() for t in args.tests.split(",") if t.strip()]
    env = child_env()
    rows: List[Dict[str, Any]] = []
    failed = False
    for impl in impls:
        if not os.path.exists(os.path.join(HERE, f"impl_{impl}.py")):
            print(f"{impl}: skipped (no impl_{impl}.py)", flush=True)
            continue
        try:
            info = probe_impl(impl, args, env)
        except ChildFailed as e:
            print(f"{impl}: skipped, it does not load: {e.last_line()}", flush=True)
            continue
        row: Dict[str, Any] = {"impl": impl, **info}
        print(f"{impl}: {info['version']} (pong echoes by {info['echo_style']}, "
              f"sink counts by {info['sink_style']})", flush=True)
        for test, fn in (("rt", measure_round_trip), ("tp", measure_throughput)):
            if test not in tests:
                continue
            key = "round_trip" if test == "rt" else "throughput"
            try:
                row[key] = fn(impl, args, env)
                print(f"  {key}: {json.dumps(row[key])}", flush=True)
            except ChildFailed as e:
                failed = True
                row[key] = {"error": str(e)}
                print(f"  {key}: FAILED\n{e}", flush=True)
        rows.append(row)

    print()
    print(
        f"64 B payloads; round trip: {args.warmup} warm-up + {args.rt_count} measured, reliable; "
        f"throughput: {args.seconds:g} s, {'reliable' if args.tp_reliable else 'best effort'}"
    )
    print()
    print(table(rows))
    if args.json:
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        with open(args.json, "a") as f:  # appended: one line per implementation and run
            for row in rows:
                record = {
                    "time": stamp,
                    "host": platform.node(),
                    "python": platform.python_version(),
                    "payload_bytes": PAYLOAD_SIZE,
                    "rt_warmup": args.warmup,
                    "rt_count": args.rt_count,
                    "tp_seconds": args.seconds,
                    "tp_reliable": args.tp_reliable,
                    **row,
                }
                f.write(json.dumps(record) + "\n")
    return 1 if failed else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--impl", default=",".join(ALL_IMPLS), help="comma-separated (default: all)")
    ap.add_argument("--tests", default="rt,tp", help="rt (round trip), tp (throughput)")
    ap.add_argument("--rt-count", type=int, default=10000, help="measured round trips")
    ap.add_argument("--warmup", type=int, default=1000, help="warm-up round trips")
    ap.add_argument("--rt-timeout", type=float, default=1.0,
                    help="seconds before a round trip counts as lost")
    ap.add_argument("--seconds", type=float, default=5.0, help="throughput send duration")
    ap.add_argument("--tp-reliable", action="store_true",
                    help="throughput with reliable delivery (default: best effort)")
    ap.add_argument("--json", metavar="FILE", help="append one JSON line per implementation")
    ap.add_argument("--child-timeout", type=float, default=180.0,
                    help="seconds after which a child is killed")
    # Internal: a child's role.
    ap.add_argument("--role", choices=["info", "ping", "pong", "sink", "source"], help=argparse.SUPPRESS)
    ap.add_argument("--side", default="a", help=argparse.SUPPRESS)
    ap.add_argument("--port", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--deadline", type=float, default=180.0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.role:
        run_child(args)
        return 0
    return run_parent(args)


if __name__ == "__main__":
    sys.exit(main())

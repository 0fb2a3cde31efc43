#!/usr/bin/env bash
# The Python bindings in one sitting (issue 21): 64 B round trip and 64 B one-way throughput
# between two Python processes with ndds-python, zenoh-python and cyclonedds-python
# (ndds-python/bench/bench.py), and the same two measurements with the Rust `ndds perf`, so
# that the binding's own overhead is a same-run difference.
#
#   scripts/bench-python.sh          prints a Markdown section on stdout, progress on stderr
#
# Environment: BENCH_ROUNDS (default 3), PYBENCH_VENV (the scratch virtual environment, default
# /tmp/ndds-pybench; created with numpy, maturin, eclipse-zenoh and cyclonedds from pip, and
# ndds-python built into it with --release).
# All traffic stays on 127.0.0.1: one ndds-daemon on loopback (its default) serves both the
# Python and the Rust pairs; zenoh runs in peer mode on tcp/127.0.0.1 with multicast scouting
# off, Cyclone on `lo` with multicast off (see ndds-python/bench/README.md).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
ROUNDS=${BENCH_ROUNDS:-3}
VENV=${PYBENCH_VENV:-/tmp/ndds-pybench}
WORK=$(mktemp -d /tmp/ndds-bench-python.XXXXXX)
NDDS=$ROOT/target/release/ndds
DAEMON=$ROOT/target/release/ndds-daemon
DOMAIN=$((150 + $$ % 80))
SOCK=$WORK/ndds.sock
LIMIT="timeout 60"

cleanup() {
    [[ -n ${DAEMON_PID:-} ]] && kill "$DAEMON_PID" 2>/dev/null || true
    wait 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT
say() { echo "bench-python: $*" >&2; }

say "scratch environment $VENV"
[[ -x $VENV/bin/python ]] || python3 -m venv "$VENV"
"$VENV/bin/pip" install --quiet --disable-pip-version-check "maturin>=1.9,<2" numpy \
    --only-binary=:all: eclipse-zenoh==1.10.2 cyclonedds==11.0.1 >&2
say "building ndds-python (release) into it"
(cd ndds-python && VIRTUAL_ENV=$VENV "$VENV/bin/maturin" develop --release --locked) >&2
say "building release binaries"
cargo build --release --locked -p ndds-cli -p ndds-daemon >&2

say "starting ndds-daemon on loopback (domain $DOMAIN)"
"$DAEMON" --domain "$DOMAIN" --socket "$SOCK" >"$WORK/daemon.log" 2>&1 &
DAEMON_PID=$!
for _ in $(seq 100); do [[ -S $SOCK ]] && break; sleep 0.05; done
[[ -S $SOCK ]] || { cat "$WORK/daemon.log" >&2; exit 1; }
export NDDS_DOMAIN=$DOMAIN NDDS_SOCKET=$SOCK PYBENCH_DDS_DOMAIN=$DOMAIN NDDS_EMBEDDED=never
P="$NDDS perf"

for round in $(seq "$ROUNDS"); do
    say "round $round: Python (ndds, zenoh, cyclone)"
    $LIMIT "$VENV/bin/python" ndds-python/bench/bench.py --impl ndds,zenoh,cyclone \
        --json "$WORK/python.jsonl" >"$WORK/python-$round.txt" 2>&1 ||
        { cat "$WORK/python-$round.txt" >&2; exit 1; }
    say "round $round: Rust ndds perf"
    # The same measurements: reliable round trips, 1000 warm-up and 10000 measured; best-effort
    # throughput batched at 1 ms / 8 KiB for 5 s, as the Python adapter does.
    $LIMIT $P pong --reliable --topic "py$round/rt" >/dev/null 2>&1 &
    PONG=$!
    $LIMIT $P ping --reliable --topic "py$round/rt" --count 10000 --warmup 1000 --json \
        >>"$WORK/rust-rt.jsonl"
    kill "$PONG" 2>/dev/null || true
    wait "$PONG" 2>/dev/null || true
    $LIMIT $P sub --topic "py$round/tp" --duration 4 --json >>"$WORK/rust-tp.jsonl" &
    SUB=$!
    sleep 0.3
    $LIMIT $P pub --topic "py$round/tp" --duration 5 --batch-us 1000 --batch-bytes 8192 \
        --json >/dev/null
    wait "$SUB"
done

"$VENV/bin/python" - "$WORK" "$ROUNDS" <<'EOF'
import json, sys
work, rounds = sys.argv[1], int(sys.argv[2])
py = [json.loads(l) for l in open(f"{work}/python.jsonl")]
rt = [json.loads(l) for l in open(f"{work}/rust-rt.jsonl")]
tp = [json.loads(l) for l in open(f"{work}/rust-tp.jsonl")]
def get(d, *keys):
    for k in keys:
        d = d.get(k) if isinstance(d, dict) else None
    return d
versions = {r["impl"]: r.get("version", "") for r in py}
print("| round | ndds RT p50 µs | zenoh RT p50 µs | cyclone RT p50 µs | Rust ndds perf RT p50 µs "
      "| ndds TP /s | zenoh TP /s | cyclone TP /s | Rust ndds perf TP /s |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
by_round = [py[i * 3:(i + 1) * 3] for i in range(rounds)]
for i, rows in enumerate(by_round):
    r = {row["impl"]: row for row in rows}
    def rtp(name):
        return get(r.get(name, {}), "round_trip", "p50_us")
    def tput(name):
        return get(r.get(name, {}), "throughput", "rate")
    rust_rt = rt[i]["p50_us"]
    rust_tp = tp[i]["samples_per_s"]
    cells = [rtp("ndds"), rtp("zenoh"), rtp("cyclone"), rust_rt,
             tput("ndds"), tput("zenoh"), tput("cyclone"), rust_tp]
    fmt = lambda v, d: "—" if v is None else (f"{v:,.{d}f}")
    print(f"| {i + 1} | " + " | ".join(fmt(c, 1 if j < 4 else 0) for j, c in enumerate(cells)) + " |")
print()
print("Versions: " + ", ".join(f"{k}: {v}" for k, v in versions.items()))
nd = [r for r in py if r["impl"] == "ndds"]
ratio_rt = [n["round_trip"]["p50_us"] / r["p50_us"] for n, r in zip(nd, rt)]
ratio_tp = [n["throughput"]["rate"] / t["samples_per_s"] for n, t in zip(nd, tp)]
print()
print("Binding overhead, same round: Python ndds RT p50 / Rust ndds perf RT p50 = "
      + ", ".join(f"{x:.2f}" for x in ratio_rt)
      + "; Python ndds TP / Rust ndds perf TP = " + ", ".join(f"{x:.2f}" for x in ratio_tp) + ".")
EOF

#!/usr/bin/env bash
# Two (or more) builds of ndds side by side, alternating, in one sitting: the per-sample
# figures that move when the data plane changes, all with both processes on CPU 0.
#
#   scripts/bench-ab.sh BIN_DIR_A BIN_DIR_B     (each a directory with ndds and ndds-daemon,
#                                               e.g. a worktree's target/release)
#
# Prints one line per build and round: samples/s received (2 s window, from 0.5 s after the
# first sample) for 64 B best-effort and reliable batched (--batch-us 1000 --batch-bytes
# 65000), 8 KiB best-effort and reliable, 1 MiB reliable; then round-trip p50 in µs for 64 B
# reliable and best effort and 8 KiB reliable. Environment: BENCH_ROUNDS (default 3).
# Each build gets its own daemon on loopback (--interface 127.0.0.1) and its own domain.
set -euo pipefail
[ $# -ge 1 ] || { sed -n 2,11p "$0"; exit 2; }
ROUNDS=${BENCH_ROUNDS:-3}
WORK=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; wait 2>/dev/null || true; rm -rf "$WORK"' EXIT

# Reliable flag for the side that takes no size or batching options.
reliable_of() { case "$*" in *--reliable*) echo --reliable ;; esac; }

throughput() {
    local bin=$1 sock=$2
    shift 2
    taskset -c 0 "$bin/ndds" --socket "$sock" perf sub --duration 2 --warmup 0.5 \
        $(reliable_of "$@") --json >"$WORK/sub.json" 2>&1 &
    local sub=$!
    sleep 0.3
    taskset -c 0 "$bin/ndds" --socket "$sock" perf pub --duration 4 "$@" --json >/dev/null 2>&1 || true
    wait "$sub" || true
    grep -o '"samples_per_s":[0-9]*' "$WORK/sub.json" | cut -d: -f2 || echo "-"
}

round_trip() {
    local bin=$1 sock=$2
    shift 2
    taskset -c 0 "$bin/ndds" --socket "$sock" perf pong $(reliable_of "$@") --duration 4 >/dev/null 2>&1 &
    local pong=$!
    sleep 0.3
    taskset -c 0 "$bin/ndds" --socket "$sock" perf ping --duration 2 --warmup 200 "$@" --json 2>/dev/null |
        grep -o '"p50_us":[0-9.]*' | cut -d: -f2 || echo "-"
    kill "$pong" 2>/dev/null || true
    wait "$pong" 2>/dev/null || true
}

i=0
for bin in "$@"; do
    i=$((i + 1))
    "$bin/ndds-daemon" --domain $((180 + i)) --socket "$WORK/d$i.sock" --interface 127.0.0.1 \
        >"$WORK/d$i.log" 2>&1 &
done
sleep 1
for round in $(seq "$ROUNDS"); do
    i=0
    for bin in "$@"; do
        i=$((i + 1))
        s=$WORK/d$i.sock
        echo "$bin round $round:" \
            "be64b $(throughput "$bin" "$s" --size 64 --batch-us 1000 --batch-bytes 65000)" \
            "rel64b $(throughput "$bin" "$s" --size 64 --reliable --batch-us 1000 --batch-bytes 65000)" \
            "be8k $(throughput "$bin" "$s" --size 8192)" \
            "rel8k $(throughput "$bin" "$s" --size 8192 --reliable)" \
            "rel1m $(throughput "$bin" "$s" --size 1048576 --reliable)" \
            "rtt_rel64 $(round_trip "$bin" "$s" --size 64 --reliable)" \
            "rtt_be64 $(round_trip "$bin" "$s" --size 64)" \
            "rtt_rel8k $(round_trip "$bin" "$s" --size 8192 --reliable)"
    done
done

#!/usr/bin/env bash
# Prints the "ControlShell runtime" section of docs/benchmarks.md (markdown on stdout):
# `ndds perf runtime` — the per-sample overhead of a list of 50 modules and the jitter of a
# 1 kHz timer habitat, idle, with the other core loaded, with both cores loaded, and with
# SCHED_FIFO (when run as root); and, beside the idle run, the same habitat while a
# configuration switch runs every 100 ms (its entering controller designs an LQR in
# `enable`). No network at all.
#
#   scripts/bench-runtime.sh            (scripts/bench.sh calls it)
#
# Environment: BENCH_RUNTIME_SECONDS (seconds per jitter run, default 10). Needs jq.
set -euo pipefail
cd "$(dirname "$0")/.."
SECS=${BENCH_RUNTIME_SECONDS:-10}
NDDS=target/release/ndds
[[ -x $NDDS ]] || cargo build --release -p ndds-cli >&2
WORK=$(mktemp -d /tmp/ndds-bench-runtime.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
CMDS=$WORK/commands.txt

say() { echo "bench-runtime: $*" >&2; }

# Runs one measurement; its JSON goes to $WORK/NAME.json, its command line to the list.
run() {
    local name=$1
    shift
    echo "target/release/ndds perf runtime $*" >>"$CMDS"
    say "$name: ndds perf runtime $*"
    "$NDDS" perf runtime --json "$@" >"$WORK/$name.json"
}

run idle --seconds "$SECS" --cpu 0
run other --jitter-only --switch-every 0 --seconds "$SECS" --cpu 0 --load 1 --load-cpu 1
run both --jitter-only --switch-every 0 --seconds "$SECS" --load 2
FIFO_NOTE="(not measured: SCHED_FIFO needs root)"
if [[ $(id -u) == 0 ]]; then
    run fifo --jitter-only --switch-every 0 --seconds "$SECS" --cpu 0 --load 2 --fifo 50
    FIFO_NOTE=""
fi

# The machine's own timer latency, as the baseline: cyclictest (rt-tests), one thread on
# CPU 0 at 1 kHz, installed with apt-get when missing and this runs as root.
if ! command -v cyclictest >/dev/null && [[ $(id -u) == 0 ]]; then
    apt-get install -y rt-tests >/dev/null 2>&1 || true
fi
# cyclictest p50 / p99 / max (µs) with extra arguments $2.., under $1 busy shell loops.
cyclic() {
    local busy=$1 pids=() out
    shift
    for ((i = 0; i < busy; i++)); do
        timeout $((SECS + 2)) sh -c 'while :; do :; done' &
        pids+=($!)
    done
    echo "cyclictest -a 0 -t 1 -i 1000 -D $SECS -q -h 20000 $*   # with $busy busy shell loop(s)" >>"$CMDS"
    out=$(cyclictest -a 0 -t 1 -i 1000 -D "$SECS" -q -h 20000 "$@" 2>/dev/null)
    kill "${pids[@]}" 2>/dev/null || true
    wait "${pids[@]}" 2>/dev/null || true
    echo "$out" | awk '/^[0-9]/ { v[n] = $1 + 0; c[n] = $2 + 0; t += $2; n++ }
        /Max Latencies/ { mx = $4 + 0 }
        END { for (k = 0; k < n; k++) { s += c[k]; if (p50 == "" && s >= t * 0.5) p50 = v[k]; if (p99 == "" && s >= t * 0.99) p99 = v[k] }
              printf "%s / %s / %s", p50, p99, mx }'
}
if command -v cyclictest >/dev/null; then
    say "cyclictest baselines"
    CT_IDLE=$(cyclic 0)
    CT_FIFO=$(cyclic 0 -p 50)
    CT_FIFO_LOADED=$(cyclic 2 -p 50)
else
    CT_IDLE="- (cyclictest missing)" CT_FIFO="-" CT_FIFO_LOADED="-"
fi

q() { jq -r "$2" "$WORK/$1.json"; }
f1() { awk -v x="$1" 'BEGIN { printf "%.1f", x }'; }

row() {
    local name=$1 label=$2
    [[ -f $WORK/$name.json ]] || { echo "| $label | - | - | - | - | - | - | - |"; return; }
    echo "| $label | $(q "$name" .jitter.samples) / $(q "$name" .jitter.expected_samples) | $(q "$name" .jitter.overruns) \
| $(f1 "$(q "$name" .jitter.latency_us.p50)") / $(f1 "$(q "$name" .jitter.latency_us.p99)") / $(f1 "$(q "$name" .jitter.latency_us.max)") \
| $(f1 "$(q "$name" .jitter.period_jitter_us.p50)") / $(f1 "$(q "$name" .jitter.period_jitter_us.p99)") / $(f1 "$(q "$name" .jitter.period_jitter_us.max)") \
| $(f1 "$(q "$name" .jitter.exec_us.p50)") / $(f1 "$(q "$name" .jitter.exec_us.p99)") |"
}

cat <<EOM
## The ControlShell runtime

Measured by \`scripts/bench-runtime.sh\` on the same machine, with no network: a habitat runs
a list of 50 modules. **Overhead** (manual habitat, $(q idle .overhead.nop.samples) samples timed
one by one on the calling thread):

| modules | per sample (mean) | per module (mean) | per sample p50 / p99 / max |
|---|---|---|---|
| 50 that do nothing (the runtime's own cost) | $(f1 "$(q idle .overhead.nop.mean_ns_per_sample)") ns | $(f1 "$(q idle .overhead.nop.mean_ns_per_module)") ns | $(q idle .overhead.nop.p50_ns) / $(q idle .overhead.nop.p99_ns) / $(q idle .overhead.nop.max_ns) ns |
| 50 1 × 1 gains in a chain (each reads its gain and input and writes its output, all owned by the habitat: no lock; two copies) | $(f1 "$(q idle .overhead.gain.mean_ns_per_sample)") ns | $(f1 "$(q idle .overhead.gain.mean_ns_per_module)") ns | $(q idle .overhead.gain.p50_ns) / $(q idle .overhead.gain.p99_ns) / $(q idle .overhead.gain.max_ns) ns |

**Jitter** of a 1 kHz timer habitat running the 50 gains for $SECS s (µs; *start latency*: how
late a sample started against its absolute deadline; *period jitter*: how far the interval
between two starts was from 1 ms; an overrun is a deadline skipped):

| load | samples / expected | overruns | start latency p50 / p99 / max | period jitter p50 / p99 / max | execution p50 / p99 |
|---|---|---|---|---|---|
$(row idle "idle, habitat on CPU 0")
$(row other "1 busy thread on CPU 1, habitat on CPU 0")
$(row both "2 busy threads, unpinned (both cores loaded)")
$(row fifo "2 busy threads, habitat on CPU 0 with SCHED_FIFO 50 $FIFO_NOTE")

**Switch under load**: the idle run's habitat again for $SECS s, with a configuration switch
every 100 ms between a 1 × 1 gain and a controller whose \`enable\` designs an LQR gain for a
24-state model ($(q idle .switching.designs) designs of $(f1 "$(q idle .switching.mean_design_ms)") ms each, run on the
switching thread while the habitat samples). Goal: start latency p99 within 2× of the run
without switches, no overrun caused by a switch.

| run | switches | samples | overruns | start latency p99 / max (µs) |
|---|---|---|---|---|
| without switches | 0 | $(q idle .jitter.samples) | $(q idle .jitter.overruns) | $(f1 "$(q idle .jitter.latency_us.p99)") / $(f1 "$(q idle .jitter.latency_us.max)") |
| a switch every 100 ms | $(q idle .switching.switches) | $(q idle .switching.samples) | $(q idle .switching.overruns) | $(f1 "$(q idle .switching.latency_us.p99)") / $(f1 "$(q idle .switching.latency_us.max)") |

p99 ratio, switching / not: $(awk -v x="$(q idle .switching.latency_p99_ratio_to_idle)" 'BEGIN { printf "%.2f", x }').

The machine's own timer latency for comparison (cyclictest, one thread on CPU 0 waking every
1 ms; p50 / p99 / max in µs; its normal-priority run keeps the default 50 µs timer slack, which
the habitats set to 1 ns):

| cyclictest | wake-up latency p50 / p99 / max |
|---|---|
| idle, normal priority | $CT_IDLE |
| idle, SCHED_FIFO 50 | $CT_FIFO |
| 2 busy threads, SCHED_FIFO 50 | $CT_FIFO_LOADED |

Steady-state sampling allocates nothing: \`ndds-runtime/tests/runtime_alloc.rs\` counts
allocations with a counting global allocator on the sampling thread (50 modules plus the
PD/LQG loop stepped 2000 times per configuration; a 1 kHz timer habitat for 1 s including ten
statistics hand-overs; CSMats published and received through topics for 1000 samples): 0.

Commands:

\`\`\`sh
$(cat "$CMDS")
\`\`\`
EOM

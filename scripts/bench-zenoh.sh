#!/usr/bin/env bash
# Reliable 64 B throughput, ndds against Zenoh, in one sitting (issue 15's goal: ndds reliable
# 64 B >= Zenoh's rate in the same run, 0 lost). Rounds alternate a Zenoh pair
# (scripts/zenoh-bench: peer mode, TCP on loopback, congestion control Block, its default
# batching) and an `ndds perf` pair (reliable, batched), with both processes on CPU 0 ("0")
# and with the publisher on CPU 0 and the subscriber on CPU 1 ("0/1").
#
#   scripts/bench-zenoh.sh              prints a Markdown section on stdout, progress on stderr
#
# Environment: BENCH_ROUNDS (rounds per placement, default 3), BENCH_SECONDS (measured seconds
# per run, default 2), ZENOH_TARGET (the Zenoh crate's target directory, default
# /work/zenoh-target; never the workspace's target/). Needs taskset.
# All traffic stays on 127.0.0.1: the ndds daemon runs on loopback (its default), the Zenoh
# subscriber listens on tcp/127.0.0.1:PORT only, the publisher listens nowhere and connects
# to it, and both have multicast and gossip scouting off.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SECS=${BENCH_SECONDS:-2}
ROUNDS=${BENCH_ROUNDS:-3}
ZENOH_TARGET=${ZENOH_TARGET:-/work/zenoh-target}
WORK=$(mktemp -d /tmp/ndds-bench-zenoh.XXXXXX)
NDDS=$ROOT/target/release/ndds
DAEMON=$ROOT/target/release/ndds-daemon
ZB=$ZENOH_TARGET/release/zenoh-bench
SOCK=$WORK/ndds.sock
DOMAIN=$((150 + $$ % 80))
PORT=$((40000 + $$ % 20000))
CMDS=$WORK/commands.txt
RESULTS=$WORK/results.txt
LIMIT="timeout $((SECS + 20))"
: >"$RESULTS"

cleanup() {
    [[ -n ${DAEMON_PID:-} ]] && kill "$DAEMON_PID" 2>/dev/null || true
    wait 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT

say() { echo "bench-zenoh: $*" >&2; }

# ---------------------------------------------------------------------------- set-up

say "building the Zenoh pair (scripts/zenoh-bench, target $ZENOH_TARGET)"
(cd scripts/zenoh-bench && CARGO_TARGET_DIR=$ZENOH_TARGET nice -n 19 cargo build --release --locked) >&2
say "building release binaries"
cargo build --release --locked -p ndds-cli -p ndds-daemon >&2
ZENOH_VERSION=$(awk '$0 == "name = \"zenoh\"" { getline; gsub(/[^0-9.]/, ""); print; exit }' \
    scripts/zenoh-bench/Cargo.lock)

say "starting ndds-daemon on loopback (domain $DOMAIN)"
"$DAEMON" --domain "$DOMAIN" --socket "$SOCK" >"$WORK/daemon.log" 2>&1 &
DAEMON_PID=$!
for _ in $(seq 100); do [[ -S $SOCK ]] && break; sleep 0.05; done
[[ -S $SOCK ]] || { cat "$WORK/daemon.log" >&2; exit 1; }
P="$NDDS --socket $SOCK perf"

# ---------------------------------------------------------------------------- helpers

# The CPU prefix of one side: placement "0" puts both on CPU 0, "0/1" the publisher (a) on 0
# and the subscriber (b) on 1.
pin() {
    case "$1/$2" in
    0/1/b) echo "taskset -c 1" ;;
    *) echo "taskset -c 0" ;;
    esac
}

# Runs the subscriber SUB in the background, then the publisher PUB 0.3 s later; leaves the
# subscriber's output in FILE. Both are bounded by their own duration and by `timeout`.
pair() {
    local placement=$1 file=$2 sub=$3 pub=$4
    local pb pa
    pb=$(pin "$placement" b)
    pa=$(pin "$placement" a)
    printf '%s %s &\n%s %s\n\n' "$pb" "$sub" "$pa" "$pub" |
        sed "s#$WORK#\$WORK#g; s#$ZENOH_TARGET#\$ZENOH_TARGET#g; s#$ROOT/##g" | tr -s ' ' >>"$CMDS"
    # shellcheck disable=SC2086
    $LIMIT $pb $sub >"$file" 2>"$file.err" &
    local spid=$!
    sleep 0.3
    # shellcheck disable=SC2086
    $LIMIT $pa $pub >"$file.pub" 2>"$file.pub.err" || say "failed: $pub ($(tail -1 "$file.pub.err"))"
    wait "$spid" || say "failed: $sub ($(tail -1 "$file.err"))"
    PORT=$((PORT + 1))
}

# A number field of the one-line JSON report in FILE, with DIGITS decimals (default 0).
jget() {
    grep -o "\"$2\":[^,}]*" "$1" 2>/dev/null | head -1 | cut -d: -f2 | tr -d '"' |
        awk -v d="${3:-0}" '{ printf "%.*f\n", d, $1 }' || true
}

# Records one run: tool placement round samples/s lost loss% (a failed run's fields are "-").
record() {
    local tool=$1 placement=$2 round=$3 file=$4 rate lost loss
    rate=$(jget "$file" samples_per_s)
    lost=$(jget "$file" lost)
    loss=$(jget "$file" loss_pct 2)
    echo "$tool $placement $round ${rate:--} ${lost:--} ${loss:--}" >>"$RESULTS"
    say "  $tool: ${rate:--} samples/s, ${lost:--} lost"
}

run_zenoh() {
    local placement=$1 round=$2 f
    f=$WORK/zenoh-${placement//\//_}-$round
    pair "$placement" "$f" "$ZB sub --port $PORT --duration $SECS --warmup 0.5 --json" \
        "$ZB pub --port $PORT --size 64 --duration $((SECS + 3)) --json"
    record zenoh "$placement" "$round" "$f"
}

run_ndds() {
    local placement=$1 round=$2 f
    f=$WORK/ndds-${placement//\//_}-$round
    pair "$placement" "$f" "$P sub --duration $SECS --warmup 0.5 --reliable --json" \
        "$P pub --size 64 --duration $((SECS + 3)) --reliable --batch-us 1000 --batch-bytes 65000 --json"
    record ndds "$placement" "$round" "$f"
}

# ---------------------------------------------------------------------------- the runs

START=$(date +%s)
for placement in 0 0/1; do
    for round in $(seq "$ROUNDS"); do
        say "CPUs $placement, round $round of $ROUNDS"
        run_zenoh "$placement" "$round"
        run_ndds "$placement" "$round"
    done
done
ELAPSED=$(($(date +%s) - START))
say "measured in ${ELAPSED} s"

# ---------------------------------------------------------------------------- the report

# Field N (4: samples/s, 5: lost, 6: loss %) of TOOL's run in PLACEMENT, round ROUND.
get() { awk -v t="$1" -v p="$2" -v r="$3" -v n="$4" '$1 == t && $2 == p && $3 == r { print $n; exit }' "$RESULTS"; }

# The median of TOOL's samples/s in PLACEMENT ("-" when a run failed).
median() {
    awk -v t="$1" -v p="$2" '$1 == t && $2 == p { if ($4 == "-") bad = 1; v[n++] = $4 + 0 }
        END { if (n == 0 || bad) { print "-"; exit }
              for (i = 0; i < n; i++) for (j = i + 1; j < n; j++) if (v[j] < v[i]) { k = v[i]; v[i] = v[j]; v[j] = k }
              printf "%.0f\n", (n % 2) ? v[(n - 1) / 2] : (v[n / 2 - 1] + v[n / 2]) / 2 }' "$RESULTS"
}

# The samples TOOL lost over all rounds in PLACEMENT ("-" when a run failed).
lost_sum() {
    awk -v t="$1" -v p="$2" '$1 == t && $2 == p { if ($5 == "-") bad = 1; s += $5 }
        END { print bad ? "-" : s + 0 }' "$RESULTS"
}

ratio() { awk -v a="$1" -v b="$2" 'BEGIN { if (a == "-" || b == "-" || b == 0) print "-"; else printf "%.2f", a / b }'; }

placement_table() {
    local placement=$1 round nd zn r met
    echo "| round | zenoh samples/s | zenoh lost | ndds samples/s | ndds lost |"
    echo "|---|---|---|---|---|"
    for round in $(seq "$ROUNDS"); do
        echo "| $round | $(get zenoh "$placement" "$round" 4) | $(get zenoh "$placement" "$round" 5) |" \
            "$(get ndds "$placement" "$round" 4) | $(get ndds "$placement" "$round" 5) |"
    done
    zn=$(median zenoh "$placement")
    nd=$(median ndds "$placement")
    echo "| median (lost: sum) | $zn | $(lost_sum zenoh "$placement") | $nd | $(lost_sum ndds "$placement") |"
    r=$(ratio "$nd" "$zn")
    met=$(awk -v r="$r" -v l="$(lost_sum ndds "$placement")" 'BEGIN {
        if (r == "-" || l == "-") print "-"; else if (r >= 1 && l == 0) print "yes"; else print "**no**" }')
    echo
    echo "ndds / zenoh (medians): **$r**; goal >= 1 with 0 lost: $met"
}

cat <<EOF
## Reliable 64 B: ndds against Zenoh

Samples per second received in a ${SECS} s steady window (from 0.5 s after the first sample;
the publisher writes flat out), rounds per placement: ${ROUNDS}, Zenoh and ndds alternating,
measured in one sitting by \`scripts/bench-zenoh.sh\` ($(date -u '+%Y-%m-%d %H:%M UTC'), ${ELAPSED} s).
Lost: sequence numbers that never arrived in the window.

- Zenoh: zenoh $ZENOH_VERSION from crates.io (TCP transport only), \`scripts/zenoh-bench\`: peer
  mode, multicast and gossip scouting off, the subscriber listening on tcp/127.0.0.1 and the
  publisher connected to it; reliable, congestion control Block, default batching; 64 B
  payloads whose first 8 bytes are the sequence number (a callback subscriber counts them).
- ndds: \`ndds perf pub/sub --reliable\`, batched (\`--batch-us 1000 --batch-bytes 65000\`),
  through one \`ndds-daemon\` on loopback; ndds \`$(git rev-parse --short HEAD 2>/dev/null || echo unknown)$(git diff --quiet HEAD -- ndds-core ndds-client ndds-cli ndds-daemon 2>/dev/null || echo " + uncommitted changes")\`.
- CPUs: \`0\` runs both processes on CPU 0, \`0/1\` the publisher on CPU 0 and the subscriber on
  CPU 1 (\`taskset\`).

### CPUs 0

$(placement_table 0)

### CPUs 0/1

$(placement_table 0/1)

### Commands

Run from the repository root, with \`WORK\` a temporary directory, \`ZENOH_TARGET\` the Zenoh
crate's target directory (built by \`cd scripts/zenoh-bench && CARGO_TARGET_DIR=\$ZENOH_TARGET cargo build --release --locked\`)
and a daemon started as \`target/release/ndds-daemon --domain $DOMAIN --socket \$WORK/ndds.sock &\`.
Each pair below is one run (the first line's process starts 0.3 s earlier):

\`\`\`sh
$(cat "$CMDS")
\`\`\`
EOF

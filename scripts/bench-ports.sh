#!/usr/bin/env bash
# Prints the "Ports" section of docs/benchmarks.md (markdown on stdout): round trips of a
# port's send/receive/reply and of query/response between two processes on loopback, beside
# the plain pub/sub round trip of `ndds perf ping` measured in the same run. One daemon on
# loopback (its default interface); release build.
#
#   scripts/bench-ports.sh            (scripts/bench.sh calls it)
#
# Environment: BENCH_PORT_COUNT (round trips per run, default 5000), BENCH_PORT_ROUNDS
# (loosely against tightly coupled rounds, default 3), BENCH_PORT_SPIN_US (the tight port's
# busy-wait, default 200). Needs jq.
set -euo pipefail
cd "$(dirname "$0")/.."
COUNT=${BENCH_PORT_COUNT:-5000}
ROUNDS=${BENCH_PORT_ROUNDS:-3}
SPIN_US=${BENCH_PORT_SPIN_US:-200}
[[ -x target/release/ndds && -x target/release/ndds-daemon ]] ||
    cargo build --release -p ndds-cli -p ndds-daemon >&2
WORK=$(mktemp -d /tmp/ndds-bench-ports.XXXXXX)
DOMAIN=$((150 + $$ % 80))
target/release/ndds-daemon --domain "$DOMAIN" --socket "$WORK/ndds.sock" >"$WORK/daemon.log" 2>&1 &
DAEMON=$!
trap 'kill $DAEMON 2>/dev/null || true; rm -rf "$WORK"' EXIT
sleep 0.5
N="target/release/ndds --socket $WORK/ndds.sock"
CMDS=$WORK/commands.txt

# Runs a server ($1, in the background) and a client ($2); the client's JSON goes to $3.
pair() {
    echo "$1 &" >>"$CMDS"
    echo "$2" >>"$CMDS"
    $1 >/dev/null 2>&1 &
    local server=$!
    sleep 0.5
    $2 >"$WORK/$3.json"
    kill "$server" 2>/dev/null || true
    wait "$server" 2>/dev/null || true
}

pair "$N perf port --serve --seconds 60" "$N perf port --count $COUNT --json" send
pair "$N perf port --serve --query --seconds 60" "$N perf port --query --count $COUNT --json" query
pair "$N perf pong --duration 60" "$N perf ping --size 64 --count $COUNT --json" pubsub
# Loosely against tightly coupled (busy-waiting $SPIN_US us), alternating, $ROUNDS rounds.
for r in $(seq 1 "$ROUNDS"); do
    pair "$N perf port --serve --port ndds.loose --seconds 60" \
        "$N perf port --port ndds.loose --count $COUNT --json" "loose$r"
    pair "$N perf port --serve --port ndds.tight --tight $SPIN_US --seconds 60" \
        "$N perf port --port ndds.tight --count $COUNT --json" "tight$r"
done

q() { jq -r "$2" "$WORK/$1.json"; }
f1() { awk -v x="$1" 'BEGIN { printf "%.1f", x }'; }
# The median over the rounds of field $2 of runs $1<round>.
median() {
    for r in $(seq 1 "$ROUNDS"); do q "$1$r" "$2"; done | sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'
}
each() {
    for r in $(seq 1 "$ROUNDS"); do f1 "$(q "$1$r" "$2")"; echo; done | paste -sd, | sed 's/,/, /g'
}
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a / b }'; }
row() {
    echo "| $2 | $(f1 "$(q "$1" .p50_us)") | $(f1 "$(q "$1" .p90_us)") | $(f1 "$(q "$1" .p99_us)") | $(f1 "$(q "$1" .max_us)") |"
}

cat <<EOM
## Ports

Round trips between two processes under one daemon on loopback, $COUNT each, measured by
\`scripts/bench-ports.sh\` in one run (µs):

| exchange | p50 | p90 | p99 | max |
|---|---|---|---|---|
$(row send "port send / receive / reply")
$(row query "port query / response handler")
$(row pubsub "pub/sub ping / pong, 64 B (\`ndds perf ping\`)")

Loosely against tightly coupled ports (\`ndds perf port --serve --tight $SPIN_US\`: the owner's
\`receive\` and the user's \`send\` busy-wait up to $SPIN_US µs before they park), alternating,
$ROUNDS rounds of $COUNT round trips (µs; each round's value, then the medians' ratio):

| percentile | loose | tight | tight / loose |
|---|---|---|---|
| p50 | $(each loose .p50_us) | $(each tight .p50_us) | $(ratio "$(median tight .p50_us)" "$(median loose .p50_us)") |
| p90 | $(each loose .p90_us) | $(each tight .p90_us) | $(ratio "$(median tight .p90_us)" "$(median loose .p90_us)") |
| p99 | $(each loose .p99_us) | $(each tight .p99_us) | $(ratio "$(median tight .p99_us)" "$(median loose .p99_us)") |

A port round trip is two reliable streams (request, reply) handled on application threads:
the owner's \`receive\` and the user's wait for the reply each take a sample from a consumer
queue, where \`ndds perf ping\` answers from the receive thread itself (a direct consumer).

Commands (\`N\` = \`target/release/ndds --socket \$WORK/ndds.sock\`, a daemon started as
\`target/release/ndds-daemon --domain $DOMAIN --socket \$WORK/ndds.sock\`):

\`\`\`sh
$(sed "s#target/release/ndds --socket $WORK/ndds.sock#\$N#g" "$CMDS")
\`\`\`
EOM

#!/usr/bin/env bash
# Reliable throughput with and without 10 % loss between two simulated hosts: two network
# namespaces joined by a veth pair (MTU 1500), an ndds-daemon in each on its veth address,
# `ndds perf pub --reliable` on host A and `ndds perf sub --reliable` on host B, and nftables
# on host B dropping 10 % of the UDP datagrams arriving from A. Prints a Markdown section
# (goal rows, table, commands) on stdout; progress on stderr. Called by scripts/bench.sh;
# needs root, `ip` and `nft`, and the release binaries.
#
#   scripts/bench-loss.sh
#
# Environment: BENCH_SECONDS (measured seconds per run, default 2); BENCH_BIN (directory of
# the ndds and ndds-daemon binaries to measure, default target/release); BENCH_CONFIGS (the
# runs, as SIZE:BATCHING pairs, default "64:1000/65000 1024:off 8192:off").
# All traffic stays inside the two namespaces.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SECS=${BENCH_SECONDS:-2}
BIN=${BENCH_BIN:-$ROOT/target/release}
NDDS=$BIN/ndds
DAEMON=$BIN/ndds-daemon
TAG=$$
NS_A=ndds-bl-a-$TAG
NS_B=ndds-bl-b-$TAG
IP_A=10.213.0.1
IP_B=10.213.0.2
DOMAIN=$((150 + TAG % 80))
WORK=$(mktemp -d /tmp/ndds-bench-loss.XXXXXX)
RESULTS=$WORK/results.txt
CMDS=$WORK/commands.txt
LIMIT="timeout 60"

say() { echo "bench-loss: $*" >&2; }

cleanup() {
    for pid in ${PIDS:-}; do kill "$pid" 2>/dev/null || true; done
    wait 2>/dev/null || true
    ip netns del "$NS_A" 2>/dev/null || true
    ip netns del "$NS_B" 2>/dev/null || true
    [[ -n ${BENCH_KEEP:-} ]] && say "kept $WORK" || rm -rf "$WORK"
}
trap cleanup EXIT

[[ $(id -u) == 0 ]] || { say "needs root (network namespaces)"; exit 1; }
command -v nft >/dev/null || { say "needs nft"; exit 1; }

say "hosts $NS_A ($IP_A) and $NS_B ($IP_B)"
ip netns add "$NS_A"
ip netns add "$NS_B"
ip link add "bl-a-$TAG" type veth peer name "bl-b-$TAG"
ip link set "bl-a-$TAG" netns "$NS_A"
ip link set "bl-b-$TAG" netns "$NS_B"
ip -n "$NS_A" addr add "$IP_A/24" dev "bl-a-$TAG"
ip -n "$NS_B" addr add "$IP_B/24" dev "bl-b-$TAG"
for ns in "$NS_A" "$NS_B"; do ip -n "$ns" link set lo up; done
ip -n "$NS_A" link set "bl-a-$TAG" up
ip -n "$NS_B" link set "bl-b-$TAG" up

ip netns exec "$NS_A" "$DAEMON" --domain "$DOMAIN" --socket "$WORK/a.sock" --interface "$IP_A" \
    >"$WORK/daemon-a.log" 2>&1 &
PIDS="$!"
ip netns exec "$NS_B" "$DAEMON" --domain "$DOMAIN" --socket "$WORK/b.sock" --interface "$IP_B" \
    >"$WORK/daemon-b.log" 2>&1 &
PIDS="$PIDS $!"
for _ in $(seq 100); do [[ -S $WORK/a.sock && -S $WORK/b.sock ]] && break; sleep 0.05; done

# Drops LOSS % of the UDP datagrams reaching host B from host A (0: none).
set_loss() {
    ip netns exec "$NS_B" nft -f - <<EOF
add table inet ndds_bench
delete table inet ndds_bench
EOF
    [[ $1 == 0 ]] && return
    ip netns exec "$NS_B" nft -f - <<EOF
table inet ndds_bench {
  chain input {
    type filter hook input priority filter; policy accept;
    iifname "bl-b-$TAG" ip saddr $IP_A meta l4proto udp numgen random mod 100 < $1 counter drop
  }
}
EOF
}

jget() {
    grep -o "\"$2\":[^,}]*" "$1" 2>/dev/null | head -1 | cut -d: -f2 | tr -d '"' |
        awk -v d="${3:-1}" '{ printf "%.*f\n", d, $1 }' || true
}

# One reliable pub/sub run: SIZE, BATCH ("off" or "US/BYTES"), LOSS percent.
run() {
    local size=$1 batch=$2 loss=$3 batching="" f
    f=$WORK/run-$size-${batch//\//_}-$loss
    [[ $batch != off ]] && batching="--batch-us ${batch%/*} --batch-bytes ${batch#*/}"
    set_loss "$loss"
    local sub="ip netns exec $NS_B $NDDS --socket $WORK/b.sock perf sub --reliable --duration $SECS --warmup 0.5 --json"
    local pub="ip netns exec $NS_A $NDDS --socket $WORK/a.sock perf pub --reliable --size $size --duration $((SECS + 3)) $batching --json"
    printf '# %s %% loss at host B\n%s &\n%s\n\n' "$loss" "$sub" "$pub" | sed "s#$WORK#\$WORK#g; s#$ROOT/##g" >>"$CMDS"
    # shellcheck disable=SC2086
    $LIMIT $sub >"$f.b" 2>"$f.b.err" &
    local spid=$!
    sleep 0.5
    # shellcheck disable=SC2086
    $LIMIT $pub >"$f.a" 2>"$f.a.err" || say "failed: $pub ($(tail -1 "$f.a.err"))"
    wait "$spid" || say "failed: $sub ($(tail -1 "$f.b.err"))"
    local dropped
    dropped=$({ ip netns exec "$NS_B" nft list table inet ndds_bench 2>/dev/null || true; } |
        { grep -o 'packets [0-9]*' || true; } | awk '{ s += $2 } END { print s + 0 }')
    echo "$size $batch $loss $(jget "$f.b" samples_per_s 0) $(jget "$f.b" mb_per_s) $(jget "$f.b" loss_pct 2) $(jget "$f.b" samples 0) $dropped" >>"$RESULTS"
    say "$size B, batching $batch, $loss % loss: $(jget "$f.b" samples_per_s 0) samples/s"
}

CONFIGS=${BENCH_CONFIGS:-"64:1000/65000 1024:off 8192:off"}
for config in $CONFIGS; do
    for loss in 0 10; do
        run "${config%%:*}" "${config#*:}" "$loss"
    done
done
set_loss 0

get() { awk -v k="$1 $2 $3" -v n="$4" '$1" "$2" "$3 == k { print $(3 + n); exit }' "$RESULTS"; }
human() { awk -v s="$1" 'BEGIN { if (s >= 1024) printf "%d KiB", s / 1024; else printf "%d B", s }'; }

echo "## Reliable stream through 10 % loss (two simulated hosts)"
echo
echo "Two network namespaces joined by a veth pair (MTU 1500, so datagrams of at most 1472"
echo "bytes: an 8 KiB sample travels as 6 fragments, and a batch holds about 19 samples of"
echo "64 B); a daemon in each; \`ndds perf pub --reliable\` on host A, \`ndds perf sub"
echo "--reliable\` on host B (history depth 1024 on both sides), and nftables on host B dropping"
echo "10 % of the UDP datagrams from A, each independently (data and heartbeats; B's"
echo "acknowledgements to A are not dropped). Reproduce with \`scripts/bench-loss.sh\` (root)."
echo
echo "| size | batching | samples/s, no loss | samples/s, 10 % loss | ratio | goal | met | loss % seen by sub | datagrams dropped |"
echo "|---|---|---|---|---|---|---|---|---|"
for config in $CONFIGS; do
    size=${config%%:*}
    batch=${config#*:}
    clean=$(get "$size" "$batch" 0 1)
    lossy=$(get "$size" "$batch" 10 1)
    lost=$(get "$size" "$batch" 10 3)
    dropped=$(get "$size" "$batch" 10 5)
    ratio=$(awk -v a="$lossy" -v b="$clean" 'BEGIN { if (b == "" || b == 0 || a == "") print "-"; else printf "%.2f", a / b }')
    met=$(awk -v r="$ratio" -v l="$lost" 'BEGIN { if (r == "-") print "-"; else if (r >= 0.7 && l == 0) print "yes"; else print "**no**" }')
    echo "| $(human "$size") | $batch | $clean | $lossy | $ratio | >= 0.70, 0 lost | $met | $lost | $dropped |"
done
echo
echo "Commands (\`WORK\` a temporary directory; the daemons run as"
echo "\`ip netns exec HOST target/release/ndds-daemon --domain $DOMAIN --socket \$WORK/HOST.sock --interface ADDRESS\`):"
echo
echo '```sh'
cat "$CMDS"
echo '```'

#!/usr/bin/env bash
# Sealed against open domains, one sitting (docs/benchmarks.md, "Sealed against open domains").
#
#   scripts/bench-sealed.sh            ROUNDS rounds (default 3) on CPUS (default 0)
#
# Environment: ROUNDS, CPUS (a taskset list: 0, or 0,1), CIPHERS (default
# "aegis-128l aes-128-gcm aes-256-gcm chacha20-poly1305"). Builds nothing: run `cargo build --release -p
# ndds-cli -p ndds-daemon` first, and nothing else meanwhile. One daemon per domain (open, and
# one per cipher), all on 127.0.0.1; in each round every domain in turn: 8 KiB best-effort
# throughput, 64 B batched throughput (--batch-us 1000 --batch-bytes 65000) and the 64 B round
# trip p50, through `ndds perf`. Prints one line per measurement: round, domain, what, value.
set -euo pipefail
cd "$(dirname "$0")/.."

bin=target/release
rounds=${ROUNDS:-3}
cpus=${CPUS:-0}
ciphers=${CIPHERS:-aegis-128l aes-128-gcm aes-256-gcm chacha20-poly1305}
[[ -x $bin/ndds && -x $bin/ndds-daemon ]] || {
    echo "build first: cargo build --release -p ndds-cli -p ndds-daemon" >&2
    exit 2
}

work=$(mktemp -d)
daemons=()
cleanup() {
    for pid in "${daemons[@]}"; do kill "$pid" 2>/dev/null || true; done
    wait 2>/dev/null || true
    rm -rf "$work"
}
trap cleanup EXIT

# Domains 211.. (open first), each with its own daemon and socket.
names=(open)
domain=211
start_daemon() {
    local name=$1 key=${2:-}
    local args=(--domain "$domain" --socket "$work/$name.sock" --interface 127.0.0.1)
    [[ -n $key ]] && args+=(--key-file "$key")
    "$bin/ndds-daemon" "${args[@]}" >"$work/$name.log" 2>&1 &
    daemons+=($!)
    domain=$((domain + 1))
}
start_daemon open
for cipher in $ciphers; do
    "$bin/ndds" key new "$work/$cipher.key" --cipher "$cipher" >/dev/null
    start_daemon "$cipher" "$work/$cipher.key"
    names+=("$cipher")
done
sleep 1

field() {
    python3 -c "import json,sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])" "$1" "$2"
}

measure() {
    local round=$1 name=$2
    local env=(NDDS_SOCKET="$work/$name.sock")
    [[ $name != open ]] && env+=(NDDS_KEY_FILE="$work/$name.key")
    local run=(env "${env[@]}" taskset -c "$cpus" "$bin/ndds" perf)
    local sub
    "${run[@]}" sub --duration 2 --warmup 0.5 --json >"$work/sub.json" &
    sub=$!
    "${run[@]}" pub --size 8192 --duration 5 --json >/dev/null
    wait "$sub"
    echo "$round $name 8KiB_samples_per_s $(field "$work/sub.json" samples_per_s)"
    "${run[@]}" sub --duration 2 --warmup 0.5 --json >"$work/sub.json" &
    sub=$!
    "${run[@]}" pub --size 64 --duration 5 --batch-us 1000 --batch-bytes 65000 --json >/dev/null
    wait "$sub"
    echo "$round $name 64B_batched_samples_per_s $(field "$work/sub.json" samples_per_s)"
    "${run[@]}" pong --duration 60 >/dev/null &
    local pong=$!
    "${run[@]}" ping --size 64 --duration 2 --warmup 200 --json >"$work/ping.json"
    kill "$pong" 2>/dev/null || true
    wait "$pong" 2>/dev/null || true
    echo "$round $name 64B_rtt_p50_us $(field "$work/ping.json" p50_us)"
}

for round in $(seq 1 "$rounds"); do
    for name in "${names[@]}"; do
        measure "$round" "$name"
    done
done

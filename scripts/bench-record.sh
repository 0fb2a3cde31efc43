#!/usr/bin/env bash
# Recording throughput against the disk, one sitting (docs/benchmarks.md, "Recording").
#
#   scripts/bench-record.sh [DIR]        DIR: where files go (default: a new directory in
#                                        target/, on the disk the repository is on)
#
# Builds nothing: run `cargo build --release -p ndds-cli -p ndds-daemon` first (or name another
# directory of those two binaries in NDDS_BIN), and nothing
# else meanwhile. SECONDS_PER_RUN (default 5) sets how long each publisher runs: a run longer
# than the page cache absorbs (15 s here) measures what the disk sustains. One daemon on 127.0.0.1. Prints one line per measurement:
#   dd MB/s; for 8 KiB and 1 MiB samples published flat out: the recorder's MB/s, its drops,
#   its peak memory; the same at half of dd's rate; 64 B samples at 200 000/s (batched); and
#   `ndds play` of each recording: its rate against the recorded one.
set -euo pipefail
cd "$(dirname "$0")/.."

bin=${NDDS_BIN:-target/release}
[[ -x $bin/ndds && -x $bin/ndds-daemon ]] || {
    echo "build first: cargo build --release -p ndds-cli -p ndds-daemon" >&2
    exit 2
}
dir=${1:-target/bench-record}
rm -rf "$dir"
mkdir -p "$dir"
seconds=${SECONDS_PER_RUN:-5}
# Long runs write several GiB per recording (each is removed once measured): check the room.
free=$(df --output=avail -B1 "$dir" | tail -1)
need=$((seconds * 800 * 1000 * 1000))
if (( free < need )); then
    echo "$dir has $((free >> 30)) GiB free; SECONDS_PER_RUN=$seconds needs about $((need >> 30)) GiB" >&2
    exit 2
fi

"$bin/ndds-daemon" --domain 219 --socket "$dir/d.sock" --interface 127.0.0.1 >"$dir/daemon.log" 2>&1 &
daemon=$!
trap 'kill $daemon 2>/dev/null || true; rm -f "$dir"/*.mcap "$dir"/dd.bin' EXIT
sleep 1
export NDDS_SOCKET=$dir/d.sock

field() {
    python3 -c "import json,sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])" "$1" "$2"
}

# The disk: written sequentially and flushed, as much as a flat-out recording writes in a run
# (2 GiB per 5 s): a shorter burst measures the VM's write cache rather than the disk.
dd_mib=$((2048 * (seconds > 5 ? seconds : 5) / 5))
dd_out=$(dd if=/dev/zero of="$dir/dd.bin" bs=1M count="$dd_mib" conv=fdatasync 2>&1 | tail -1)
rm -f "$dir/dd.bin"
dd_bytes_s=$(python3 -c "
import re,sys
m = re.search(r'([0-9.]+) s, ', sys.argv[1])
print(int(int(sys.argv[2]) * 1048576 / float(m.group(1))))" "$dd_out" "$dd_mib")
echo "dd MiB $dd_mib"
echo "dd MB/s $((dd_bytes_s / 1000000))"

# One recording: SIZE bytes at RATE (or max) for $seconds s, into a file; prints MB/s, drops,
# peak resident memory of the recorder, and the play rate against the recorded one.
record() {
    local name=$1 size=$2 rate=$3 extra=${4:-}
    local file="$dir/$name.mcap"
    rm -f "$file"
    "$bin/ndds" record ndds/perf/data -o "$file" --compression none --summary-json \
        >"$dir/$name.json" 2>"$dir/$name.err" &
    local rec=$!
    sleep 1
    # shellcheck disable=SC2086
    "$bin/ndds" perf pub --size "$size" --rate "$rate" --duration "$seconds" $extra \
        --json >"$dir/$name.pub.json"
    sleep 1
    local peak
    peak=$(awk '/VmHWM/ {print $2}' "/proc/$rec/status")
    # The recorder's finish (its last chunk, the summary, and a sync of the file to the disk)
    # is timed too: dd's figure includes its final fdatasync.
    local stopping=$EPOCHREALTIME
    kill -INT "$rec"
    wait "$rec" || true
    local finish
    finish=$(python3 -c "import sys; print(float(sys.argv[2]) - float(sys.argv[1]))" "$stopping" "$EPOCHREALTIME")
    python3 - "$dir/$name.json" "$dir/$name.pub.json" "$name" "$peak" "$finish" <<'EOF'
import json, sys
summary = json.load(open(sys.argv[1]))
pub = json.load(open(sys.argv[2]))
name, peak, finish = sys.argv[3], int(sys.argv[4]), float(sys.argv[5])
topic = summary["topics"][0] if summary["topics"] else {"messages": 0, "bytes": 0,
                                                         "lost_gaps": 0, "lost_overflow": 0}
sent = pub["written"]
window = pub["elapsed_s"] or 1
print(f"{name} sent {sent} recorded {topic['messages']} lost {summary['lost']} "
      f"(gaps {topic['lost_gaps']}, overflow {topic['lost_overflow']}) "
      f"MB/s {topic['bytes'] / window / 1e6:.1f} "
      f"with_finish {topic['bytes'] / (window + 1 + finish) / 1e6:.1f} (finish {finish:.2f} s) "
      f"recorder_peak_MiB {peak / 1024:.1f}")
EOF
    "$bin/ndds" play "$file" --delay 0.2 --json >"$dir/$name.play.json"
    python3 - "$dir/$name.play.json" "$file" "$bin/ndds" "$name" <<'EOF'
import json, subprocess, sys
play = json.load(open(sys.argv[1]))
info = json.loads(subprocess.run([sys.argv[3], "bag", "info", "--json", sys.argv[2]],
                                 capture_output=True, check=True).stdout)[0]
recorded = info["messages"] / max(info["duration_s"], 1e-9)
played = play["published"] / max(play["seconds"] - 0.2, 1e-9)
print(f"{sys.argv[4]} play msgs/s {played:.0f} recorded msgs/s {recorded:.0f} "
      f"ratio {played / recorded:.3f}")
EOF
    rm -f "$file"
}

record 8k_max 8192 max
record 1m_max 1048576 max
half_8k=$((dd_bytes_s / 2 / 8192))
half_1m=$((dd_bytes_s / 2 / 1048576))
record 8k_half_dd 8192 "$half_8k"
record 1m_half_dd 1048576 "$half_1m"
record 64b_200k 64 200000 "--batch-us 1000 --batch-bytes 65000"

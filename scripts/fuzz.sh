#!/usr/bin/env bash
# Coverage-guided fuzzing of ndds's decoders and protocol engines with AFL++ (cargo-afl, stable
# toolchain). See docs/fuzzing.md.
#
#   scripts/fuzz.sh build                  build every target (cargo afl build --release)
#   scripts/fuzz.sh list                   name the targets
#   scripts/fuzz.sh run TARGET SECONDS     fuzz one target; exits 1 if it saved a crash
#   scripts/fuzz.sh ci [SECONDS]           install what is missing, build, run every target
#                                          SECONDS each (default 10)
#   scripts/fuzz.sh replay [TARGET]        run the corpus and saved crashes without AFL++
#   scripts/fuzz.sh minimize TARGET        shrink a run's queue into the seed corpus (afl-cmin)
#
# Each run starts from fuzz/corpus/TARGET and writes to target/fuzz-out/TARGET (its queue,
# crashes/, hangs/ and fuzzer_stats); the corpus itself is never written to. Runs as root in a
# clean clone; nothing here uses the network except apt-get and cargo install when a tool is
# missing.
set -euo pipefail
cd "$(dirname "$0")/.."

root=$(pwd)
fuzz_dir=$root/fuzz
out_root=$root/target/fuzz-out
bin_dir=$fuzz_dir/target/release

export AFL_NO_UI=1
export AFL_SKIP_CPUFREQ=1
export AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1
# Another build or test may be using the cores: do not pin to one.
export AFL_NO_AFFINITY=1
export AFL_QUIET=1

targets() {
    ls "$fuzz_dir/corpus"
}

# cargo-afl builds AFL++ from source when it is installed (a C compiler and make are enough;
# the optional LLVM plugins are not used). `cargo afl config --build` does it again for a new
# toolchain, and says so when it is already done.
install_tools() {
    if ! command -v cc >/dev/null || ! command -v make >/dev/null; then
        apt-get update && apt-get install -y build-essential
    fi
    if ! cargo afl --version >/dev/null 2>&1; then
        cargo install cargo-afl --locked
    fi
    local log
    log=$(mktemp)
    if ! cargo afl config --build >"$log" 2>&1; then
        if ! grep -q 'already built' "$log"; then
            cat "$log" >&2
            rm -f "$log"
            return 1
        fi
    fi
    rm -f "$log"
}

build() {
    (cd "$fuzz_dir" && cargo afl build --release --locked --bins)
}

# Prints one line of a run's fuzzer_stats: name value.
stat() {
    awk -v key="$2" -F' *: *' '$1 == key { print $2 }' "$1/fuzzer_stats"
}

run() {
    local target=$1 seconds=$2
    local binary=$bin_dir/$target out=$out_root/$target
    [[ -x $binary ]] || { echo "no binary $binary: run scripts/fuzz.sh build" >&2; return 2; }
    [[ -d $fuzz_dir/corpus/$target ]] || { echo "no corpus fuzz/corpus/$target" >&2; return 2; }
    rm -rf "$out"
    mkdir -p "$out"
    local started=$SECONDS
    cargo afl fuzz -V "$seconds" -i "$fuzz_dir/corpus/$target" -o "$out" -- "$binary" \
        >"$out/afl.log" 2>&1 || {
        echo "afl-fuzz failed for $target:" >&2
        tail -n 30 "$out/afl.log" >&2
        return 2
    }
    local elapsed=$((SECONDS - started))
    local dir=$out/default
    local crashes hangs
    crashes=$(stat "$dir" saved_crashes)
    hangs=$(stat "$dir" saved_hangs)
    printf '%-18s %5ss  execs %-10s corpus %-6s coverage %-8s crashes %-3s hangs %s\n' \
        "$target" "$elapsed" "$(stat "$dir" execs_done)" "$(stat "$dir" corpus_count)" \
        "$(stat "$dir" bitmap_cvg)" "$crashes" "$hangs"
    if [[ $crashes != 0 ]]; then
        echo "$target: crashing inputs in $dir/crashes/ (see docs/fuzzing.md):" >&2
        ls "$dir/crashes" >&2
        return 1
    fi
}

replay() {
    local target chosen=("$@")
    [[ ${#chosen[@]} -gt 0 ]] || mapfile -t chosen < <(targets)
    (cd "$fuzz_dir" && cargo build --release --locked --bins --target-dir target/replay)
    for target in "${chosen[@]}"; do
        local inputs=("$fuzz_dir/corpus/$target")
        [[ -d $fuzz_dir/crashes/$target ]] && inputs+=("$fuzz_dir/crashes/$target")
        "$fuzz_dir/target/replay/release/$target" "${inputs[@]}" | tail -n 1 | sed "s/^/$target: /"
    done
}

minimize() {
    local target=$1 queue=$out_root/$1/default/queue
    [[ -d $queue ]] || { echo "no queue $queue: run the target first" >&2; return 2; }
    # `cargo afl cmin` runs AFL++'s Python afl-cmin, which narrows the queue of these
    # persistent-mode targets down to 0 files ("Found 0 unique tuples"); its awk version,
    # installed beside it, reads their traces. The newest AFL++ that cargo-afl built is used.
    local cmin
    cmin=$(ls -t "$HOME"/.local/share/afl.rs/*/*/afl/bin/afl-cmin.awk 2>/dev/null | head -n 1)
    [[ -n $cmin ]] || { echo "no afl-cmin.awk under ~/.local/share/afl.rs: run scripts/fuzz.sh build" >&2; return 2; }
    local tmp kept
    tmp=$(mktemp -d)
    PATH=$(dirname "$cmin"):$PATH "$cmin" -i "$queue" -o "$tmp/min" -- "$bin_dir/$target" >"$tmp/log" 2>&1 || {
        tail -n 20 "$tmp/log" >&2
        rm -rf "$tmp"
        return 1
    }
    kept=$(find "$tmp/min" -type f | wc -l)
    if [[ $kept -eq 0 ]]; then
        # Never trade a corpus for nothing.
        echo "afl-cmin kept no input of $queue; fuzz/corpus/$target is unchanged" >&2
        tail -n 20 "$tmp/log" >&2
        rm -rf "$tmp"
        return 1
    fi
    rm -rf "$fuzz_dir/corpus/$target"
    mv "$tmp/min" "$fuzz_dir/corpus/$target"
    rm -rf "$tmp"
    echo "$target: $kept inputs kept of $(find "$queue" -maxdepth 1 -type f | wc -l)"
    du -sh "$fuzz_dir/corpus/$target"
}

case ${1:-} in
    build) build ;;
    list) targets ;;
    run)
        [[ $# -eq 3 ]] || { echo "usage: $0 run TARGET SECONDS" >&2; exit 2; }
        run "$2" "$3"
        ;;
    ci)
        seconds=${2:-10}
        install_tools
        build
        failed=0
        for target in $(targets); do
            run "$target" "$seconds" || failed=1
        done
        # The instrumented build (about 3 GB) is not needed after the runs, and CI's disk is
        # shared with the test build that follows. A crash's inputs stay in target/fuzz-out.
        rm -rf "$fuzz_dir/target"
        exit $failed
        ;;
    replay) shift; replay "$@" ;;
    minimize)
        [[ $# -eq 2 ]] || { echo "usage: $0 minimize TARGET" >&2; exit 2; }
        minimize "$2"
        ;;
    *)
        sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'
        exit 2
        ;;
esac

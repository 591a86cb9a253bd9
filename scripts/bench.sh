#!/usr/bin/env bash
# Run the criterion benches of the pure-Rust crates and gate their medians against
# benches/thresholds.toml (see docs/BENCHMARKS.md). Extra arguments go to `cargo bench`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# run_bench PACKAGE BENCH... : one `cargo bench`, its progress lines filtered out.
run_bench() {
    local package=$1
    shift
    local targets=()
    for b in "$@"; do
        targets+=(--bench "$b")
    done
    echo "bench: cargo bench ($package: $*)"
    set +e
    cargo bench -p "$package" "${targets[@]}" "${EXTRA[@]}" 2>&1 \
        | grep -vE '^(Benchmarking |Gnuplot not found)'
    local status=${PIPESTATUS[0]}
    set -e
    if [ "$status" -ne 0 ]; then
        echo "bench: cargo bench failed (exit $status)" >&2
        exit "$status"
    fi
}

EXTRA=("$@")
run_bench picopit-dynamics models plant
run_bench picopit-pico-nn pico
run_bench picopit-mpc ctrl_step
run_bench picopit-planner plan_step
run_bench picopit-vehicle-io ipc
python3 scripts/bench_gate.py

#!/usr/bin/env bash
# Run the criterion benches of the pure-Rust crates and gate their medians against
# benches/thresholds.toml (see docs/BENCHMARKS.md). A gate over its limit is measured again
# (its bench and its binary's references, in a new bench process), up to twice, before the
# script fails: on a shared machine a neighbour's burst can slow one bench and neither
# reference, and the surrogate steps run in a fast or a slow mode from one bench process to
# the next (docs/BENCHMARKS.md). Extra arguments go to `cargo bench`.
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

# package_of BINARY: the crate whose bench binary it is.
package_of() {
    case "$1" in
        models | plant) echo picopit-dynamics ;;
        pico) echo picopit-pico-nn ;;
        ctrl_step) echo picopit-mpc ;;
        plan_step) echo picopit-planner ;;
        ipc) echo picopit-vehicle-io ;;
        *)
            echo "bench: no package known for the bench binary '$1'" >&2
            return 1
            ;;
    esac
}

EXTRA=("$@")
run_bench picopit-dynamics models plant
run_bench picopit-pico-nn pico
run_bench picopit-mpc ctrl_step
run_bench picopit-planner plan_step
run_bench picopit-vehicle-io ipc
if python3 scripts/bench_gate.py; then
    exit 0
fi
for attempt in 1 2; do
    echo "bench: measuring the benches over their limit again ($attempt of 2)"
    retries=$(python3 scripts/bench_gate.py --failing)
    while read -r binary filter; do
        [ -n "$binary" ] || continue
        package=$(package_of "$binary")
        echo "bench: cargo bench ($package: $binary, $filter)"
        set +e
        cargo bench -p "$package" --bench "$binary" "${EXTRA[@]}" -- "$filter" 2>&1 \
            | grep -vE '^(Benchmarking |Gnuplot not found)'
        status=${PIPESTATUS[0]}
        set -e
        if [ "$status" -ne 0 ]; then
            echo "bench: cargo bench failed (exit $status)" >&2
            exit "$status"
        fi
    done <<<"$retries"
    if python3 scripts/bench_gate.py; then
        exit 0
    fi
done
exit 1

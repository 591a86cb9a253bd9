#!/usr/bin/env bash
# Run the criterion benches of the pure-Rust crates and gate their medians against
# benches/thresholds.toml (see docs/BENCHMARKS.md). Extra arguments go to `cargo bench`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

echo "bench: cargo bench (picopit-dynamics: models, plant)"
set +e
cargo bench -p picopit-dynamics --bench models --bench plant "$@" 2>&1 \
    | grep -vE '^(Benchmarking |Gnuplot not found)'
status=${PIPESTATUS[0]}
set -e
if [ "$status" -ne 0 ]; then
    echo "bench: cargo bench failed (exit $status)" >&2
    exit "$status"
fi
python3 scripts/bench_gate.py

#!/usr/bin/env bash
# Run all tests: the Rust workspace (default members: the pure-Rust crates) and the Python
# tests in tests/ against a release build of the extension in ./.venv, set up in full
# (scripts/setup.sh --full: every extra and the vehicle I/O binaries). Both suites always
# run; the script fails if either does. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh --full

echo "test: cargo test (workspace default members)"
cargo_rc=0
cargo test --no-fail-fast || cargo_rc=$?

echo "test: pytest tests/"
pytest_rc=0
.venv/bin/python -m pytest tests/ "$@" || pytest_rc=$?
if [ "$pytest_rc" -eq 5 ]; then
    echo "test: pytest collected no tests"
    pytest_rc=0
fi

if [ "$cargo_rc" -ne 0 ] || [ "$pytest_rc" -ne 0 ]; then
    echo "test: FAILED (cargo test exit $cargo_rc, pytest exit $pytest_rc)" >&2
    exit 1
fi
# Success ends on pytest's own summary line (CI reads the runner's closing line).

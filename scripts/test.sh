#!/usr/bin/env bash
# Run all tests: the Rust workspace (default members: the pure-Rust crates) and the Python
# tests in tests/ against a release build of the extension in ./.venv.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh

echo "test: cargo test (workspace default members)"
cargo test

echo "test: pytest tests/"
set +e
.venv/bin/python -m pytest tests/ "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
    echo "test: pytest collected no tests"
    rc=0
fi
exit "$rc"

#!/usr/bin/env bash
# Set everything up in ./.venv, then run the main job. Until the benchmark exists that is a
# two-vehicle PIT simulation (`picopit simulate`); extra arguments are passed to it.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
exec .venv/bin/picopit simulate "$@"

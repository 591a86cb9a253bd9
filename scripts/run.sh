#!/usr/bin/env bash
# Set everything up in ./.venv, then run the main job: the closed-loop benchmark
# (`picopit bench`) on its default scene set, a fixed stratified subset of 128 scenes of
# data/scenarios.jsonl x the four controller configurations, written to runs/bench-<timestamp>/.
# Extra arguments are passed to it (e.g. --full, --configs picopinn, --limit 16, --out DIR).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
exec .venv/bin/picopit bench "$@"

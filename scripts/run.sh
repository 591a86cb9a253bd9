#!/usr/bin/env bash
# Set up ./.venv with what the main job needs (scripts/setup.sh: the extension and the
# benchmark's dependencies, no torch, CasADi or Ray), then run it: the closed-loop benchmark
# (`picopit bench`) on its default scene set, a fixed stratified subset of 128 scenes of
# data/scenarios.jsonl x the four controller configurations, written to runs/bench-<timestamp>/.
# Extra arguments are passed to it (e.g. --full, --configs picopinn, --limit 16, --out DIR).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
exec .venv/bin/picopit bench "$@"

#!/usr/bin/env bash
# Install picopit into ./.venv: a release build of the Rust extension (picopit._core) and the
# Python package (editable: py/python is imported in place) with what `picopit bench` needs.
#
#   scripts/setup.sh          the main job's set: the extension, numpy, matplotlib, tqdm,
#                             pyarrow, mcap, foxglove-sdk (and tomli before Python 3.11)
#   scripts/setup.sh --full   everything: also the extras test (pytest, scipy, CommonRoad's
#                             vehicle models, protobuf, jsonschema), train (torch, safetensors),
#                             peers (CasADi), ray, and the pit-controller / pit-vehicle binaries
#                             (`picopit trials`)
#
# Idempotent: re-running only rebuilds what changed; a full set-up stays full. Needs python3
# (>= 3.9; PYTHON=... picks another interpreter) and cargo.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

FULL=0
for arg in "$@"; do
    case "$arg" in
        --full) FULL=1 ;;
        *) echo "setup: unknown option '$arg' (usage: scripts/setup.sh [--full])" >&2; exit 2 ;;
    esac
done

PYTHON="${PYTHON:-python3}"
VENV="$PWD/.venv"

venv_ok() { [ -x "$VENV/bin/python" ] && "$VENV/bin/python" -c 'import sys, pip' >/dev/null 2>&1; }

if ! venv_ok; then
    rm -rf "$VENV"
    echo "setup: creating $VENV with $("$PYTHON" --version 2>&1)"
    if ! "$PYTHON" -m venv "$VENV"; then
        # Debian's system python ships venv/ensurepip separately.
        if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
            echo "setup: python3 -m venv failed; installing python3-venv with apt-get"
            rm -rf "$VENV"
            DEBIAN_FRONTEND=noninteractive apt-get update -qq
            DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv
            "$PYTHON" -m venv "$VENV"
        else
            echo "setup: '$PYTHON -m venv' failed; install your distribution's python3-venv package" >&2
            exit 1
        fi
    fi
fi

export VIRTUAL_ENV="$VENV"
export PATH="$VENV/bin:$PATH"
export PIP_DISABLE_PIP_VERSION_CHECK=1
# No wheel cache: the full set pulls torch with its CUDA libraries (~4 GB from PyPI); a cached
# copy would double that on disk, and a CI machine once ran out of space installing it.
export PIP_NO_CACHE_DIR=1
python -m pip install --quiet 'maturin>=1.9.4,<2'

# The extras: test (pytest; scipy and CommonRoad's models for the plant validation; protobuf and
# jsonschema for the recording checks), train (torch, safetensors: the surrogate pipeline), peers
# (CasADi: benchmarks/peers), ray (picopit bench --ray-address; tests/test_bench.py starts a local
# instance). A set-up that was full once stays full (the marker file), so run.sh after test.sh
# does not look as if it removed anything. The build shares ./target with cargo.
MARKER="$VENV/.picopit-full"
EXTRAS=()
if [ "$FULL" = 1 ] || [ -e "$MARKER" ]; then
    FULL=1
    EXTRAS=(--extras test,train,peers,ray)
fi
echo "setup: building picopit._core (release) and installing picopit into $VENV" \
    "($([ "$FULL" = 1 ] && echo "full: all extras" || echo "the main job's dependencies"))"
maturin develop --release "${EXTRAS[@]}" --manifest-path py/Cargo.toml
python -c 'import picopit; print("setup: picopit ready:", ", ".join(picopit.__all__))'

if [ "$FULL" = 1 ]; then
    touch "$MARKER"
    # The vehicle I/O processes (pit-controller, pit-vehicle): `picopit trials` runs them.
    echo "setup: building pit-controller and pit-vehicle (release)"
    cargo build --release --quiet -p picopit-vehicle-io --bins
fi

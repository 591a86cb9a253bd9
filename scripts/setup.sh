#!/usr/bin/env bash
# Install picopit into ./.venv: a release build of the Rust extension (picopit._core), the
# Python package (editable: py/python is imported in place) and its dependencies, plus pytest.
# Idempotent: re-running only rebuilds what changed. Needs python3 (>= 3.9) and cargo.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

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
python -m pip install --quiet 'maturin>=1.9.4,<2'

echo "setup: building picopit._core (release) and installing picopit into $VENV"
# --extras test pulls in pytest, train torch/safetensors/scipy (the surrogate pipeline),
# peers casadi (benchmarks/peers), ray (picopit bench --ray-address; tests/test_bench.py runs
# the benchmark on a local Ray instance); the build shares ./target with cargo.
maturin develop --release --extras test,train,peers,ray --manifest-path py/Cargo.toml
python -c 'import picopit; print("setup: picopit ready:", ", ".join(picopit.__all__))'

# The vehicle I/O processes (pit-controller, pit-vehicle): `picopit trials` runs them.
echo "setup: building pit-controller and pit-vehicle (release)"
cargo build --release --quiet -p picopit-vehicle-io --bins

#!/usr/bin/env bash
# Sourced by scripts/test.sh (and usable alone): creates the project's Python virtual
# environment under the cache folder, installs the test requirements and builds the
# `modesuite` package into it in place (`maturin develop`, the dev profile: the Rust tests'
# build outputs are reused; `--release` for benchmarks). Exports MODESUITE_VENV.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh
export MODESUITE_VENV="${MODESUITE_VENV:-${XDG_CACHE_HOME:-$HOME/.cache}/modesuite-venv}"
PYTHON="${PYTHON:-python3}"
if [ ! -x "$MODESUITE_VENV/bin/python" ]; then
    echo "python: creating $MODESUITE_VENV"
    "$PYTHON" -m venv "$MODESUITE_VENV"
fi
stamp="$MODESUITE_VENV/.requirements"
if ! cmp -s python/requirements-test.txt "$stamp"; then
    "$MODESUITE_VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
        -r python/requirements-test.txt
    cp python/requirements-test.txt "$stamp"
fi
# `scripts/python.sh --release` builds the optimised package (for benchmarks)
profile=()
for a in "$@"; do
    if [ "$a" = "--release" ]; then profile=(--release); fi
done
# maturin finds the interpreter through the active virtual environment
VIRTUAL_ENV="$MODESUITE_VENV" PATH="$MODESUITE_VENV/bin:$PATH" \
    "$MODESUITE_VENV/bin/maturin" develop --quiet --locked "${profile[@]}"

#!/usr/bin/env bash
# The whole test suite: set up, then formatting, lints (warnings are errors), every Rust test,
# and the Python package's tests (built into a virtual environment this script creates).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
# disk space before and after, for a CI log that ends early
df -h "$(dirname "$CARGO_TARGET_DIR")" 2>/dev/null | tail -1 | sed 's/^/test: disk before: /' || true
trap 'du -sh "$CARGO_TARGET_DIR" 2>/dev/null | sed "s/^/test: build outputs: /"; df -h "$(dirname "$CARGO_TARGET_DIR")" 2>/dev/null | tail -1 | sed "s/^/test: disk after: /"' EXIT
cargo fmt --all -- --check
cargo clippy --locked --workspace --all-targets -- -D warnings
# the binding crate has no Rust tests of its own: maturin builds it below
cargo test --locked --workspace --exclude modesuite-python
# the compiled example plugins the Python tests load
cargo build --locked -p plugin-trefoil -p plugin-panics
export MODESUITE_PLUGIN_DIR="$CARGO_TARGET_DIR/debug"
# the command line the Python tests compare with (built by `cargo test` above)
export MODESUITE_BIN="$CARGO_TARGET_DIR/debug/modesuite"
source scripts/python.sh
"$MODESUITE_VENV/bin/python" -m pytest -q -W error python/tests

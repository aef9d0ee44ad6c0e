#!/usr/bin/env bash
# The whole test suite: set up, then formatting, lints (warnings are errors) and every test.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
cargo fmt --all -- --check
cargo clippy --locked --workspace --all-targets -- -D warnings
cargo test --locked --workspace

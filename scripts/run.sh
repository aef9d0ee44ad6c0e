#!/usr/bin/env bash
# The main job: set up, build (release) and run `modesuite` with the given arguments.
# Without arguments it runs the embedded default and prints its metrics.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
cargo build --release --locked -p modesuite
exec "$CARGO_TARGET_DIR/release/modesuite" "$@"
